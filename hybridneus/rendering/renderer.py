"""Rendering rays of a :class:`~hybridneus.model.field.HybridField` with NeuS compositing."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from hybridneus.rendering.neus import alpha_from_sdf, composite, weights_from_alpha
from hybridneus.rendering.sampling import NeuSSampler, intervals_from_samples


@dataclass
class RenderOutput:
    """What :func:`render_rays` returns.

    Attributes:
        color: composited RGB over the background, (n_rays, 3).
        opacity: sum of weights, (n_rays,).
        depth: expected distance along the ray, (n_rays,).
        normal: weighted unit normal, (n_rays, 3).
        gradients: SDF gradients at all samples, (n_rays * n_samples, 3) (Eikonal input).
        weights: (n_rays, n_samples).
    """

    color: torch.Tensor
    opacity: torch.Tensor
    depth: torch.Tensor
    normal: torch.Tensor
    gradients: torch.Tensor
    weights: torch.Tensor


def render_rays(
    field,
    origins: torch.Tensor,  # (n_rays, 3)
    dirs: torch.Tensor,  # (n_rays, 3)
    sampler: NeuSSampler,
    generator: torch.Generator | None = None,
    train: bool = True,
    crop_softness: float = 0.01,
) -> RenderOutput:
    """Sample, evaluate the field and composite NeuS colours for a batch of rays.

    Args:
        field: a :class:`~hybridneus.model.field.HybridField`.
        origins: ray origins, (n_rays, 3).
        dirs: unit ray directions, (n_rays, 3).
        sampler: places the samples (no grad) from ``field.raw_sdf``.
        generator: jitter for the coarse strata (``None``: fixed positions).
        train: keep the graph (double backward for the Eikonal term); otherwise all outputs
            are detached.
        crop_softness: width of the soft crop-cylinder edge that scales opacity.

    Returns:
        :class:`RenderOutput`.

    Note:
        Differentiable in the field's parameters when ``train`` (sample positions are not).
    """
    n_rays = origins.shape[0]
    t = sampler(origins, dirs, field.raw_sdf, generator)
    n_samples = t.shape[1]
    mids, deltas = intervals_from_samples(t)
    pts = (origins[:, None, :] + dirs[:, None, :] * mids[..., None]).reshape(-1, 3)
    dirs_flat = dirs[:, None, :].expand(-1, n_samples, -1).reshape(-1, 3)
    sdf, grad, feats = field.sdf_gradient_features(pts, create_graph=train)
    with torch.set_grad_enabled(train):
        rgb = field.radiance(pts, dirs_flat, grad, feats)
        dot = (dirs_flat * grad).sum(dim=-1)
        crop = field.crop_weight(pts, crop_softness).view(n_rays, n_samples)
        alpha = crop * alpha_from_sdf(sdf.view(n_rays, n_samples), dot.view(n_rays, n_samples),
                                      deltas, field.inv_s())
        weights = weights_from_alpha(alpha)
        color = composite(weights, rgb.view(n_rays, n_samples, 3), field.background())
        normals = torch.nn.functional.normalize(grad, dim=-1).view(n_rays, n_samples, 3)
        normal = composite(weights, normals)
        depth = (weights * mids).sum(dim=-1)
    return RenderOutput(color, weights.sum(dim=-1), depth, normal, grad, weights)


def render_rays_chunked(
    field,
    origins: torch.Tensor,
    dirs: torch.Tensor,
    sampler: NeuSSampler,
    chunk_rays: int = 2048,
    crop_softness: float = 0.01,
) -> RenderOutput:
    """:func:`render_rays` without gradients, in chunks of rays (previews, evaluation).

    Note:
        Not differentiable.
    """
    outs = [
        render_rays(field, o, d, sampler, None, False, crop_softness)
        for o, d in zip(origins.split(chunk_rays), dirs.split(chunk_rays), strict=True)
    ]
    return RenderOutput(
        *(torch.cat([getattr(o, name) for o in outs]) for name in
          ("color", "opacity", "depth", "normal", "gradients", "weights"))
    )
