"""NeuS volume rendering: unbiased opacity from SDF samples, weights and compositing.

All functions work on the batched layout ``(n_rays, n_samples)``: sample ``i`` of a ray is
the interval ``[t_starts[i], t_ends[i]]`` with its point at the midpoint.
"""

from __future__ import annotations

import math

import torch

from hybridneus.model.eventneus import TAIL_CUTOFF

_FLOOR = math.exp(-TAIL_CUTOFF)


def _cdf(sdf_times_s: torch.Tensor) -> torch.Tensor:
    """``sigmoid``, with its tail below ``exp(-TAIL_CUTOFF)`` held there: far inside a
    surface the true value and its derivative are subnormal floats, slow on x86 CPUs."""
    return torch.sigmoid(sdf_times_s.clamp_min(-TAIL_CUTOFF))


def alpha_from_sdf(
    sdf: torch.Tensor,  # (n_rays, n_samples)
    dir_dot_grad: torch.Tensor,  # (n_rays, n_samples)
    deltas: torch.Tensor,  # (n_rays, n_samples)
    inv_s: torch.Tensor | float,
) -> torch.Tensor:
    r"""Discrete opacity of each interval from the SDF at its midpoint (NeuS, unbiased).

    The SDF at the interval ends is estimated from the midpoint value and the directional
    derivative, then

    .. math::
        \alpha_i = \max\Big(\frac{\Phi_s(f(t_i)) - \Phi_s(f(t_{i+1}))}{\Phi_s(f(t_i))}, 0\Big),
        \quad \Phi_s(x) = \mathrm{sigmoid}(s x).

    The cosine is clamped to be non-positive (only surfaces entered from outside are opaque).

    Args:
        sdf: SDF at the interval midpoints, (n_rays, n_samples).
        dir_dot_grad: ray direction dotted with the SDF gradient there, (n_rays, n_samples).
        deltas: interval lengths, (n_rays, n_samples).
        inv_s: NeuS sharpness s (scalar tensor or float).

    Returns:
        alpha: opacities in [0, 1], (n_rays, n_samples).

    Note:
        Differentiable (and twice differentiable) in ``sdf``, ``dir_dot_grad`` and ``inv_s``.
    """
    iter_cos = -torch.relu(-dir_dot_grad)
    prev_sdf = sdf - iter_cos * deltas * 0.5
    next_sdf = sdf + iter_cos * deltas * 0.5
    prev_cdf = _cdf(prev_sdf * inv_s)
    next_cdf = _cdf(next_sdf * inv_s)
    alpha = (prev_cdf - next_cdf + 1e-5) / (prev_cdf + 1e-5)
    return alpha.clamp(0.0, 1.0)


def alpha_from_sdf_pairs(
    sdf_start: torch.Tensor,  # (n_rays, n_samples)
    sdf_end: torch.Tensor,  # (n_rays, n_samples)
    inv_s: torch.Tensor | float,
) -> torch.Tensor:
    """Opacity of intervals from the SDF at both ends (used when placing samples).

    Args:
        sdf_start: SDF at the interval starts, (n_rays, n_samples).
        sdf_end: SDF at the interval ends, (n_rays, n_samples).
        inv_s: sharpness.

    Returns:
        alpha: (n_rays, n_samples) in [0, 1].

    Note:
        Differentiable, but only used under ``torch.no_grad`` for sample placement.
    """
    prev_cdf = _cdf(sdf_start * inv_s)
    next_cdf = _cdf(sdf_end * inv_s)
    return ((prev_cdf - next_cdf + 1e-5) / (prev_cdf + 1e-5)).clamp(0.0, 1.0)


def transmittance_from_alpha(alpha: torch.Tensor) -> torch.Tensor:
    """Light reaching each interval's start: exclusive product of ``1 - alpha``.

    Args:
        alpha: (n_rays, n_samples).

    Returns:
        transmittance: (n_rays, n_samples), 1 for the first sample.

    Note:
        Differentiable.
    """
    ones = torch.ones_like(alpha[..., :1])
    t = torch.cumprod(torch.cat([ones, 1.0 - alpha + 1e-7], dim=-1), dim=-1)[..., :-1]
    # Behind an opaque surface the product falls by 1e-7 a sample into the subnormal floats,
    # and the weights' gradients with it; below exp(-TAIL_CUTOFF) it is held at exact zero.
    return t * (t > _FLOOR)


def weights_from_alpha(alpha: torch.Tensor) -> torch.Tensor:
    """Rendering weights ``T_i * alpha_i``; each ray's weights sum to at most 1.

    Args:
        alpha: (n_rays, n_samples).

    Returns:
        weights: (n_rays, n_samples).

    Note:
        Differentiable.
    """
    return alpha * transmittance_from_alpha(alpha)


def composite(
    weights: torch.Tensor,  # (n_rays, n_samples)
    values: torch.Tensor,  # (n_rays, n_samples, n_channels)
    background: torch.Tensor | None = None,  # (n_channels,) or (n_rays, n_channels)
) -> torch.Tensor:
    """Weighted sum of per-sample values, with the background filling the remaining weight.

    Args:
        weights: (n_rays, n_samples).
        values: (n_rays, n_samples, n_channels), e.g. colours.
        background: constant or per-ray colour; ``None`` composites over zero.

    Returns:
        composited: (n_rays, n_channels).

    Note:
        Differentiable in all inputs.
    """
    out = (weights.unsqueeze(-1) * values).sum(dim=-2)
    if background is not None:
        out = out + (1.0 - weights.sum(dim=-1, keepdim=True)) * background
    return out
