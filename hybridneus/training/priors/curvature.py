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
from hybridneus.data.windows import RayBatch
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
        counts = hit
        if self.cfg.silent_only and isinstance(ctx.batch, RayBatch):
            silent = (ctx.batch.target == 0).to(hit.dtype)
            counts = hit * torch.cat([silent, silent])
        offset = torch.randn(points.shape, generator=ctx.generator, device=points.device)
        step = self.cfg.step * torch.nn.functional.normalize(offset, dim=-1)
        if self.cfg.order == 2:
            grads = ctx.field.sdf_gradient_features(
                torch.cat([points - step, points, points + step]), True)[1]
            ctx.eikonal.append((grads, torch.cat([hit, hit, hit])))
            value = L.bending_loss(*grads.chunk(3), counts)
        else:
            grads = ctx.field.sdf_gradient_features(torch.cat([points, points + step]), True)[1]
            ctx.eikonal.append((grads, torch.cat([hit, hit])))
            value = L.curvature_loss(*grads.chunk(2), counts)
        return {"curvature": (weight, value)}
