"""Placing samples along rays: box clipping, inverse-CDF sampling and NeuS up-sampling.

Samplers never own the field: they take an ``sdf_fn`` callable (points (n, 3) -> sdf (n,))
and run it under ``torch.no_grad``. Sample positions carry no gradient.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from hybridneus.rendering.neus import alpha_from_sdf_pairs, weights_from_alpha
from hybridneus.rendering.occupancy import OccupancyGrid

SdfFn = Callable[[torch.Tensor], torch.Tensor]


def ray_aabb_intersect(
    origins: torch.Tensor,  # (n_rays, 3)
    dirs: torch.Tensor,  # (n_rays, 3)
    aabb: torch.Tensor,  # (6,) min xyz, max xyz
    near_min: float = 0.0,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Entry and exit distances of rays through an axis-aligned box (slab test).

    Args:
        origins: ray origins, (n_rays, 3).
        dirs: ray directions, (n_rays, 3).
        aabb: box as (x_min, y_min, z_min, x_max, y_max, z_max).
        near_min: entry distances are clamped to at least this.

    Returns:
        t_near: (n_rays,).
        t_far: (n_rays,), at least ``t_near + 1e-3`` (misses get a tiny empty interval).
        hit: (n_rays,) bool.

    Note:
        Not differentiable (used for sample placement only).
    """
    safe = torch.where(dirs.abs() < 1e-9, torch.full_like(dirs, 1e-9), dirs)
    inv = 1.0 / safe
    t0 = (aabb[:3] - origins) * inv
    t1 = (aabb[3:] - origins) * inv
    t_near = torch.minimum(t0, t1).amax(dim=-1).clamp_min(near_min)
    t_far = torch.maximum(t0, t1).amin(dim=-1)
    hit = t_far > t_near
    t_far = torch.maximum(t_far, t_near + 1e-3)
    return t_near, t_far, hit


def sample_pdf(
    bins: torch.Tensor,  # (n_rays, n_bins + 1)
    weights: torch.Tensor,  # (n_rays, n_bins)
    n_samples: int,
    jitter: torch.Tensor | None = None,  # (n_rays, n_samples) in [0, 1)
) -> torch.Tensor:
    """Inverse-CDF samples from a piecewise-constant density over ``bins``.

    Args:
        bins: sorted bin edges along each ray, (n_rays, n_bins + 1).
        weights: non-negative bin weights, (n_rays, n_bins); all-zero rows sample uniformly.
        n_samples: samples per ray.
        jitter: stratification offsets; ``None`` places samples at stratum centres.

    Returns:
        t: sorted sample distances, (n_rays, n_samples).

    Note:
        Not differentiable (sample placement).
    """
    weights = weights + 1e-5
    pdf = weights / weights.sum(dim=-1, keepdim=True)
    cdf = torch.cat([torch.zeros_like(pdf[:, :1]), torch.cumsum(pdf, dim=-1)], dim=-1)
    cdf = cdf / cdf[:, -1:]
    offsets = jitter if jitter is not None else torch.full_like(bins[:, :1], 0.5)
    u = (torch.arange(n_samples, device=bins.device, dtype=bins.dtype) + offsets) / n_samples
    u = u.expand(bins.shape[0], n_samples).contiguous()
    idx = torch.searchsorted(cdf, u, right=True)
    below = (idx - 1).clamp(0, cdf.shape[-1] - 1)
    above = idx.clamp(0, cdf.shape[-1] - 1)
    cdf_lo, cdf_hi = cdf.gather(1, below), cdf.gather(1, above)
    bin_lo, bin_hi = bins.gather(1, below), bins.gather(1, above)
    denom = torch.where(cdf_hi - cdf_lo < 1e-5, torch.ones_like(cdf_lo), cdf_hi - cdf_lo)
    frac = (u - cdf_lo) / denom
    return bin_lo + frac * (bin_hi - bin_lo)


def _eval_sdf(sdf_fn: SdfFn, origins, dirs, t, chunk: int) -> torch.Tensor:
    pts = (origins[:, None, :] + dirs[:, None, :] * t[..., None]).reshape(-1, 3)
    out = torch.cat([sdf_fn(p) for p in pts.split(chunk)]) if pts.shape[0] else pts[:, 0]
    return out.reshape(t.shape)


def upsample_neus(
    t: torch.Tensor,  # (n_rays, n)
    sdf: torch.Tensor,  # (n_rays, n)
    n_new: int,
    inv_s: float,
) -> torch.Tensor:
    """New sample distances where a sharp NeuS density puts its weight (NeuS up-sampling).

    The SDF at the interval ends comes from the samples themselves; the slope is the smaller
    of this and the previous interval's (clamped to be non-positive), as in NeuS.

    Args:
        t: sorted sample distances, (n_rays, n).
        sdf: SDF at ``t``, (n_rays, n).
        n_new: samples to add per ray.
        inv_s: fixed sharpness of this round.

    Returns:
        t_new: (n_rays, n_new), sorted.

    Note:
        Not differentiable (sample placement).
    """
    prev_sdf, next_sdf = sdf[:, :-1], sdf[:, 1:]
    dist = (t[:, 1:] - t[:, :-1]).clamp_min(1e-6)
    mid_sdf = 0.5 * (prev_sdf + next_sdf)
    cos = (next_sdf - prev_sdf) / dist
    prev_cos = torch.cat([torch.zeros_like(cos[:, :1]), cos[:, :-1]], dim=-1)
    cos = torch.minimum(cos, prev_cos).clamp(-1e3, 0.0)
    alpha = alpha_from_sdf_pairs(mid_sdf - cos * dist * 0.5, mid_sdf + cos * dist * 0.5, inv_s)
    weights = weights_from_alpha(alpha)
    return sample_pdf(t, weights, n_new)


