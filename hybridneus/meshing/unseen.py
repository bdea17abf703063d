"""Space that no training camera saw, and filling it before marching cubes.

Events say nothing about space that no camera can see, so a trained field is free to leave
it empty or full. The EventNeRF captures circle the object from above the equator only, so
the underside is such space: a fit may open a cave from the bottom up into the object, with
walls that are never rendered and so never corrected. Chamfer distance counts those walls.

:func:`unseen_space` finds the empty space (SDF > 0) that is hidden from every camera by the
field's own surface, keeps the part that lies within the morphological closing of the
field's matter (pockets that matter nearly surrounds, rather than the open wedge below a flat
underside, which the closing leaves out), drops the slivers of it thinner than a few voxels,
and returns the signed distance to that region.
:class:`FilledField` wraps a field so that its SDF is ``min(sdf, distance)``: the union of
the field's matter and the filled pockets. Mesh extraction runs on the wrapped field.

All of this only reads the trained field; nothing is written back to it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from hybridneus.meshing.volume import Bounds, VoxelGrid, evaluate_sdf
from hybridneus.model.protocol import Field, as_points


@dataclass
class UnseenSpace:
    """The space to fill, as a signed distance on a voxel grid.

    Attributes:
        grid: the grid the distance is sampled on (its bounds are those meshed).
        distance: (nx, ny, nz) float32 signed distance in world units to the filled region,
            negative inside it.
        filled: voxels filled (hidden from every camera and inside the closing of matter).
        hidden: empty voxels hidden from every camera, before the closing's restriction.
        cameras: camera centres used.
    """

    grid: VoxelGrid
    distance: np.ndarray
    filled: int
    hidden: int
    cameras: int


def spread_cameras(centres: np.ndarray, n: int, around: np.ndarray | None = None) -> np.ndarray:
    """Up to ``n`` of ``centres`` (n_views, 3) spread over the directions they see from.

    Farthest-point sampling on the unit directions from ``around`` (default the origin), so a
    spiral that dwells near the equator still contributes its few views near the pole.
    """
    centres = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    if len(centres) <= n:
        return centres
    d = centres - (np.zeros(3) if around is None else np.asarray(around, np.float64))
    d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
    chosen = [0]
    gap = np.full(len(d), np.inf)
    for _ in range(n - 1):
        gap = np.minimum(gap, np.linalg.norm(d - d[chosen[-1]], axis=1))
        chosen.append(int(gap.argmax()))
    return centres[chosen]


def _hidden_from_all(
    sdf: np.ndarray, grid: VoxelGrid, cameras: np.ndarray, candidates: np.ndarray
) -> np.ndarray:
    """Flat indices of ``candidates`` (grid points) from which every camera's line of sight
    meets the zero level of ``sdf`` (the volume's marching-cubes surface)."""
    import open3d as o3d

    scene = occluder(sdf, grid)
    shape = tuple(sdf.shape)
    for centre in cameras:
        if candidates.size == 0:
            break
        origins = grid.points(*np.unravel_index(candidates, shape))  # float32
        dirs = centre.astype(np.float32) - origins
        dist = np.linalg.norm(dirs, axis=1)
        dirs /= np.maximum(dist, 1e-12)[:, None]
        hit = scene.cast_rays(o3d.core.Tensor(np.hstack([origins, dirs])))["t_hit"].numpy()
        candidates = candidates[hit < dist]  # blocked on the way: still unseen
    return candidates


def occluder(sdf: np.ndarray, grid: VoxelGrid):
    """An Open3D ``RaycastingScene`` of the zero level of ``sdf`` (sampled on ``grid``), in
    world coordinates: what hides space from a camera."""
    import open3d as o3d
    from skimage.measure import marching_cubes

    verts, faces, _, _ = marching_cubes(sdf, 0.0)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(grid.to_world(verts).astype(np.float32)),
        o3d.core.Tensor(faces.astype(np.uint32)),
    )
    return scene


def region_space(fill: np.ndarray, grid: VoxelGrid, hidden: int, cameras: int) -> UnseenSpace:
    """The :class:`UnseenSpace` of the voxels ``fill`` (bool, on ``grid``; changed in place):
    the box's faces are left empty, what reaches them is cut there as the crop cuts matter."""
    from scipy import ndimage

    shape = tuple(grid.shape)
    fill[[0, -1]] = False
    fill[:, [0, -1]] = False
    fill[:, :, [0, -1]] = False
    if fill.any():
        distance = ndimage.distance_transform_edt(~fill) - ndimage.distance_transform_edt(fill)
    else:
        distance = np.full(shape, float(max(shape)))
    return UnseenSpace(grid=grid, distance=(distance * grid.voxel).astype(np.float32),
                       filled=int(fill.sum()), hidden=hidden, cameras=cameras)


def _closing(solid: np.ndarray, radius: float) -> np.ndarray:
    """Morphological closing of ``solid`` with a ball of ``radius`` voxels (Euclidean)."""
    from scipy import ndimage

    grown = ndimage.distance_transform_edt(~solid) <= radius
    return (ndimage.distance_transform_edt(grown) > radius) | solid


def _opening(region: np.ndarray, radius: float) -> np.ndarray:
    """Morphological opening of ``region`` with a ball of ``radius`` voxels: the parts of it
    that such a ball fits in."""
    from scipy import ndimage

    core = ndimage.distance_transform_edt(region) > radius
    return (ndimage.distance_transform_edt(~core) <= radius) & region


