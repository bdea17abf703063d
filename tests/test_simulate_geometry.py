"""Trajectories, camera conventions, rendering and mesh loading of hybridneus.simulate."""

from __future__ import annotations

import numpy as np
import pytest

from hybridneus.errors import MeshError
from hybridneus.simulate import (
    PinholeCamera,
    Renderer,
    Shading,
    builtin_scene,
    circle,
    even_spiral,
    load_mesh,
    look_at_origin,
    normalization_for,
    sample_bilinear,
    seiffert_spiral,
)


def test_seiffert_constant_speed_and_paper_step():
    traj = seiffert_spiral(999, revolutions=8)
    d = traj.directions
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    step = np.degrees(np.arccos(np.clip((d[1:] * d[:-1]).sum(1), -1, 1)))
    # chord angles of a unit-speed curve: all equal, 2.886 deg as in EventNeRF's data
    assert abs(np.median(step) - 2.886) < 0.01
    assert step.max() - step.min() < 0.02
    assert d[0, 1] == pytest.approx(1.0)  # starts at the north pole (+y)
    elev = np.degrees(np.arcsin(d[:, 1]))
    assert elev.min() >= -1e-9 and np.mean(elev < 1.0) > 0.7  # bunches at the equator


def test_even_spiral_spreads_elevation():
    traj = even_spiral(200, revolutions=4, elevation_start_deg=80, elevation_end_deg=10)
    elev = np.degrees(np.arcsin(traj.directions[:, 1]))
    np.testing.assert_allclose(elev, np.linspace(80, 10, 200), atol=1e-9)
    az = np.unwrap(traj.azimuth)
    assert az[-1] - az[0] == pytest.approx(4 * 2 * np.pi)


@pytest.mark.parametrize("traj", [seiffert_spiral(50, 3), even_spiral(40, 2), circle(30, 20.0)])
def test_look_at_poses_follow_opencv_axes(traj):
    radius = 1 / 1.1
    c2w = look_at_origin(traj.directions, traj.azimuth, radius)
    r = c2w[:, :3, :3]
    np.testing.assert_allclose(np.einsum("nij,nik->njk", r, r), np.broadcast_to(np.eye(3), r.shape),
                               atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0, atol=1e-12)
    pos = c2w[:, :3, 3]
    np.testing.assert_allclose(np.linalg.norm(pos, axis=1), radius, atol=1e-12)
    np.testing.assert_allclose(r[:, :, 2], -pos / radius, atol=1e-12)  # z forward to origin
    assert np.all(np.abs(r[:, 1, 0]) < 1e-12)  # image x axis horizontal
    assert np.all(r[:, 1, 1] <= 1e-12)  # image y (down) never points up in the world


def test_camera_directions_match_reference_model():
    cam = PinholeCamera(8, 6, 5.0, 4.0, 4.0, 3.0, k1=0.1, k2=-0.02)
    d = cam.directions(1)[:, :, 0]
    u, v = 2, 5
    x, y = (u + 0.5 - 4.0) / 5.0, (v + 0.5 - 3.0) / 4.0
    r2 = x * x + y * y
    s = 1 + 0.1 * r2 - 0.02 * r2 * r2
    np.testing.assert_allclose(d[v, u], [x / s, y / s, 1.0])
    d2 = cam.directions(2)  # 4 sub-rays average to the pixel centre without distortion
    cam0 = PinholeCamera(8, 6, 5.0, 4.0, 4.0, 3.0)
    np.testing.assert_allclose(cam0.directions(2).mean(2), cam0.directions(1)[:, :, 0])
    assert d2.shape == (6, 8, 4, 3)


