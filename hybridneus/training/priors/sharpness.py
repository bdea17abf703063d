"""``priors.sharpness_floor``: a rising lower bound on the NeuS sharpness
(:class:`hybridneus.config.SharpnessFloor`); ``priors.sharpness_ceiling``: a fixed upper
bound (:class:`hybridneus.config.SharpnessCeiling`).

Where events leave the geometry ambiguous (faint, event-poor regions, thin parts) the learned
sharpness can sink and the fit turn to fog: a thick semi-transparent envelope, or hollows,
whose zero level is far from the object. After each optimiser step the variance ``v`` is
projected up to the floor (:func:`hybridneus.training.schedules.sharpness_floor`); it keeps
its gradient, so the sharpness can still rise above it. There is no floor in the first
``delay`` of training, where the sharpness dips while the surface leaves the initial sphere,
and the floor then grows out of 1 over ``blend`` instead of jumping to its curve.
"""

from __future__ import annotations

import math

import torch

from hybridneus.config import SharpnessCeiling as CeilingConfig
from hybridneus.config import SharpnessFloor as FloorConfig
from hybridneus.training.priors.base import Prior
from hybridneus.training.schedules import sharpness_floor


class SharpnessFloor(Prior):
    """See the module docstring.

    Args:
        cfg: ``priors.sharpness_floor``.
        start: the initial sharpness ``exp(10 v_0)``, where the floor's curve starts.
    """

    name = "sharpness_floor"

    def __init__(self, cfg: FloorConfig, start: float) -> None:
        self.cfg = cfg
        self.start = start

    def floor(self, p: float) -> float:
        """The floor at progress ``p`` (0.0: none)."""
        c = self.cfg
        return sharpness_floor(p, self.start, c.floor, c.at, c.delay, c.blend)

    def after_update(self, trainer, p: float) -> None:
        floor = self.floor(p)
        if floor > 0:
            with torch.no_grad():
                trainer.field.variance.clamp_(min=math.log(floor) / 10.0)


class SharpnessCeiling(Prior):
    """Projects the variance ``v`` down to ``log(ceiling) / 10`` after each step.

    Where the events keep favouring crisper edges the sharpness can grow past anything the
    grid and the samples resolve; the occupancy band then shrinks below the field's error,
    rays skip the cells the surface crosses, and the field empties. Projecting (rather than
    clamping ``inv_s`` in the renderer) also keeps ``v`` where its gradient lives: the
    field's own clamp at 1e6 would leave a runaway ``v`` without one, for good.

    Args:
        cfg: ``priors.sharpness_ceiling``.
        cell: the finest grid cell's size (world units).
    """

    name = "sharpness_ceiling"

    def __init__(self, cfg: CeilingConfig, cell: float) -> None:
        self.ceiling = cfg.per_cell / cell

    def after_update(self, trainer, p: float) -> None:
        with torch.no_grad():
            trainer.field.variance.clamp_(max=math.log(self.ceiling) / 10.0)
