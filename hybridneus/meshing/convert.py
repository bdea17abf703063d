"""Meshes in and out: numpy arrays, Open3D, and files (PLY / OBJ / GLB, written atomically).

Conventions everywhere: vertices (n_vertices, 3) float64 world coordinates, faces
(n_faces, 3) int64 vertex indices with counter-clockwise (outward) winding, colours
(n_vertices, 3) float in [0, 1] (files store them as uint8).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh

from hybridneus.errors import MeshError
from hybridneus.fileio import atomic_path
from hybridneus.meshing.color import to_uint8

MESH_FORMATS = ("ply", "obj", "glb")


def mesh_from_numpy(
    vertices: np.ndarray, faces: np.ndarray, colors: np.ndarray | None = None
) -> trimesh.Trimesh:
    """A trimesh from vertices (n_vertices, 3), faces (n_faces, 3) and optional colours.

    ``colors`` may be float in [0, 1] (n_vertices, 3) or uint8 (n_vertices, 3 | 4).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"expected (n, 3) vertices and faces, got {vertices.shape}, {faces.shape}")
    kwargs = {}
    if colors is not None:
        colors = np.asarray(colors)
        kwargs["vertex_colors"] = colors if colors.dtype == np.uint8 else to_uint8(colors[:, :3])
    return trimesh.Trimesh(vertices, faces, process=False, **kwargs)


def mesh_to_numpy(mesh: trimesh.Trimesh) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(vertices (n_vertices, 3) float64, faces (n_faces, 3) int64, colours or None).

    Colours are (n_vertices, 3) float32 in [0, 1] when the mesh has vertex colours.
    """
    colors = None
    if mesh.visual.kind == "vertex":
        colors = np.asarray(mesh.visual.vertex_colors)[:, :3].astype(np.float32) / 255.0
    return np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64), colors


def mesh_to_open3d(mesh: trimesh.Trimesh):  # -> open3d.geometry.TriangleMesh
    """An ``open3d.geometry.TriangleMesh`` with the same vertices, faces and vertex colours."""
    import open3d as o3d

    vertices, faces, colors = mesh_to_numpy(mesh)
    out = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(vertices), o3d.utility.Vector3iVector(faces.astype(np.int32))
    )
    if colors is not None:
        out.vertex_colors = o3d.utility.Vector3dVector(colors.astype(np.float64))
    return out


def mesh_from_open3d(o3d_mesh) -> trimesh.Trimesh:
    """A trimesh from an ``open3d.geometry.TriangleMesh`` (vertex colours kept if present)."""
    vertices = np.asarray(o3d_mesh.vertices)
    faces = np.asarray(o3d_mesh.triangles)
    colors = np.asarray(o3d_mesh.vertex_colors) if o3d_mesh.has_vertex_colors() else None
    return mesh_from_numpy(vertices, faces, colors)


def save_mesh(mesh: trimesh.Trimesh, path: str | os.PathLike, format: str | None = None) -> Path:
    """Write ``mesh`` atomically as PLY (binary, uint8 colours), OBJ or GLB; returns the path.

    ``format`` defaults to the file suffix.
    """
    path = Path(path)
    fmt = (format or path.suffix.lstrip(".")).lower()
    if fmt not in MESH_FORMATS:
        raise MeshError(f"{path}: mesh format {fmt!r} is not one of {', '.join(MESH_FORMATS)}")
    with atomic_path(path, suffix=f".{fmt}") as tmp:
        mesh.export(tmp, file_type=fmt)
    return path


def load_mesh(path: str | os.PathLike) -> trimesh.Trimesh:
    """Read a triangle mesh (any format trimesh reads); MeshError if missing, bad or empty."""
    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: no such mesh file")
    try:
        mesh = trimesh.load(path, force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for malformed files
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise MeshError(f"{path}: cannot read mesh ({reason})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(f"{path}: file holds no triangles")
    if not np.isfinite(np.asarray(mesh.vertices)).all():
        raise MeshError(f"{path}: vertices contain NaN or infinity")
    return mesh