def test_sample_bilinear_orientation_and_wrap():
    tex = np.zeros((2, 2, 3), np.float32)
    tex[0, :] = (1, 0, 0)  # top row (v near 1) red
    tex[1, :] = (0, 0, 1)  # bottom row blue
    uv = np.array([[0.25, 0.75], [0.25, 0.25], [1.25, 0.75], [0.5, 0.5]], np.float32)
    out = sample_bilinear(tex, uv)
    np.testing.assert_allclose(out[0], [1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(out[1], [0, 0, 1], atol=1e-6)
    np.testing.assert_allclose(out[2], [1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(out[3], [0.5, 0, 0.5], atol=1e-6)


def _write_textured_quad(folder):
    """A y-up quad facing +z with a texture: top half red, bottom half blue."""
    from PIL import Image

    img = np.zeros((16, 16, 3), np.uint8)
    img[:8] = (255, 0, 0)
    img[8:] = (0, 0, 255)
    Image.fromarray(img).save(folder / "tex.png")
    (folder / "quad.mtl").write_text("newmtl m\nKd 0.5 0.5 0.5\nmap_Kd tex.png\n")
    (folder / "quad.obj").write_text(
        "mtllib quad.mtl\nv -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n"
        "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    return folder / "quad.obj"


def test_obj_texture_renders_upright(tmp_path):
    mesh = load_mesh(_write_textured_quad(tmp_path))
    assert mesh.n_faces == 2 and len(mesh.textures) == 1
    norm = normalization_for(mesh, 0.4)
    world = mesh.transformed(norm.scale, np.asarray(norm.translation))
    cam = PinholeCamera.from_fov(32, 24, 60.0)
    c2w = look_at_origin(np.array([[0.0, 0.0, 1.0]]), np.array([np.pi / 2]), 1 / 1.1)
    frames, coverage = Renderer(world, cam, supersample=1).render(c2w)
    img = frames[0]
    centre = coverage[0] == 1
    top = img[:12][centre[:12]]
    bottom = img[12:][centre[12:]]
    assert top.size and bottom.size
    assert np.all(top[:, 0] > 0.5) and np.all(top[:, 2] < 0.05)  # red above
    assert np.all(bottom[:, 2] > 0.5) and np.all(bottom[:, 0] < 0.05)  # blue below
    bg = img[~(coverage[0] > 0)]
    np.testing.assert_allclose(bg, 159 / 255, atol=1e-5)


def test_renderer_hits_match_reference_barycentrics():
    """Open3D's barycentric (u, v) weight vertices 1 and 2: the interpolated point must lie
    on the ray."""
    mesh = builtin_scene("device")
    norm = normalization_for(mesh, 0.4)
    world = mesh.transformed(norm.scale, np.asarray(norm.translation))
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(world.vertices.astype(np.float32)),
                        o3d.core.Tensor(world.faces.astype(np.uint32)))
    rng = np.random.default_rng(0)
    origins = np.tile([[0.0, 0.2, 0.9]], (200, 1))
    targets = rng.uniform(-0.1, 0.1, (200, 3))
    dirs = targets - origins
    out = scene.cast_rays(o3d.core.Tensor(np.hstack([origins, dirs]).astype(np.float32)))
    t = out["t_hit"].numpy()
    ok = np.isfinite(t)
    assert ok.sum() > 100
    prim = out["primitive_ids"].numpy()[ok]
    uv = out["primitive_uvs"].numpy()[ok]
    tri = world.vertices[world.faces[prim]]
    p = (1 - uv[:, :1] - uv[:, 1:]) * tri[:, 0] + uv[:, :1] * tri[:, 1] + uv[:, 1:] * tri[:, 2]
    np.testing.assert_allclose(p, origins[ok] + t[ok, None] * dirs[ok], atol=1e-4)


def test_load_mesh_errors(tmp_path):
    with pytest.raises(MeshError, match="no such mesh file"):
        load_mesh(tmp_path / "missing.obj")
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99\nend_header\n\x00")
    with pytest.raises(MeshError, match="bad.ply"):
        load_mesh(bad)
    pts = tmp_path / "points.obj"
    pts.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(MeshError, match="points.obj: no triangles"):
        load_mesh(pts)
    with pytest.raises(MeshError, match="builtin:nope"):
        builtin_scene("nope")


def test_load_multi_material_obj_keeps_colours(tmp_path):
    (tmp_path / "two.mtl").write_text("newmtl a\nKd 1 0 0\nnewmtl b\nKd 0 0 1\n")
    (tmp_path / "two.obj").write_text(
        "mtllib two.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nv 3 0 0\nv 2 1 0\n"
        "usemtl a\nf 1 2 3\nusemtl b\nf 4 5 6\n")
    mesh = load_mesh(tmp_path / "two.obj")
    assert mesh.n_faces == 2
    cols = {tuple(np.round(c[0], 2)) for c in mesh.corner_colors}
    assert cols == {(1.0, 0.0, 0.0), (0.0, 0.0, 1.0)}


def test_load_ply_vertex_colours_and_off(tmp_path):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=1)
    m.visual.vertex_colors = np.tile([0, 255, 0, 255], (len(m.vertices), 1))
    m.export(tmp_path / "s.ply")
    mesh = load_mesh(tmp_path / "s.ply")
    np.testing.assert_allclose(mesh.corner_colors[..., 1], 1.0)
    m.export(tmp_path / "s.off")
    assert load_mesh(tmp_path / "s.off").n_faces == len(m.faces)
    m.export(tmp_path / "s.glb")
    assert load_mesh(tmp_path / "s.glb").n_faces == len(m.faces)


def test_open3d_and_numpy_ray_paths_render_the_same():
    mesh = builtin_scene("device")
    norm = normalization_for(mesh, 0.4)
    world = mesh.transformed(norm.scale, np.asarray(norm.translation))
    cam = PinholeCamera.from_fov(40, 30, 55.0)
    traj = seiffert_spiral(12, 2)
    c2w = look_at_origin(traj.directions, traj.azimuth, 1 / 1.1)[[2, 7, 11]]
    fast = Renderer(world, cam, supersample=2)
    slow = Renderer(world, cam, supersample=2)
    slow.use_open3d_rays = False
    assert fast.use_open3d_rays
    a, ca = fast.render(c2w)
    b, cb = slow.render(c2w)
    # float32 ray directions differ in the last bits; only grazing edge rays may flip
    assert np.mean(np.abs(a - b) > 1e-3) < 0.002
    assert np.abs(ca - cb).mean() < 1e-3


def _shade_reference(renderer, prim, bary, normals, dirs):
    """Straightforward per-hit shading: interpolate corner colours, multiply the texture,
    flip the normal to face the camera, Lambert with ambient."""
    w = np.stack([1 - bary[:, 0] - bary[:, 1], bary[:, 0], bary[:, 1]], 1)[:, :, None]
    mesh = renderer.mesh
    albedo = (w * mesh.corner_colors[prim].astype(np.float64) ** 2.2).sum(1)
    for i, p in enumerate(prim):
        t = mesh.face_texture[p]
        if t >= 0:
            uv = (w[i] * mesh.corner_uv[p]).sum(0)
            albedo[i] *= sample_bilinear(mesh.textures[t].astype(np.float64) ** 2.2,
                                         uv[None].astype(np.float32))[0]
    n = np.where((normals * dirs).sum(1, keepdims=True) > 0, -normals, normals)
    if renderer.shading.headlight:
        light = -dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
        cos = np.clip((n * light).sum(1), 0, None)[:, None]
    else:
        light = np.asarray(renderer.shading.light_dir) / np.linalg.norm(renderer.shading.light_dir)
        cos = np.clip(n @ light, 0, None)[:, None]
    return albedo * (renderer.shading.ambient + renderer.shading.diffuse * cos)


@pytest.mark.parametrize("shading", [
    Shading(),
    Shading(light_dir=(-1.0, -0.2, 0.3), ambient=0.1, diffuse=1.2),
    Shading(headlight=True),
], ids=["default", "other-light", "headlight"])
def test_fast_shading_matches_reference(shading):
    from hybridneus.simulate.scene_mesh import concatenate_parts

    # textured device + vertex-coloured ring of the thin scene: all three colour paths
    mesh = concatenate_parts([builtin_scene("device"), builtin_scene("thin")])
    cam = PinholeCamera.from_fov(8, 6, 55.0)
    r = Renderer(mesh, cam, supersample=1, shading=shading)
    rng = np.random.default_rng(0)
    prim = rng.integers(0, mesh.n_faces, 500)
    bary = rng.dirichlet([1, 1, 1], 500)[:, 1:].astype(np.float32)
    normals = rng.normal(size=(500, 3)).astype(np.float32)
    dirs = rng.normal(size=(500, 3)).astype(np.float32)
    assert (mesh.face_texture[prim] >= 0).any() and r._face_varying[prim].any()
    fast = r._shade(prim, bary, normals, dirs)
    np.testing.assert_allclose(fast, _shade_reference(r, prim, bary, normals, dirs), atol=2e-5)


def test_unlit_headlight_and_background_renders():
    """Unlit (ambient 1, diffuse 0) returns the albedo whatever the light; a headlight makes a
    surface facing the camera as bright as ambient + diffuse; misses take the background."""
    mesh = builtin_scene("device")
    norm = normalization_for(mesh, 0.4)
    world = mesh.transformed(norm.scale, np.asarray(norm.translation))
    cam = PinholeCamera.from_fov(24, 18, 55.0)
    traj = seiffert_spiral(12, 2)
    c2w = look_at_origin(traj.directions, traj.azimuth, 1 / 1.1)[[3, 9]]
    bg = (0.1, 0.5, 0.9)
    unlit = [Renderer(world, cam, 1, Shading(light_dir=d, ambient=1.0, diffuse=0.0,
                                             background=bg)).render(c2w)[0]
             for d in [(0.0, 1.0, 0.0), (1.0, -1.0, 0.0)]]
    np.testing.assert_array_equal(unlit[0], unlit[1])
    frames, cover = Renderer(world, cam, 1, Shading(background=bg)).render(c2w)
    np.testing.assert_allclose(frames[cover == 0], np.broadcast_to(bg, frames[cover == 0].shape),
                               atol=1e-6)
    # Lambert never brightens beyond the unlit albedo when ambient + diffuse = 1
    lit = Renderer(world, cam, 1, Shading(ambient=0.0, diffuse=1.0, headlight=True,
                                          background=bg)).render(c2w)[0]
    assert np.all(lit[cover == 1] <= unlit[0][cover == 1] + 1e-6)
    assert np.any(lit[cover == 1] < unlit[0][cover == 1] - 0.05)


def test_shading_validation():
    for bad in [dict(light_dir=(0.0, 0.0, 0.0)), dict(ambient=-0.1),
                dict(ambient=0.0, diffuse=0.0), dict(background=(0.5, 0.5, 1.5)),
                dict(background=(0.5, 0.5))]:
        with pytest.raises(ValueError):
            Shading(**bad)


def test_public_names_resolve():
    import hybridneus.simulate as sim

    for name in sim.__all__:
        assert getattr(sim, name) is not None, name
