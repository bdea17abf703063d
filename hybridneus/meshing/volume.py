"""The sampling volume of mesh extraction: world-space bounds, crop cylinder, voxel grid, and
the chunked SDF queries over it."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from hybridneus.model.protocol import Field

Bounds = tuple[tuple[float, float, float], tuple[float, float, float]]

DEFAULT_BOUNDS: Bounds = ((-1.0, -1.0, -1.0), (1.0, 1.0, 1.0))


@dataclass(frozen=True)
class CropVolume:
    """The reference code's crop: the cylinder x^2 + z^2 <= r^2 with y_min <= y <= y_max."""

    r: float
    y_min: float
    y_max: float

    @property
    def bounds(self) -> Bounds:
        """The axis-aligned box around the cylinder, ((x, y, z)_min, (x, y, z)_max)."""
        return ((-self.r, self.y_min, -self.r), (self.r, self.y_max, self.r))

    def padded_bounds(self, pad: float = 0.02, limit: float = 1.0) -> Bounds:
        """:attr:`bounds` grown by ``pad`` x the longest side, cut to [-limit, limit]^3.

        The padding leaves grid points outside the crop, so marching cubes closes surfaces
        that end on it (a trained field is cut by the crop: ``max(sdf, crop_sdf)``).
        """
        lo, hi = (np.asarray(b, dtype=np.float64) for b in self.bounds)
        margin = pad * float((hi - lo).max())
        lo = np.maximum(lo - margin, -limit)
        hi = np.minimum(hi + margin, limit)
        return tuple(lo.tolist()), tuple(hi.tolist())  # type: ignore[return-value]

    @classmethod
    def of_field(cls, field_: object) -> CropVolume | None:
        """The crop a field carries (a trained field's ``crop`` buffer, (r, y_min, y_max)),
        or ``None`` for a field without one (the analytic shapes)."""
        values = getattr(field_, "crop", None)
        if values is None:
            return None
        return cls(*(float(v) for v in values))

    def boundary_distance(self, points: np.ndarray) -> np.ndarray:
        """Unsigned distance (n,) from each of ``points`` (n, 3) to the cylinder's surface.

        Exact inside and beside the cylinder; outside its rims the larger of the radial and
        vertical distances (a lower bound), which is all that near-surface tests need.
        """
        radial = np.sqrt(points[:, 0] ** 2 + points[:, 2] ** 2) - self.r
        vertical = np.maximum(self.y_min - points[:, 1], points[:, 1] - self.y_max)
        inside = np.minimum(np.abs(radial), np.abs(vertical))
        return np.where((radial <= 0) & (vertical <= 0), inside, np.maximum(radial, vertical))

    def boundary_normal(self, points: np.ndarray) -> np.ndarray:
        """Outward unit normal (n, 3) of the part of the cylinder (side, floor, top) nearest
        to each of ``points`` (n, 3); points on the axis get the floor's or top's normal."""
        rho = np.sqrt(points[:, 0] ** 2 + points[:, 2] ** 2)
        gaps = np.stack([np.abs(rho - self.r), np.abs(points[:, 1] - self.y_min),
                         np.abs(points[:, 1] - self.y_max)], axis=1)
        gaps[rho < 1e-12, 0] = np.inf
        part = gaps.argmin(axis=1)
        normals = np.zeros_like(points, dtype=np.float64)
        side = part == 0
        normals[side, 0] = points[side, 0] / rho[side]
        normals[side, 2] = points[side, 2] / rho[side]
        normals[part == 1, 1] = -1.0
        normals[part == 2, 1] = 1.0
        return normals

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether each of ``points`` (n_points, 3) lies inside (grown by ``margin``) -> (n,)."""
        radial = points[:, 0] ** 2 + points[:, 2] ** 2 <= (self.r + margin) ** 2
        vertical = (points[:, 1] >= self.y_min - margin) & (points[:, 1] <= self.y_max + margin)
        return radial & vertical


def check_bounds(bounds: Sequence[Sequence[float]]) -> Bounds:
    """Validate ``((x0, y0, z0), (x1, y1, z1))`` with x1 > x0 etc.; return it as floats."""
    lo, hi = (tuple(float(v) for v in corner) for corner in bounds)
    if len(lo) != 3 or len(hi) != 3 or not all(h > l for l, h in zip(lo, hi, strict=True)):
        raise ValueError(f"bounds {bounds!r}: expected ((x0, y0, z0), (x1, y1, z1)) with x1 > x0")
    return lo, hi  # type: ignore[return-value]


@dataclass(frozen=True)
class VoxelGrid:
    """A regular grid of sample points with cubic voxels.

    Point (i, j, k) sits at ``origin + voxel * (i, j, k)``; ``shape`` counts points per axis.
    ``res`` points span the longest side of the bounds; shorter sides get as many points as
    needed to cover them with the same voxel size (so the grid may overhang by < 1 voxel).
    """

    origin: np.ndarray
    voxel: float
    shape: tuple[int, int, int]

    @classmethod
    def from_bounds(cls, bounds: Bounds, res: int) -> VoxelGrid:
        """The grid with ``res`` points along the longest side of ``bounds``."""
        if res < 2:
            raise ValueError(f"res {res}: need at least 2 points per axis")
        lo, hi = check_bounds(bounds)
        extent = np.asarray(hi, dtype=np.float64) - np.asarray(lo, dtype=np.float64)
        voxel = float(extent.max()) / (res - 1)
        shape = tuple(max(2, math.ceil(e / voxel - 1e-6) + 1) for e in extent)
        return cls(np.asarray(lo, dtype=np.float64), voxel, shape)  # type: ignore[arg-type]

    def points(self, ix: np.ndarray, iy: np.ndarray, iz: np.ndarray) -> np.ndarray:
        """World points (n_points, 3) float32 of integer grid indices, each (n_points,)."""
        # float32 throughout: indices < 2^24 are exact and res^3 float64 copies are costly.
        out = np.empty((np.shape(ix)[0], 3), dtype=np.float32)
        for axis, idx in enumerate((ix, iy, iz)):
            np.multiply(idx, np.float32(self.voxel), out=out[:, axis], casting="unsafe")
            out[:, axis] += np.float32(self.origin[axis])
        return out

    def to_index(self, points: np.ndarray) -> np.ndarray:
        """Continuous grid coordinates (n_points, 3) float64 of world ``points``."""
        return (np.asarray(points, dtype=np.float64) - self.origin) / self.voxel

    def to_world(self, index_coords: np.ndarray) -> np.ndarray:
        """World coordinates (n_points, 3) float64 of continuous grid coordinates."""
        return self.origin + self.voxel * np.asarray(index_coords, dtype=np.float64)


def evaluate_sdf(field_: Field, points: np.ndarray, chunk: int = 2**18) -> np.ndarray:
    """Query ``field_.sdf`` at ``points`` (n_points, 3) in chunks -> (n_points,) float32.

    Note:
        Runs under ``torch.no_grad()``; values are copied back to the CPU chunk by chunk.
    """
    out = np.empty(points.shape[0], dtype=np.float32)
    with torch.no_grad():
        for start in range(0, points.shape[0], chunk):
            p = torch.from_numpy(np.ascontiguousarray(points[start : start + chunk]))
            d = field_.sdf(p.to(field_.device, torch.float32))
            out[start : start + chunk] = d.reshape(-1).float().cpu().numpy()
    return out
