"""``priors.silent_lines``: a silent line of pixels sees one flat surface
(:class:`hybridneus.config.SilentLinesPrior`).

A face of one colour fires only along its outline, and the events hold its inside nowhere:
behind a firing outline, a dish explains them as well as the plane does. On a plane, inverse
depth is linear along any image line, so for a run of silent pixels along the window's image
motion (:mod:`hybridneus.data.lines`) the depth of a pixel between the run's ends follows
from theirs. The term is the mean depth, along the camera's viewing axis, by which each
middle lies behind that plane, over the lines whose three rays hit the surface and whose
middle lies behind the plane by at most ``max_bend`` of the line's length: a face that sank
a little is pulled back, while a line whose middle lies far behind its ends looks past
something in front (the body of a cage seen between two wires) and is left alone. It only
pulls toward the camera: a face pushed out would move a silhouette and the events hold it,
but one that sinks changes no event; and a smooth body of one colour so evenly lit that it
stays silent bulges in front of its lines, where a symmetric term would flatten it. Its
weight grows from 0 over ``ramp`` from ``start`` of training, once the surface has formed:
while the fit carves the initial sphere down, every line still runs across matter that must
go. The sampler renders the lines' rays with the batch
(:func:`hybridneus.training.objective.batch_rays`).
"""

from __future__ import annotations

import torch

from hybridneus.config import SilentLinesPrior as SilentLinesConfig
from hybridneus.training.priors.base import Prior, StepContext
from hybridneus.training.schedules import ramp


def plane_depth(z_start: torch.Tensor, z_end: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Depth at ``t`` in [0, 1] along an image line between depths ``z_start`` and ``z_end``
    on one plane (inverse depth is linear along the line); all (k,)."""
    return 1.0 / ((1.0 - t) / z_start + t / z_end)


def line_residual(depth: torch.Tensor, opacity: torch.Tensor, dirs: torch.Tensor,
                  forward: torch.Tensor, t: torch.Tensor, max_bend: float = 0.0
                  ) -> torch.Tensor:
    """Mean depth by which each middle lies behind the plane_depth of its ends, along
    ``forward`` (a middle in front of it counts 0).

    Args:
        depth: (3k,) expected distance along the ray (weighted, as the renderer's) of the
            starts, middles and ends in that order.
        opacity: (3k,) their opacities; a line counts where all three exceed 0.5.
        dirs: (3k, 3) unit ray directions (their origin is the same camera).
        forward: (3,) the camera's viewing axis.
        t: (k,) where each middle lies between its ends.
        max_bend: a line counts only where its gap is at most this fraction of the distance
            between its ends' surface points (0: every line counts).

    Returns:
        () the mean over the counted lines (0 when none count).
    """
    k = t.shape[0]
    dist = depth / opacity.detach().clamp_min(1e-6)
    z = dist * (dirs @ forward)
    z_a, z_m, z_b = z[:k], z[k:2 * k], z[2 * k:]
    count = (opacity.detach() > 0.5).reshape(3, k).all(dim=0)
    gap = torch.relu(z_m - plane_depth(z_a.clamp_min(1e-3), z_b.clamp_min(1e-3), t))
    if max_bend > 0:
        points = (dist[:, None] * dirs).detach()
        length = (points[2 * k:] - points[:k]).norm(dim=-1)
        count = count & (gap.detach() <= max_bend * length)
    if not bool(count.any()):
        return z.sum() * 0.0
    return gap[count].mean()


def line_weight(cfg: SilentLinesConfig, p: float) -> float:
    """The term's weight at training progress ``p`` (0 before ``start``): while it is 0 the
    sampler draws no lines, so the batch renders no rays for them."""
    return cfg.weight * ramp(p, cfg.start, cfg.ramp) if cfg.enabled else 0.0


class SilentLinesPrior(Prior):
    """See the module docstring."""

    name = "silent_lines"

    def __init__(self, cfg: SilentLinesConfig) -> None:
        self.cfg = cfg

    def terms(self, ctx: StepContext) -> dict[str, tuple[float, torch.Tensor]]:
        batch = ctx.batch
        weight = line_weight(self.cfg, ctx.p)
        if weight <= 0 or getattr(batch, "line_t", None) is None or len(batch.line_t) == 0:
            return {}
        k3 = 3 * batch.line_t.shape[0]
        out = ctx.out
        value = line_residual(out.depth[-k3:], out.opacity[-k3:], ctx.dirs[-k3:],
                              batch.forward, batch.line_t, self.cfg.max_bend)
        return {"silent_lines": (weight, value)}
