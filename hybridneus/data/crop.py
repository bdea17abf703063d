"""The crop cylinder that bounds a scene.

The scene preset's crop is a vertical cylinder ``x^2 + z^2 <= r^2``, ``y_min <= y <= y_max``,
given as ``(r, y_min, y_max)``; nothing outside it is ever rendered or meshed.
"""

from __future__ import annotations

import torch


def crop_sdf(points: torch.Tensor, crop: torch.Tensor) -> torch.Tensor:
    """Signed distance (approximate outside the corners) to the crop cylinder.

    Args:
        points: (n_points, 3) world points.
        crop: (3,) radius, y_min, y_max.

    Returns:
        sdf: (n_points,), negative inside the cylinder.

    Note:
        Differentiable in ``points``.
    """
    radial = torch.sqrt(points[:, 0] ** 2 + points[:, 2] ** 2 + 1e-12) - crop[0]
    vertical = torch.maximum(crop[1] - points[:, 1], points[:, 1] - crop[2])
    return torch.maximum(radial, vertical)


def crop_aabb(crop: torch.Tensor) -> torch.Tensor:
    """Box (6,) around the crop cylinder, clipped to [-1, 1]^3."""
    r, y0, y1 = (float(v) for v in crop)
    lo = torch.tensor([-r, y0, -r]).clamp(-1.0, 1.0)
    hi = torch.tensor([r, y1, r]).clamp(-1.0, 1.0)
    return torch.cat([lo, hi])
