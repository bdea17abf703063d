"""Vertex colours from a field's colour head, as in the EventNeuS appendix ("Coloured Meshes").

For each vertex, the colour field is sampled at the 8 corners of the grid voxel that contains
the vertex, each seen along the inward normal (view direction = -normal, a camera looking
straight at the surface). The corner colours are averaged with weights
w = 1 / (|sdf(corner)| + eps), so corners nearest the surface dominate. Corners shared by
several vertices are evaluated once.

The normal is either the mesh's vertex normal (averaged over the vertices that share a
corner; the default in :func:`~hybridneus.meshing.extract.extract_mesh`, which needs only
forward SDF queries) or, without normals, the normalised SDF gradient at the corner itself
(one extra backward pass per corner).
"""

from __future__ import annotations

import numpy as np
import torch

from hybridneus.meshing.volume import VoxelGrid
from hybridneus.model.protocol import Field

_CORNERS = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)], dtype=np.int64)


def query_colors(
    field_: Field, points: np.ndarray, dirs: np.ndarray | None = None, chunk: int = 2**16
) -> tuple[np.ndarray, np.ndarray]:
    """SDF (n_points,) and RGB (n_points, 3) float32 at ``points`` seen along ``dirs``.

    Without ``dirs`` (n_points, 3) the view direction is -grad sdf / |grad sdf| at the point.

    Note:
        Nothing is kept for backward; only the gradient query (no ``dirs``) runs autograd.
    """
    sdf = np.empty(points.shape[0], dtype=np.float32)
    rgb = np.empty((points.shape[0], 3), dtype=np.float32)
    for start in range(0, points.shape[0], chunk):
        p = torch.from_numpy(np.ascontiguousarray(points[start : start + chunk]))
        p = p.to(field_.device, torch.float32)
        if dirs is None:
            d, g = field_.sdf_and_gradient(p)
            view = -(g / g.norm(dim=-1, keepdim=True).clamp(min=1e-12)).detach()
        else:
            with torch.no_grad():
                d = field_.sdf(p)
            view = torch.from_numpy(np.ascontiguousarray(dirs[start : start + chunk]))
            view = view.to(field_.device, torch.float32)
        with torch.no_grad():
            c = field_.color(p, view)
        sdf[start : start + chunk] = d.detach().reshape(-1).float().cpu().numpy()
        rgb[start : start + chunk] = c.detach().float().cpu().numpy()
    return sdf, rgb


def vertex_colors(
    field_: Field,
    vertices: np.ndarray,
    grid: VoxelGrid,
    normals: np.ndarray | None = None,
    chunk: int = 2**16,
    eps: float | None = None,
) -> np.ndarray:
    """Colours (n_vertices, 3) float32 in [0, 1] for world ``vertices`` (n_vertices, 3).

    Args:
        field_: the field whose ``color`` head is sampled.
        vertices: vertex positions in world coordinates.
        grid: the voxel grid the mesh was extracted on (its corners are the colour samples).
        normals: outward unit vertex normals (n_vertices, 3); None = SDF gradients at corners.
        chunk: points per field query.
        eps: added to |sdf| in the weights; default 1% of a voxel.
    """
    if vertices.shape[0] == 0:
        return np.zeros((0, 3), dtype=np.float32)
    eps = 0.01 * grid.voxel if eps is None else eps
    shape = np.asarray(grid.shape, dtype=np.int64)
    base = np.floor(grid.to_index(vertices)).astype(np.int64)
    base = np.clip(base, 0, shape - 2)
    corners = base[:, None, :] + _CORNERS[None, :, :]  # (n_vertices, 8, 3)
    flat = np.ravel_multi_index(corners.reshape(-1, 3).T, tuple(shape))
    unique, inverse = np.unique(flat, return_inverse=True)
    inverse = inverse.reshape(-1)
    dirs = None
    if normals is not None:
        # a corner shared by several vertices looks along their mean inward normal
        summed = np.zeros((unique.size, 3))
        np.add.at(summed, inverse, -np.repeat(np.asarray(normals, np.float64), 8, axis=0))
        dirs = summed / np.maximum(np.linalg.norm(summed, axis=1, keepdims=True), 1e-12)
        dirs = dirs.astype(np.float32)
    ix, iy, iz = np.unravel_index(unique, tuple(shape))
    sdf, rgb = query_colors(field_, grid.points(ix, iy, iz), dirs, chunk)
    inverse = inverse.reshape(-1, 8)
    weights = 1.0 / (np.abs(sdf[inverse]) + eps)  # (n_vertices, 8)
    weights /= weights.sum(axis=1, keepdims=True)
    colors = np.einsum("vk,vkc->vc", weights, rgb[inverse])
    return np.clip(colors, 0.0, 1.0).astype(np.float32)


def to_uint8(colors: np.ndarray) -> np.ndarray:
    """[0, 1] float colours (n, 3) -> uint8 RGBA (n, 4) as stored in PLY files."""
    rgb = np.clip(np.round(np.asarray(colors, dtype=np.float64) * 255.0), 0, 255).astype(np.uint8)
    alpha = np.full((rgb.shape[0], 1), 255, dtype=np.uint8)
    return np.concatenate([rgb, alpha], axis=1)
