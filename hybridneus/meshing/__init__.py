"""Meshes from fields: marching cubes in a narrow band, clean-up, vertex colours, file I/O.

Public API::

    from hybridneus.meshing import extract_mesh, PostprocessOptions, CropVolume, save_mesh
    mesh = extract_mesh(field, res=300, color=True)      # trimesh.Trimesh, world coordinates
    mesh = extract_mesh(field, cameras=centres)          # fill the pockets no camera saw
    save_mesh(mesh, "mesh.ply")

See docs/meshing.md.
"""

from hybridneus.meshing.convert import (
    MESH_FORMATS,
    load_mesh,
    mesh_from_numpy,
    mesh_from_open3d,
    mesh_to_numpy,
    mesh_to_open3d,
    save_mesh,
)
from hybridneus.meshing.extract import ExtractionStats, extract_mesh, extract_sdf_mesh
from hybridneus.meshing.postprocess import PostprocessOptions, postprocess_mesh
from hybridneus.meshing.unseen import FilledField, UnseenSpace, unseen_space
from hybridneus.meshing.volume import DEFAULT_BOUNDS, CropVolume, VoxelGrid

__all__ = [
    "DEFAULT_BOUNDS",
    "MESH_FORMATS",
    "CropVolume",
    "ExtractionStats",
    "FilledField",
    "PostprocessOptions",
    "UnseenSpace",
    "VoxelGrid",
    "extract_mesh",
    "extract_sdf_mesh",
    "load_mesh",
    "mesh_from_numpy",
    "mesh_from_open3d",
    "mesh_to_numpy",
    "mesh_to_open3d",
    "postprocess_mesh",
    "save_mesh",
    "unseen_space",
]
