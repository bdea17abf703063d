"""The crop cylinder that bounds a scene, and the box a field's grid spans around it.

The scene preset's crop is a vertical cylinder ``x^2 + z^2 <= r^2``, ``y_min <= y <= y_max``,
given as ``(r, y_min, y_max)``; nothing outside it is ever rendered or meshed.
"""

from __future__ import annotations

import torch

from hybridneus.errors import ConfigError


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


#: The whole reconstruction volume, [-1, 1]^3 as (lo, hi): the grid's span before
#: ``grid.domain`` existed, and what checkpoints without a saved ``grid_box`` were trained on.
VOLUME_BOX = (-1.0, -1.0, -1.0, 1.0, 1.0, 1.0)


def grid_box(crop: tuple[float, float, float], domain: str = "crop",
             margin: float = 0.3) -> tuple[float, ...]:
    """The box (lo_x, lo_y, lo_z, hi_x, hi_y, hi_z) that a field's feature grid spans.

    Args:
        crop: (radius, y_min, y_max) of the crop cylinder.
        domain: ``crop``: the cube centred on the crop's box (clipped to [-1, 1]^3) whose
            half-side is ``1 + margin`` times the box's largest half-extent, or the whole
            volume when that cube is at least as large; ``volume``: [-1, 1]^3.
        margin: growth of the cube beyond the crop's box, so that the regularisers' random
            points (the box grown by ``loss.random_box_margin`` of its side on each side: 0.3
            of the half-extent at the default 0.15) stay inside the grid.

    Raises:
        ConfigError: unknown ``domain`` or a negative ``margin``.
    """
    if domain not in ("crop", "volume"):
        raise ConfigError(f"grid.domain: unknown {domain!r}; expected crop or volume")
    if margin < 0:
        raise ConfigError(f"grid.domain_margin: must be >= 0, got {margin}")
    if domain == "volume":
        return VOLUME_BOX
    box = crop_aabb(torch.tensor([float(c) for c in crop])).tolist()
    lo, hi = box[:3], box[3:]
    half = (1.0 + margin) * max((b - a) / 2 for a, b in zip(lo, hi, strict=True))
    if half >= 1.0:
        return VOLUME_BOX
    centre = [(a + b) / 2 for a, b in zip(lo, hi, strict=True)]
    return tuple([c - half for c in centre] + [c + half for c in centre])
