"""Mesh conversion (numpy, Open3D), files (PLY/OBJ/GLB), loading errors and the PNG preview."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from hybridneus.errors import MeshError
from hybridneus.meshing import (
    load_mesh,
    mesh_from_numpy,
    mesh_from_open3d,
    mesh_to_numpy,
    mesh_to_open3d,
    save_mesh,
)
from hybridneus.meshing.render import render_views, save_preview


@pytest.fixture()
def coloured():
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.4)
    rng = np.random.default_rng(0)
    colors = rng.uniform(0, 1, size=(len(mesh.vertices), 3))
    return mesh_from_numpy(mesh.vertices, mesh.faces, colors)


def test_numpy_round_trip(coloured):
    v, f, c = mesh_to_numpy(coloured)
    assert v.dtype == np.float64 and f.dtype == np.int64 and c.dtype == np.float32
    again = mesh_from_numpy(v, f, c)
    assert np.array_equal(again.faces, coloured.faces)
    assert np.array_equal(again.visual.vertex_colors, coloured.visual.vertex_colors)
    with pytest.raises(ValueError):
        mesh_from_numpy(v[:, :2], f)


def test_open3d_round_trip_keeps_geometry_and_colours(coloured):
    o3d_mesh = mesh_to_open3d(coloured)
    assert len(o3d_mesh.triangles) == len(coloured.faces)
    assert o3d_mesh.has_vertex_colors()
    back = mesh_from_open3d(o3d_mesh)
    assert np.allclose(back.vertices, coloured.vertices)
    assert np.array_equal(back.faces, coloured.faces)
    assert np.array_equal(back.visual.vertex_colors, coloured.visual.vertex_colors)


@pytest.mark.parametrize("fmt", ["ply", "obj", "glb"])
def test_save_and_load_each_format(coloured, tmp_path, fmt):
    path = save_mesh(coloured, tmp_path / f"m.{fmt}")
    assert path.is_file() and not list(tmp_path.glob(".*tmp*"))
    back = load_mesh(path)
    assert len(back.faces) == len(coloured.faces)
    assert back.area == pytest.approx(coloured.area, rel=1e-4)
    if fmt == "ply":
        assert np.array_equal(back.visual.vertex_colors, coloured.visual.vertex_colors)


def test_save_rejects_unknown_formats(coloured, tmp_path):
    with pytest.raises(MeshError, match="m.xyz"):
        save_mesh(coloured, tmp_path / "m.xyz")


def test_load_errors_name_the_file(tmp_path):
    with pytest.raises(MeshError, match="missing.ply: no such mesh file"):
        load_mesh(tmp_path / "missing.ply")
    garbage = tmp_path / "garbage.ply"
    garbage.write_bytes(b"ply\nformat nonsense\n\x00\x01")
    with pytest.raises(MeshError, match="garbage.ply"):
        load_mesh(garbage)
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing\n")
    with pytest.raises(MeshError, match="empty.obj"):
        load_mesh(empty)


def test_preview_shows_the_colours(coloured, tmp_path):
    red = mesh_from_numpy(coloured.vertices, coloured.faces, np.tile([1.0, 0.0, 0.0], (162, 1)))
    image = render_views(red, size=64)
    assert image.shape == (64, 4 * 64, 3) and image.dtype == np.uint8
    hit = image.sum(axis=-1) < 3 * 255
    assert 0.1 < hit.mean() < 0.9
    assert (image[hit][:, 1] <= image[hit][:, 0]).all() and image[hit][:, 0].max() > 150
    png = save_preview(red, tmp_path / "p.png", size=32)
    assert png.read_bytes()[:4] == b"\x89PNG"