def unseen_space(
    field_: Field,
    cameras: np.ndarray,
    bounds: Bounds,
    res: int = 128,
    close_radius: float = 0.1,
    min_thickness: float = 4.0,
    max_cameras: int = 192,
    chunk: int = 2**18,
) -> UnseenSpace:
    """The pockets of empty space that no camera sees, as a signed distance (see module doc).

    Args:
        field_: the trained field (only ``sdf`` is queried).
        cameras: camera centres (n_views, 3) in world coordinates.
        bounds: the world box to examine (the box that will be meshed).
        res: grid points along the box's longest side.
        close_radius: radius of the closing ball, as a fraction of the box's longest side;
            hidden space farther than this from matter on some side is left empty.
        min_thickness: in grid voxels; parts of the fill that a ball of this diameter does
            not fit in (a morphological opening) are left empty: thin slivers along a
            surface, such as the shallow hidden strip under an uneven flat bottom.
        max_cameras: cameras tested (spread by :func:`spread_cameras`).
        chunk: points per field query.

    Raises:
        ValueError: no cameras, or a non-finite camera centre.
    """
    cameras = np.asarray(cameras, dtype=np.float64).reshape(-1, 3)
    if len(cameras) == 0 or not np.isfinite(cameras).all():
        raise ValueError("cameras: expected finite camera centres (n_views >= 1, 3)")
    grid = VoxelGrid.from_bounds(bounds, res)
    shape = tuple(grid.shape)
    centre = grid.origin + 0.5 * grid.voxel * (np.asarray(shape) - 1)
    chosen = spread_cameras(cameras, max_cameras, around=centre)
    ix, iy, iz = np.indices(shape).reshape(3, -1)
    sdf = evaluate_sdf(field_, grid.points(ix, iy, iz), chunk).reshape(shape)
    solid = sdf <= 0
    empty = np.flatnonzero(~solid)
    if not solid.any() or empty.size == 0:
        hidden = np.zeros(0, dtype=np.int64)
    else:
        hidden = _hidden_from_all(sdf, grid, chosen, empty)
    fill = np.zeros(shape, dtype=bool)
    fill.flat[hidden] = True
    radius = close_radius * (max(shape) - 1)
    if hidden.size:
        fill &= _closing(solid, radius)
    if min_thickness > 0 and fill.any():
        fill = _opening(fill, 0.5 * min_thickness)
    return region_space(fill, grid, int(hidden.size), len(chosen))


class FilledField:
    """A field whose matter is the union of ``field_``'s and the ``unseen`` pockets.

    ``sdf`` is ``min(field_.sdf, unseen distance)``, the distance trilinearly interpolated
    on its grid (outside the grid, ``field_.sdf`` alone); colours and gradients are
    ``field_``'s own. Like a trained field, it takes numpy (and returns numpy) or torch
    tensors on any device (and returns tensors on ``device``).
    """

    def __init__(self, field_: Field, unseen: UnseenSpace) -> None:
        self.field = field_
        self.device = field_.device
        self.unseen = unseen
        g = unseen.grid
        self._volume = torch.from_numpy(unseen.distance)[None, None].to(self.device)
        self._origin = torch.as_tensor(g.origin, dtype=torch.float32, device=self.device)
        self._span = torch.as_tensor(
            g.voxel * (np.asarray(g.shape) - 1), dtype=torch.float32, device=self.device
        )

    def __getattr__(self, name: str):
        # crop, background and the rest of the wrapped field's attributes
        field_ = self.__dict__.get("field")
        if field_ is None:
            raise AttributeError(name)
        return getattr(field_, name)

    def _distance(self, points: torch.Tensor) -> torch.Tensor:
        u = (points.float() - self._origin) / self._span * 2 - 1
        # grid_sample indexes (x, y, z) of a (D, H, W) volume as (W, H, D)
        coords = u[:, [2, 1, 0]].reshape(1, -1, 1, 1, 3)
        d = torch.nn.functional.grid_sample(
            self._volume, coords, mode="bilinear", align_corners=True, padding_mode="border"
        ).reshape(-1)
        beyond = ((u < -1) | (u > 1)).any(dim=1)
        return torch.where(beyond, torch.full_like(d, float("inf")), d)

    def sdf(self, points: Any) -> Any:
        """``min(field.sdf, distance to the filled pockets)`` at ``points`` (n, 3) -> (n,)."""
        pts, was_numpy = as_points(points, self.device)
        own = self.field.sdf(pts)
        out = torch.minimum(own, self._distance(pts).to(own.dtype).reshape(own.shape))
        return out.cpu().numpy() if was_numpy else out

    def sdf_and_gradient(self, points: Any) -> tuple[Any, Any]:
        """The wrapped field's SDF gradient; the SDF value as :meth:`sdf`."""
        pts, was_numpy = as_points(points, self.device)
        own, grad = self.field.sdf_and_gradient(pts)
        filled = self._distance(pts.detach()).to(own.dtype).reshape(own.shape)
        out = torch.minimum(own, filled)
        if was_numpy:
            return out.cpu().numpy(), grad.cpu().numpy()
        return out, grad

    def color(self, points: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
        """The wrapped field's colour."""
        return self.field.color(points, dirs)
