"""Loss functions of event-supervised NeuS training; each returns a scalar tensor.

:mod:`hybridneus.training.objective` and the priors combine them into a step's terms.
"""

from __future__ import annotations

import torch


def log_intensity_diff_from_colors(
    c0: torch.Tensor,  # (n_rays, 3)
    c1: torch.Tensor,  # (n_rays, 3)
    eps: float,
    gamma: float = 2.2,
) -> torch.Tensor:
    """Per-channel log-brightness change ``log(c1^gamma + eps) - log(c0^gamma + eps)``.

    Args:
        c0: rendered colour at the window start, (n_rays, 3), in [0, 1].
        c1: rendered colour at the window end, (n_rays, 3).
        eps: the scene preset's ``tonemap_eps``.
        gamma: display gamma. Default: 2.2.

    Returns:
        d: (n_rays, 3).

    Note:
        Differentiable in ``c0`` and ``c1``.
    """
    c0 = c0.clamp_min(0.0)
    c1 = c1.clamp_min(0.0)
    return torch.log(c1**gamma + eps) - torch.log(c0**gamma + eps)


def event_loss(
    c0: torch.Tensor,  # (n_rays, 3)
    c1: torch.Tensor,  # (n_rays, 3)
    target: torch.Tensor,  # (n_rays,)
    bayer: torch.Tensor,  # (n_rays, 3)
    eps: float,
) -> torch.Tensor:
    r"""EventNeRF / EventNeuS event loss on a batch of pixels.

    .. math::
        d = \log(c_1^{2.2} + \epsilon) - \log(c_0^{2.2} + \epsilon), \qquad
        L = \mathrm{mean}_{\text{rays}}\big(\textstyle\sum_{ch} M_{ch}\, d_{ch} - C E\big)^2

    where ``M`` is the pixel's one-hot RGGB Bayer mask and ``C E`` the accumulated event
    frame times the threshold (polarity offset included), as given by the batch's ``target``.

    Args:
        c0: colour rendered at the window start pose, (n_rays, 3).
        c1: colour rendered at the window end pose, (n_rays, 3).
        target: C * E, (n_rays,).
        bayer: one-hot Bayer channel of each pixel, (n_rays, 3).
        eps: ``tonemap_eps`` of the scene preset.

    Returns:
        loss: scalar.

    Note:
        Differentiable in ``c0`` and ``c1``.
    """
    d = log_intensity_diff_from_colors(c0, c1, eps)
    pred = (bayer * d).sum(dim=-1)
    return ((pred - target) ** 2).mean()


def rgb_loss(color: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean squared colour error (RGB-frame supervision, the benchmarks' upper bound).

    Args:
        color: rendered colour, (n_rays, 3).
        target: frame colour in [0, 1], (n_rays, 3).

    Returns:
        loss: scalar.
    """
    return ((color - target) ** 2).sum(dim=-1).mean()


def eikonal_loss(gradients: torch.Tensor, weights: torch.Tensor | None = None) -> torch.Tensor:
    """Mean of ``(|grad sdf| - 1)^2`` over points.

    Args:
        gradients: (n_points, 3), with a graph for double backward.
        weights: optional (n_points,) weights of a weighted mean (0 leaves a point out
            without indexing, which would make a GPU wait for the count).

    Returns:
        loss: scalar.

    Note:
        Differentiable (needs the gradient computed with ``create_graph=True``).
    """
    per_point = (gradients.norm(dim=-1) - 1.0) ** 2
    return _mean(per_point, weights)


def _mean(values: torch.Tensor, weights: torch.Tensor | None) -> torch.Tensor:
    """Mean, or weighted mean (0 when every weight is 0)."""
    if weights is None:
        return values.mean()
    return (values * weights).sum() / weights.sum().clamp_min(1e-12)


def curvature_loss(
    grad_a: torch.Tensor, grad_b: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Mean squared change of unit normals between points and their offset copies.

    Args:
        grad_a: SDF gradients at points, (n_points, 3).
        grad_b: SDF gradients at the points shifted by a small random offset, (n_points, 3).
        weights: optional (n_points,) weights of a weighted mean.

    Returns:
        loss: scalar.

    Note:
        Differentiable.
    """
    na = torch.nn.functional.normalize(grad_a, dim=-1)
    nb = torch.nn.functional.normalize(grad_b, dim=-1)
    return _mean(((na - nb) ** 2).sum(dim=-1), weights)


def outside_loss(sdf: torch.Tensor, outside: torch.Tensor) -> torch.Tensor:
    """Mean of ``relu(-sdf)`` over the points known to be empty (0 when there are none).

    Used for the points outside the crop cylinder and those the events' visual hull calls
    empty. Nothing outside the crop is rendered, and space the cameras never see against
    the background costs no event error, so no event keeps matter out of either; negative
    values there (left over from initialisation, or grown) cap or fill meshes. This soft
    penalty pushes them positive without clamping the SDF (a hard clamp collapses training).

    Args:
        sdf: SDF at random points, (n_points,).
        outside: (n_points,) bool, True where the point is known to be empty.

    Returns:
        loss: scalar.

    Note:
        Differentiable in ``sdf``. Masked by multiplication, not indexing: no host sync on a
        GPU (boolean indexing and ``any()`` wait for the device).
    """
    weight = outside.to(sdf.dtype)
    return (torch.relu(-sdf) * weight).sum() / weight.sum().clamp(min=1.0)
