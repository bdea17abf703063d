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
from hybridneus.data.windows import RayBatch
from hybridneus.training import losses as L
from hybridneus.training.priors.base import Prior, StepContext
from hybridneus.training.schedules import ramp

#: The deepest drift behind the hull, in hull voxels, that ``silent_depth`` pulls back. A
#: silent ray that meets the surface farther in looks through a hollow that no silhouette
#: carves (the body inside a wire cage, the floor under a bowl's rim), where the surface
#: rightly lies behind the hull; a face that sank lies a few voxels in.
HOLLOW_VOXELS = 8


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
        terms = {"hull": (weight, L.outside_loss(r.sdf, free))}
        if self.cfg.silent_depth > 0 and isinstance(ctx.batch, RayBatch):
            terms["hull_depth"] = (weight * self.cfg.silent_depth, self._depth_excess(ctx))
        return terms

    def _depth_excess(self, ctx: StepContext, n_marks: int = 256) -> torch.Tensor:
        """Mean distance by which the rendered surface of a silent ray lies beyond the ray's
        entry into the hull (less one hull voxel), over the silent rays that hit; an excess
        is counted up to :data:`HOLLOW_VOXELS` hull voxels and pulls no further."""
        out = ctx.out
        opacity = out.opacity
        depth = out.depth / opacity.detach().clamp_min(1e-6)
        silent = ctx.batch.target == 0
        use = torch.cat([silent, silent]) & (opacity.detach() > 0.5)
        if not bool(use.any()):
            return depth.sum() * 0.0
        d = depth[use]
        frac = torch.linspace(0.0, 1.0, n_marks, device=d.device)
        t = d.detach()[:, None] * frac  # (n, K)
        pts = ctx.origins[use][:, None, :] + t[..., None] * ctx.dirs[use][:, None, :]
        inside = self.free_space.occupied(pts.reshape(-1, 3)).reshape(t.shape)
        first = torch.where(inside.any(dim=1), inside.float().argmax(dim=1),
                            torch.full_like(d, n_marks - 1, dtype=torch.long))
        entry = t.gather(1, first[:, None])[:, 0]
        voxel = self.free_space.voxel
        # beyond the cap the excess is a hollow the hull cannot carve, not a drifted face
        return torch.relu(d - entry - voxel).clamp(max=HOLLOW_VOXELS * voxel).mean()
