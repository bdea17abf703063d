"""The loss of one training step, from a render and its batch.

Every fit has the data term (``event``: the EventNeuS loss on the two window ends; ``rgb``:
the frames' colours, for the RGB upper bound), the Eikonal term on every SDF gradient the
step evaluated, and the ``outside`` term that keeps matter out of the space beyond the crop
cylinder, which is never rendered. The priors (:mod:`hybridneus.training.priors`) add their
own terms. Each term is ``(weight, value)``; the step minimises the weighted sum and logs
each value as ``loss/<name>``.
"""

from __future__ import annotations

import torch

from hybridneus.config import LossConfig
from hybridneus.data.crop import crop_sdf
from hybridneus.data.frames import FrameBatch
from hybridneus.data.windows import RayBatch
from hybridneus.training import losses as L
from hybridneus.training.priors import Prior, RandomPoints, StepContext

Terms = dict[str, tuple[float, torch.Tensor]]


def batch_rays(batch: RayBatch | FrameBatch) -> tuple[torch.Tensor, torch.Tensor]:
    """The rays a batch renders, (n, 3) origins and directions: an event batch's pixels at
    the window start, then the same pixels at its end."""
    if isinstance(batch, RayBatch):
        return (torch.cat([batch.origins0, batch.origins1]),
                torch.cat([batch.dirs0, batch.dirs1]))
    return batch.origins, batch.dirs


def data_terms(out, batch: RayBatch | FrameBatch, loss: LossConfig, eps: float) -> Terms:
    """The data term of ``out`` rendered from :func:`batch_rays` of ``batch``."""
    if isinstance(batch, RayBatch):
        n = batch.target.shape[0]
        value = L.event_loss(out.color[:n], out.color[n:], batch.target, batch.bayer, eps)
        return {"event": (loss.lambda_event, value)}
    return {"rgb": (loss.lambda_rgb, L.rgb_loss(out.color, batch.color))}


def random_points(aabb: torch.Tensor, n: int, margin: float,
                  generator: torch.Generator) -> torch.Tensor:
    """(n, 3) uniform points in the box ``aabb`` (6,) grown by ``margin`` of its size on each
    side, within [-1, 1]^3."""
    lo, hi = aabb[:3], aabb[3:]
    pad = (hi - lo) * margin
    lo, hi = (lo - pad).clamp(-1.0, 1.0), (hi + pad).clamp(-1.0, 1.0)
    u = torch.rand((n, 3), generator=generator, device=aabb.device)
    return lo + u * (hi - lo)


class Objective:
    """The step's loss terms (see the module docstring).

    Args:
        loss: ``cfg.loss``.
        priors: the fit's priors.
        aabb: (6,) the crop box, where the random volume points go.
    """

    def __init__(self, loss: LossConfig, priors: list[Prior], aabb: torch.Tensor) -> None:
        self.loss = loss
        self.priors = priors
        self.aabb = aabb
        self.wants_random = loss.n_random_points > 0 and (
            loss.lambda_eikonal > 0 or loss.lambda_outside > 0
            or any(p.uses_random_points for p in priors))

    def __call__(self, ctx: StepContext, batch: RayBatch | FrameBatch, eps: float) -> Terms:
        """All terms of the step; fills ``ctx.random`` and ``ctx.eikonal`` on the way."""
        terms = data_terms(ctx.out, batch, self.loss, eps)
        ctx.eikonal.append((ctx.out.gradients, None))
        if self.wants_random:
            pts = random_points(self.aabb, self.loss.n_random_points,
                                self.loss.random_box_margin, ctx.generator)
            sdf, grad, _ = ctx.field.sdf_gradient_features(pts, create_graph=True)
            ctx.eikonal.append((grad, None))
            ctx.random = RandomPoints(pts, sdf, crop_sdf(pts, ctx.field.crop) > 0)
            if self.loss.lambda_outside > 0:
                terms["outside"] = (self.loss.lambda_outside,
                                    L.outside_loss(sdf, ctx.random.outside))
        for prior in self.priors:
            terms.update(prior.terms(ctx))
        if self.loss.lambda_eikonal > 0:
            terms["eikonal"] = (self.loss.lambda_eikonal, eikonal(ctx.eikonal))
        return terms


def eikonal(blocks: list[tuple[torch.Tensor, torch.Tensor | None]]) -> torch.Tensor:
    """The Eikonal term over gradient blocks, each with per-point weights (``None``: 1)."""
    grads = torch.cat([g for g, _ in blocks])
    if all(w is None for _, w in blocks):
        return L.eikonal_loss(grads)
    weights = torch.cat([torch.ones(len(g), device=g.device) if w is None else w
                         for g, w in blocks])
    return L.eikonal_loss(grads, weights)
