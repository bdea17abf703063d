"""A quick PNG preview of a mesh: a few shaded views ray-cast with Open3D on the CPU."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh

from hybridneus.fileio import atomic_path


def _look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """Camera axes (3, 3): rows right, up, forward."""
    forward = target - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    return np.stack([right, np.cross(right, forward), forward])


def render_views(
    mesh: trimesh.Trimesh,
    size: int = 256,
    azimuths: tuple[float, ...] = (30.0, 120.0, 210.0, 300.0),
    elevation: float = 20.0,
    background: float = 1.0,
    frame: tuple[np.ndarray, float] | None = None,
) -> np.ndarray:
    """Shaded orthographic views side by side -> (size, size * n_views, 3) uint8.

    Views orbit the world y axis (the datasets' up axis); colour is the vertex colour
    (barycentric blend) when present, else light grey, times a head-light Lambert term.
    ``frame`` (centre (3,), half-width of the view) frames another mesh's views alike; by
    default the mesh's own bounding box fills the view.
    """
    import open3d as o3d

    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(faces.astype(np.uint32))
    )
    colors = None
    if mesh.visual.kind == "vertex":
        colors = np.asarray(mesh.visual.vertex_colors)[:, :3].astype(np.float64) / 255.0
    if frame is None:
        centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
        half = 0.55 * float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    else:
        centre, half = np.asarray(frame[0], dtype=np.float64), float(frame[1])
    span = np.linspace(-half, half, size)
    u, v = np.meshgrid(span, -span)
    tiles = []
    for az in azimuths:
        a, e = np.radians(az), np.radians(elevation)
        direction = np.array([np.cos(e) * np.sin(a), np.sin(e), np.cos(e) * np.cos(a)])
        eye = centre + 3.0 * half * direction
        right, up, forward = _look_at(eye, centre, np.array([0.0, 1.0, 0.0]))
        origins = eye + u[..., None] * right + v[..., None] * up
        rays = np.concatenate([origins, np.broadcast_to(forward, origins.shape)], axis=-1)
        hit = scene.cast_rays(o3d.core.Tensor(rays.reshape(-1, 6).astype(np.float32)))
        t = hit["t_hit"].numpy()
        ok = np.isfinite(t)
        normals = hit["primitive_normals"].numpy()
        shade = np.abs(normals @ forward) * 0.8 + 0.2
        img = np.full((t.size, 3), background)
        if colors is not None:
            ids = hit["primitive_ids"].numpy()[ok].astype(np.int64)
            uv = hit["primitive_uvs"].numpy()[ok]
            bary = np.stack([1.0 - uv[:, 0] - uv[:, 1], uv[:, 0], uv[:, 1]], axis=1)
            base = np.einsum("nk,nkc->nc", bary, colors[faces[ids]])
        else:
            base = np.full((int(ok.sum()), 3), 0.8)
        img[ok] = base * shade[ok, None]
        tiles.append(img.reshape(size, size, 3))
    return (np.clip(np.concatenate(tiles, axis=1), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def save_preview(mesh: trimesh.Trimesh, path: str | os.PathLike, size: int = 256) -> Path:
    """Write :func:`render_views` of ``mesh`` as a PNG (atomically); returns the path."""
    from PIL import Image

    path = Path(path)
    image = render_views(mesh, size=size)
    with atomic_path(path, suffix=".png") as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
    return path