class NeuSSampler:
    """Coarse samples over occupied space, then NeuS up-sampling rounds near the surface.

    Args:
        aabb: sampling box (6,), usually the crop cylinder's box clipped to [-1, 1]^3.
        n_coarse: samples per ray placed over the occupied part of the ray.
        n_importance: samples added by up-sampling, split evenly over ``up_rounds``.
        up_rounds: rounds at sharpness ``up_base_inv_s * 2**round``.
        occupancy: grid of cells that may hold the surface; ``None`` samples uniformly.
        n_march: occupancy look-ups per ray.
        near_min: smallest start distance.
        chunk: points per no-grad SDF call.

    Example:
        >>> t = sampler(origins, dirs, field.sdf, generator=gen)  # doctest: +SKIP
    """

    def __init__(
        self,
        aabb: torch.Tensor,
        n_coarse: int = 24,
        n_importance: int = 16,
        up_rounds: int = 2,
        up_base_inv_s: float = 64.0,
        occupancy: OccupancyGrid | None = None,
        n_march: int = 128,
        near_min: float = 0.05,
        chunk: int = 65536,
    ) -> None:
        self.aabb = aabb
        self.n_coarse = n_coarse
        self.n_importance = n_importance
        self.up_rounds = up_rounds if n_importance > 0 else 0
        self.up_base_inv_s = up_base_inv_s
        self.occupancy = occupancy
        self.n_march = n_march
        self.near_min = near_min
        self.chunk = chunk

    @property
    def n_samples(self) -> int:
        """Samples per ray returned by :meth:`__call__`."""
        return self.n_coarse + (self.n_importance // max(self.up_rounds, 1)) * self.up_rounds

    @torch.no_grad()
    def __call__(
        self,
        origins: torch.Tensor,  # (n_rays, 3)
        dirs: torch.Tensor,  # (n_rays, 3)
        sdf_fn: SdfFn,
        generator: torch.Generator | None = None,
    ) -> torch.Tensor:
        """Sorted sample distances (n_rays, n_samples) along unit-direction rays.

        ``generator`` jitters the coarse strata (training); ``None`` gives fixed positions.
        """
        t_near, t_far, _ = ray_aabb_intersect(origins, dirs, self.aabb.to(origins), self.near_min)
        n_rays = origins.shape[0]
        jitter = None
        if generator is not None:
            jitter = torch.rand(
                (n_rays, 1), generator=generator, device=generator.device, dtype=origins.dtype
            ).to(origins.device)
        if self.occupancy is not None:
            steps = torch.linspace(0.0, 1.0, self.n_march + 1, device=origins.device)
            edges = t_near[:, None] + (t_far - t_near)[:, None] * steps
            mids = 0.5 * (edges[:, 1:] + edges[:, :-1])
            pts = origins[:, None, :] + dirs[:, None, :] * mids[..., None]
            occupied = self.occupancy.query(pts.reshape(-1, 3)).reshape(mids.shape).float()
            # Rays crossing no occupied cell fall back to uniform samples.
            empty = occupied.sum(dim=-1, keepdim=True) == 0
            occupied = torch.where(empty, torch.ones_like(occupied), occupied)
            t = sample_pdf(edges, occupied, self.n_coarse, jitter)
        else:
            steps = torch.arange(self.n_coarse, device=origins.device, dtype=origins.dtype)
            offsets = jitter if jitter is not None else 0.5
            t = t_near[:, None] + (t_far - t_near)[:, None] * (steps + offsets) / self.n_coarse
        if self.up_rounds == 0:
            return t
        sdf = _eval_sdf(sdf_fn, origins, dirs, t, self.chunk)
        per_round = self.n_importance // self.up_rounds
        for i in range(self.up_rounds):
            t_new = upsample_neus(t, sdf, per_round, self.up_base_inv_s * 2**i)
            t, order = torch.sort(torch.cat([t, t_new], dim=-1), dim=-1)
            if i + 1 < self.up_rounds:
                sdf_new = _eval_sdf(sdf_fn, origins, dirs, t_new, self.chunk)
                sdf = torch.cat([sdf, sdf_new], dim=-1).gather(1, order)
        return t


def intervals_from_samples(
    t: torch.Tensor,  # (n_rays, n_samples)
) -> tuple[torch.Tensor, torch.Tensor]:
    """Interval midpoints and lengths for sorted sample distances (NeuS convention).

    Interval ``i`` runs from ``t_i`` to ``t_{i+1}``; the last one gets the mean length.

    Returns:
        mids: (n_rays, n_samples).
        deltas: (n_rays, n_samples).

    Note:
        Not differentiable in practice (``t`` carries no gradient).
    """
    deltas = t[:, 1:] - t[:, :-1]
    last = deltas.mean(dim=-1, keepdim=True) if deltas.shape[1] else torch.full_like(t, 1e-2)
    deltas = torch.cat([deltas, last], dim=-1)
    return t + 0.5 * deltas, deltas
