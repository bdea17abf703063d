"""``priors.curvature``: smooth surfaces where the events say nothing
(:class:`hybridneus.config.CurvaturePrior`).

A flat face of one colour fires events only along its outline, so the data leave its inside
free to wrinkle. The term is the mean squared change of the unit normal between each rendered
surface point (the expected depth of a ray that hits, opacity > 0.5) and a copy shifted by
``step`` in a random direction; its weight falls linearly to 0 by ``end`` of training. The
gradients it evaluates join the Eikonal term.
"""

from __future__ import annotations

import torch

from hybridneus.config import CurvaturePrior as CurvatureConfig
from hybridneus.training import losses as L
from hybridneus.training.priors.base import Prior, StepContext
from hybridneus.training.schedules import fading


def surface_points(out, origins: torch.Tensor, dirs: torch.Tensor
                   ) -> tuple[torch.Tensor, torch.Tensor]:
    """The rendered surface point (expected depth) of every ray, and which rays hit something
    (opacity > 0.5) as a 0/1 weight.

    Every ray keeps a point, so that no step waits for the number of hits (a GPU would stall
    on it); a miss's point is the mean of its samples' depths, or its origin where it has no
    opacity at all.
    """
    opacity = out.opacity.detach()
    depth = out.depth.detach() / opacity.clamp_min(1e-6)
    return origins + depth[:, None] * dirs, (opacity > 0.5).to(origins.dtype)


class CurvaturePrior(Prior):
    """See the module docstring."""

    name = "curvature"

    def __init__(self, cfg: CurvatureConfig) -> None:
        self.cfg = cfg

    def weight(self, p: float) -> float:
        """The term's weight at progress ``p``."""
        return self.cfg.weight * fading(p, self.cfg.end)

    def terms(self, ctx: StepContext) -> dict[str, tuple[float, torch.Tensor]]:
        weight = self.weight(ctx.p)
        if weight <= 0:
            return {}
        points, hit = surface_points(ctx.out, ctx.origins, ctx.dirs)
        offset = torch.randn(points.shape, generator=ctx.generator, device=points.device)
        shifted = points + self.cfg.step * torch.nn.functional.normalize(offset, dim=-1)
        _, grad, _ = ctx.field.sdf_gradient_features(torch.cat([points, shifted]), True)
        ctx.eikonal.append((grad, torch.cat([hit, hit])))
        grad_p, grad_s = grad.chunk(2)
        return {"curvature": (weight, L.curvature_loss(grad_p, grad_s, hit))}
