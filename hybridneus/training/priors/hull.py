"""``priors.hull``: the events' visual hull marks free space (:class:`hybridneus.config.HullPrior`).

Events say nothing where nothing changes: matter the cameras never see against the
background, such as the space under a flat object seen from above, costs no event error, and
fits fill it. Views near the horizon do see that space against the background, and the hull
of the event silhouettes (:mod:`hybridneus.data.hull`) records it as empty. The term is
``relu(-sdf)`` at the random volume points the hull calls free, its weight growing from 0
over ``ramp`` of training. The free space is outlined with the data, before the trainer is
built (:func:`hybridneus.data.estimate.training_data`).
"""

from __future__ import annotations

import torch

from hybridneus.config import HullPrior as HullConfig
from hybridneus.data.hull import FreeSpace
from hybridneus.training import losses as L
from hybridneus.training.priors.base import Prior, StepContext
from hybridneus.training.schedules import ramp


class HullPrior(Prior):
    """See the module docstring.

    Args:
        cfg: ``priors.hull``.
        free_space: the hull's free space over the crop box.
    """

    name = "hull"
    uses_random_points = True

    def __init__(self, cfg: HullConfig, free_space: FreeSpace) -> None:
        self.cfg = cfg
        self.free_space = free_space

    def terms(self, ctx: StepContext) -> dict[str, tuple[float, torch.Tensor]]:
        weight = self.cfg.weight * ramp(ctx.p, 0.0, self.cfg.ramp)
        if weight <= 0 or ctx.random is None:
            return {}
        r = ctx.random
        free = self.free_space.free(r.points) & ~r.outside
        return {"hull": (weight, L.outside_loss(r.sdf, free))}
