"""Marching-cubes mesh extraction from a field, with narrow-band evaluation in bounded memory.

The cost of meshing is querying the field, not marching cubes. So the field is first evaluated
on a coarse grid (every ``coarse_factor``-th point per axis); a block of the fine grid between
coarse points is *active* when the zero level may pass through it: its corners change sign, or
one of them is closer to zero than the block's half diagonal times ``band_safety`` (for a true
distance function, |grad sdf| = 1, the surface cannot be farther from the nearest corner than
the half diagonal). Active blocks are grown by ``band_dilate`` blocks to absorb fields whose
gradient norm is not 1. Only fine points of active blocks are evaluated; the others are filled
with a large value of their block's sign, which marching cubes never crosses.

The fine grid is processed in slabs along x whose float32 volume stays under ``slab_bytes``;
each slab is meshed on its own and the vertices on the shared planes are welded, so memory
does not grow with res^3 (res 1024 needs ~0.3 GB per slab plus the mesh itself).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import trimesh

from hybridneus.meshing.volume import (
    DEFAULT_BOUNDS,
    Bounds,
    CropVolume,
    VoxelGrid,
    evaluate_sdf,
)
from hybridneus.model.protocol import Field
from hybridneus.progress import make_progress


@dataclass
class ExtractionStats:
    """What an extraction evaluated: counts of field queries and the active share of the grid."""

    grid_shape: tuple[int, int, int] = (0, 0, 0)
    voxel: float = 0.0
    coarse_points: int = 0
    fine_points: int = 0
    slabs: int = 0
    filled_voxels: int = 0
    times: dict[str, float] = field(default_factory=dict)

    @property
    def active_fraction(self) -> float:
        """Share of the full fine grid whose SDF was evaluated."""
        total = int(np.prod(self.grid_shape))
        return self.fine_points / total if total else 0.0


def _block_axes(n: int, block: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Per fine index along one axis: the block it starts in, and the block it closes.

    Fine index i belongs to block i // block; a boundary index (i % block == 0, i > 0) is also
    the last point of block i // block - 1. Returns (first (n,), second (n,), n_blocks).
    """
    n_blocks = max(1, math.ceil((n - 1) / block))
    idx = np.arange(n)
    first = np.minimum(idx // block, n_blocks - 1)
    second = np.where((idx % block == 0) & (idx > 0), idx // block - 1, first)
    return first, second, n_blocks


def _coarse_indices(n: int, block: int, n_blocks: int) -> np.ndarray:
    """Fine indices of the coarse nodes along one axis: 0, block, 2 block, ..., n - 1."""
    return np.minimum(np.arange(n_blocks + 1) * block, n - 1)


def _active_blocks(
    coarse: np.ndarray, half_diag: float, band_safety: float, band_dilate: int
) -> np.ndarray:
    """Blocks (n_bx, n_by, n_bz) bool that the zero level may cross, from corner SDFs."""
    sx, sy, sz = (n - 1 for n in coarse.shape)
    corners = [
        coarse[a : a + sx, b : b + sy, c : c + sz]
        for a in (0, 1)
        for b in (0, 1)
        for c in (0, 1)
    ]
    stack = np.stack(corners, axis=0)
    near = np.abs(stack).min(axis=0) <= band_safety * half_diag
    crossing = (stack.min(axis=0) <= 0.0) & (stack.max(axis=0) >= 0.0)
    active = near | crossing
    for _ in range(band_dilate):
        grown = active.copy()
        grown[1:] |= active[:-1]
        grown[:-1] |= active[1:]
        grown[:, 1:] |= active[:, :-1]
        grown[:, :-1] |= active[:, 1:]
        grown[:, :, 1:] |= active[:, :, :-1]
        grown[:, :, :-1] |= active[:, :, 1:]
        active = grown
    return active


def _weld_planes(
    verts: np.ndarray, faces: np.ndarray, planes: Sequence[int]
) -> tuple[np.ndarray, np.ndarray]:
    """Merge the duplicate vertices that two slabs both produce on their shared x planes."""
    if not planes:
        return verts, faces
    on_plane = np.isin(verts[:, 0], np.asarray(planes, dtype=verts.dtype))
    cand = np.nonzero(on_plane)[0]
    if cand.size == 0:
        return verts, faces
    # Both slabs interpolate the same edge from the same two values, so coordinates agree to
    # rounding; keys at 1e-6 voxel tell distinct edges apart and join the copies.
    keys = np.round(verts[cand] * 1e6).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    remap = np.arange(verts.shape[0])
    remap[cand] = cand[first[inverse.reshape(-1)]]
    keep = np.ones(verts.shape[0], dtype=bool)
    keep[cand] = False
    keep[cand[first]] = True
    new_index = np.cumsum(keep) - 1
    faces = new_index[remap[faces]]
    return verts[keep], faces


def _evaluate_into(
    field_: Field,
    grid: VoxelGrid,
    vol: np.ndarray,
    mask: np.ndarray,
    x0: int,
    chunk: int,
    fill: np.float32,
) -> int:
    """Write the SDF at the slab points where ``mask`` is set into ``vol``; return the count.

    Non-finite values (a diverged field) count as outside (+``fill``), with a warning, so
    that marching cubes still runs and the rest of the surface is kept.
    """
    flat = np.flatnonzero(mask)
    if flat.size:
        ny, nz = vol.shape[1:]
        ix = flat // (ny * nz)
        rest = flat - ix * (ny * nz)
        iy = rest // nz
        iz = rest - iy * nz
        del rest
        values = evaluate_sdf(field_, grid.points(ix + x0, iy, iz), chunk)
        bad = ~np.isfinite(values)
        if bad.any():
            warnings.warn(
                f"field returned {int(bad.sum())} non-finite SDF values; treated as outside",
                RuntimeWarning,
                stacklevel=3,
            )
            values[bad] = fill
        vol.reshape(-1)[flat] = values
    return int(flat.size)


def _expand(blocks: np.ndarray, axes: Sequence[tuple[np.ndarray, np.ndarray, int]]) -> np.ndarray:
    """Per grid point: whether any block it belongs to is set (blocks -> points, bool)."""
    out = blocks
    for axis in (2, 1, 0):
        first, second = axes[axis][0], axes[axis][1]
        out = np.take(out, first, axis=axis) | np.take(out, second, axis=axis)
    return out


def _refine_slab(
    field_: Field,
    grid: VoxelGrid,
    vol: np.ndarray,
    mask: np.ndarray,
    x0: int,
    fill: np.float32,
    band_safety: float,
    chunk: int,
    coarse: int,
) -> tuple[int, np.ndarray]:
    """Narrow the coarse band level by level, halving the block size down to 2 voxels.

    At each level (block side s = coarse / 2, ..., 2) the band points on the stride-s lattice
    are evaluated, the s-blocks the surface may cross are kept (same test as the coarse
    level), and the band points of dropped s-blocks are filled with their block's sign; the
    last level's kept blocks are evaluated in full. ``x0`` must be a multiple of ``coarse``
    so that the lattices line up across slabs. Returns (points evaluated, marching-cubes mask).
    """
    shape = vol.shape
    ny, nz = shape[1:]
    done = np.zeros(shape, dtype=bool)
    n_eval = 0
    step = coarse // 2
    while step >= 2:
        axes = [_block_axes(n, step) for n in shape]
        nodes = [_coarse_indices(n, step, a[2]) for n, a in zip(shape, axes, strict=True)]
        lattice = np.zeros(shape, dtype=bool)
        lattice[np.ix_(*nodes)] = True
        todo = lattice & mask & ~done
        n_eval += _evaluate_into(field_, grid, vol, todo, x0, chunk, fill)
        done |= todo
        del lattice, todo
        corners = vol[np.ix_(*nodes)]
        half_diag = 0.5 * math.sqrt(3.0) * step * grid.voxel
        active = _active_blocks(corners, half_diag, band_safety, 0)
        near = _expand(active, axes) & mask
        # Band points of dropped blocks: all corners share a sign, so the block does too.
        rest = np.flatnonzero(mask & ~near & ~done)
        if rest.size:
            bx = axes[0][0][rest // (ny * nz)]
            by = axes[1][0][(rest // nz) % ny]
            bz = axes[2][0][rest % nz]
            sign = np.where(corners[bx, by, bz] < 0.0, -1.0, 1.0).astype(np.float32)
            vol.reshape(-1)[rest] = sign * fill
        mask = near
        step //= 2
    n_eval += _evaluate_into(field_, grid, vol, mask & ~done, x0, chunk, fill)
    return n_eval, mask


def extract_sdf_mesh(
    field_: Field,
    res: int = 300,
    bounds: Bounds | None = None,
    crop: CropVolume | None = None,
    chunk: int = 2**18,
    narrow_band: bool = True,
    coarse_factor: int | None = None,
    band_safety: float = 1.5,
    band_dilate: int = 1,
    refine: bool = True,
    slab_bytes: int = 256 * 2**20,
    progress: bool = True,
) -> tuple[trimesh.Trimesh, VoxelGrid, ExtractionStats]:
    """Marching cubes on the zero level of ``field_.sdf``, before any post-processing.

    Args:
        field_: any :class:`~hybridneus.model.protocol.Field`.
        res: grid points along the longest side of the volume (voxel = side / (res - 1)).
        bounds: world box ((x0, y0, z0), (x1, y1, z1)); default [-1, 1]^3, or ``crop``'s box
            (grown by 2% and cut to [-1, 1]^3, so surfaces on the crop are closed).
        crop: crop cylinder whose box is meshed when ``bounds`` is not given.
        chunk: points per field query (bounds peak memory of the field).
        narrow_band: evaluate only blocks near the zero level (see module docstring).
        coarse_factor: fine voxels per coarse block side (power of two); default 8 (4 with
            ``refine=False``).
        band_safety: multiple of the block half diagonal within which a block is kept.
        band_dilate: blocks added around the kept ones.
        refine: narrow the band level by level down to 2-voxel blocks (:func:`_refine_slab`).
        slab_bytes: upper bound on one slab's float32 volume.
        progress: show a progress bar on stderr.

    Returns:
        (mesh in world coordinates with outward-facing triangles, the fine grid, statistics).
    """
    import time

    from skimage.measure import marching_cubes

    if bounds is None:
        bounds = crop.padded_bounds() if crop is not None else DEFAULT_BOUNDS
    grid = VoxelGrid.from_bounds(bounds, res)
    nx, ny, nz = grid.shape
    block = coarse_factor or (8 if refine else 4)
    if narrow_band and refine and (block < 2 or block & (block - 1)):
        raise ValueError(f"coarse_factor {block}: must be a power of two with refine=True")
    stats = ExtractionStats(grid_shape=grid.shape, voxel=grid.voxel)

    axes = [_block_axes(n, block) for n in grid.shape]
    n_blocks = tuple(a[2] for a in axes)
    t0 = time.perf_counter()
    bar = make_progress("pt", transient=True, disable=not progress)
    with bar:
        task = bar.add_task("meshing", total=None)
        if narrow_band:
            cx, cy, cz = (
                _coarse_indices(n, block, nb) for n, nb in zip(grid.shape, n_blocks, strict=True)
            )
            gx, gy, gz = np.meshgrid(cx, cy, cz, indexing="ij")
            stats.coarse_points = gx.size
            bar.update(task, total=gx.size)
            coarse = evaluate_sdf(field_, grid.points(gx.ravel(), gy.ravel(), gz.ravel()), chunk)
            coarse = coarse.reshape(gx.shape)
            bar.update(task, advance=gx.size)
            half_diag = 0.5 * math.sqrt(3.0) * block * grid.voxel
            active = _active_blocks(coarse, half_diag, band_safety, band_dilate)
            block_sign = np.where(coarse[:-1, :-1, :-1] < 0.0, -1.0, 1.0).astype(np.float32)
            estimate = int(active.sum()) * block**3
        else:
            active = np.ones(n_blocks, dtype=bool)
            block_sign = np.ones(n_blocks, dtype=np.float32)
            estimate = nx * ny * nz
        bar.update(task, total=stats.coarse_points + estimate, info="fine grid")
        stats.times["coarse"] = time.perf_counter() - t0

        fy, sy = axes[1][0], axes[1][1]
        fz, sz = axes[2][0], axes[2][1]
        # np.take keeps results C-contiguous (mixed slice/array indexing does not, and the
        # per-slab gathers below were 10x slower on such strided arrays).
        active_z = np.take(active, fz, axis=2) | np.take(active, sz, axis=2)
        active_yz = np.take(active_z, fy, axis=1) | np.take(active_z, sy, axis=1)  # (n_bx, ny, nz)
        sign_yz = np.take(np.take(block_sign, fz, axis=2), fy, axis=1)
        del active_z
        # Large enough never to be crossed, small enough to keep float32 interpolation sane.
        fill = np.float32(1e3 * max(grid.voxel, 1e-6))
        plane_bytes = 4 * ny * nz
        # Slab starts on multiples of the coarse block keep every refinement level's blocks on
        # one global lattice.
        slab = max(2, min(nx - 1, slab_bytes // max(plane_bytes, 1) - 1))
        if slab < nx - 1:
            slab = max(block, slab - slab % block)
        all_verts, all_faces, shared, n_verts = [], [], [], 0
        t_eval = t_mc = 0.0
        for x0 in range(0, nx - 1, slab):
            x1 = min(x0 + slab, nx - 1)
            xs = np.arange(x0, x1 + 1)
            fx, sx = axes[0][0][xs], axes[0][1][xs]
            # A point needs its value when any block it belongs to is active; the OR over the
            # (up to 2 x 2 x 2) blocks separates by axis, so expand one axis at a time.
            mask = np.take(active_yz, fx, axis=0) | np.take(active_yz, sx, axis=0)
            vol = np.take(sign_yz, fx, axis=0)
            vol *= fill
            t1 = time.perf_counter()
            if narrow_band and refine:
                n_eval, mask = _refine_slab(
                    field_, grid, vol, mask, x0, fill, band_safety, chunk, block
                )
            else:
                n_eval = _evaluate_into(field_, grid, vol, mask, x0, chunk, fill)
            t_eval += time.perf_counter() - t1
            stats.fine_points += n_eval
            stats.slabs += 1
            bar.update(task, advance=n_eval)
            t1 = time.perf_counter()
            if vol.min() < 0.0 < vol.max():
                # With inside negative, skimage's "descent" winding gives outward normals
                # (checked by the positive signed volume of a sphere in the tests).
                # Every cell that can hold the surface starts at an active point, so the mask
                # only skips cells filled with constant-sign values (about 2x faster).
                verts, faces, _, _ = marching_cubes(
                    vol,
                    level=0.0,
                    gradient_direction="descent",
                    allow_degenerate=False,
                    mask=mask if narrow_band else None,
                )
                verts = verts.astype(np.float64)
                verts[:, 0] += x0
                all_verts.append(verts)
                all_faces.append(faces.astype(np.int64) + n_verts)
                n_verts += verts.shape[0]
                if x0 > 0:
                    shared.append(x0)
            t_mc += time.perf_counter() - t1
            del mask, vol
        bar.update(task, completed=stats.coarse_points + estimate)
    stats.times["fine_eval"] = t_eval
    stats.times["marching_cubes"] = t_mc

    if not all_verts:
        return trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)), grid, stats
    verts = np.concatenate(all_verts)
    faces = np.concatenate(all_faces)
    verts, faces = _weld_planes(verts, faces, shared)
    mesh = trimesh.Trimesh(grid.to_world(verts), faces, process=False)
    return mesh, grid, stats
