"""Mesh extraction against analytic SDFs: geometry, world frame, narrow band, slabs, colours."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from hybridneus.data.crop import crop_sdf
from hybridneus.meshing import (
    DEFAULT_BOUNDS,
    CropVolume,
    ExtractionStats,
    PostprocessOptions,
    extract_mesh,
    extract_sdf_mesh,
)
from hybridneus.model.analytic import BoxField, SphereField, TorusField, UnionField
from hybridneus.model.protocol import Field

RAW = PostprocessOptions(enabled=False)


def _sdf_at(field, vertices: np.ndarray) -> np.ndarray:
    return field.sdf(torch.tensor(vertices, dtype=torch.float32)).numpy()


def test_analytic_fields_satisfy_the_protocol_and_have_unit_gradients():
    pts = torch.rand(500, 3) * 2 - 1
    for field in (SphereField(0.5), TorusField(0.5, 0.2), BoxField((0.4, 0.3, 0.5))):
        assert isinstance(field, Field)
        d, g = field.sdf_and_gradient(pts)
        assert d.shape == (500,) and g.shape == (500, 3)
        # exact distance functions: |grad| = 1 almost everywhere
        assert torch.allclose(g.norm(dim=-1), torch.ones(500), atol=1e-4)
        rgb = field.color(pts, -g)
        assert rgb.shape == (500, 3) and rgb.min() >= 0 and rgb.max() <= 1


def test_sphere_mesh_is_in_world_coordinates_with_outward_faces():
    field = SphereField(0.5, center=(0.2, 0.0, 0.0))
    stats = ExtractionStats()
    mesh = extract_mesh(field, res=96, progress=False, stats=stats)
    voxel = 2.0 / 95
    assert stats.voxel == pytest.approx(voxel)
    radii = np.linalg.norm(mesh.vertices - [0.2, 0.0, 0.0], axis=1)
    assert np.abs(radii - 0.5).max() < 0.5 * voxel
    assert np.allclose(mesh.vertices.mean(axis=0), [0.2, 0.0, 0.0], atol=0.01)
    assert mesh.is_watertight
    # positive signed volume = outward winding; marching cubes loses a little volume
    assert mesh.volume == pytest.approx(4 / 3 * np.pi * 0.5**3, rel=0.02)


@pytest.mark.parametrize(
    "field, tol_voxels",
    [(TorusField(0.5, 0.2, center=(0.0, 0.1, -0.1)), 0.5), (BoxField((0.4, 0.3, 0.5)), 1.0)],
)
def test_vertices_lie_on_the_zero_level(field, tol_voxels):
    mesh, grid, _ = extract_sdf_mesh(field, res=80, progress=False)
    assert len(mesh.faces) > 1000
    # the box's sharp edges are cut by marching cubes, hence the looser bound there
    assert np.abs(_sdf_at(field, mesh.vertices)).max() < tol_voxels * grid.voxel


def test_bounds_and_crop_select_the_world_volume():
    field = SphereField(0.3, center=(0.5, 0.5, 0.5))
    mesh = extract_mesh(field, res=64, bounds=((0.0, 0.0, 0.0), (1.0, 1.0, 1.0)), progress=False)
    grid_voxel = 1.0 / 63
    assert np.abs(np.linalg.norm(mesh.vertices - 0.5, axis=1) - 0.3).max() < 0.5 * grid_voxel
    # the crop cylinder r = 0.25, -0.3 <= y <= 0.2 keeps two caps of a sphere of radius 0.3
    crop = CropVolume(0.25, -0.3, 0.2)
    cut = extract_mesh(SphereField(0.3), res=64, crop=crop, progress=False)
    whole = extract_mesh(SphereField(0.3), res=64, progress=False)
    v = cut.vertices
    # analytic area of the kept band (0.166 < y < 0.2) and bottom cap: 2 pi R (0.034 + 0.134)
    assert cut.area == pytest.approx(2 * np.pi * 0.3 * (0.2 - 0.3 + 0.3 - np.sqrt(0.09 - 0.0625)
                                                          + 0.3 - np.sqrt(0.09 - 0.0625)), rel=0.1)
    assert cut.area < 0.5 * whole.area
    unclipped = extract_mesh(SphereField(0.3), res=64, crop=crop, clip=False, progress=False)
    assert unclipped.area > 1.5 * cut.area  # the crop's box only, not the cylinder
    assert v[:, 1].min() < -0.2 and v[:, 1].max() > 0.15
    voxel = 2 * 0.25 * 1.02 / 63
    assert (v[:, 0] ** 2 + v[:, 2] ** 2 <= (0.25 + voxel) ** 2).all()
    assert v[:, 1].min() >= -0.3 - voxel and v[:, 1].max() <= 0.2 + voxel


class _SphereCutByCrop(SphereField):
    """A sphere reaching below the crop's floor, cut as a trained field is: max(sdf, crop)."""

    def __init__(self, radius: float, crop: CropVolume) -> None:
        super().__init__(radius)
        self.crop = torch.tensor([crop.r, crop.y_min, crop.y_max])

    def _sdf(self, points: torch.Tensor) -> torch.Tensor:
        return torch.maximum(super()._sdf(points), crop_sdf(points, self.crop))


def test_trim_crop_removes_only_the_cap_the_crop_cuts():
    crop = CropVolume(0.6, -0.2, 0.6)
    field = _SphereCutByCrop(0.4, crop)
    kept = extract_mesh(field, res=64, crop=crop, progress=False)
    trimmed = extract_mesh(field, res=64, crop=crop, progress=False,
                           postprocess=PostprocessOptions(trim_crop=True))
    voxel = 1.2 * 1.02 / 63
    cap = np.pi * (0.4**2 - 0.2**2)  # the disc where the floor y = -0.2 cuts the sphere
    above = 2 * np.pi * 0.4 * (0.4 + 0.2)  # the sphere's zone above the floor
    assert kept.area == pytest.approx(above + cap, rel=0.03)
    assert trimmed.area == pytest.approx(above, rel=0.03)
    assert kept.is_watertight and not trimmed.is_watertight
    # what is left is the sphere, down to its rim on the floor
    assert np.abs(np.linalg.norm(trimmed.vertices, axis=1) - 0.4).max() < voxel
    assert trimmed.vertices[:, 1].min() > -0.2 - voxel
    # a surface that stays clear of the crop loses nothing
    inner = SphereField(0.3)
    assert len(extract_mesh(inner, res=64, crop=crop, progress=False).faces) == len(
        extract_mesh(inner, res=64, crop=crop, progress=False,
                     postprocess=PostprocessOptions(trim_crop=True)).faces)


def test_a_cropped_field_is_meshed_over_its_own_crop_by_default():
    """extract_mesh(field) meshes what `hybridneus mesh` does: res points across the field's
    crop box (grown by 2% on each side), not across the whole cube, whose voxels would be
    3.2 times larger here."""
    crop = CropVolume(0.3, -0.3, 0.3)
    field = _SphereCutByCrop(0.25, crop)
    own = CropVolume.of_field(field)  # read from the field's float32 buffer
    assert (own.r, own.y_min, own.y_max) == pytest.approx((0.3, -0.3, 0.3))
    assert CropVolume.of_field(SphereField(0.25)) is None
    stats, given = ExtractionStats(), ExtractionStats()
    mesh = extract_mesh(field, res=64, progress=False, stats=stats)
    same = extract_mesh(field, res=64, crop=own, progress=False, stats=given)
    assert stats.voxel == pytest.approx(0.6 * 1.04 / 63) and stats.voxel == given.voxel
    assert np.array_equal(mesh.vertices, same.vertices)
    cube = ExtractionStats()
    extract_mesh(field, res=64, bounds=DEFAULT_BOUNDS, progress=False, stats=cube)
    assert cube.voxel == pytest.approx(2.0 / 63)
    plain = ExtractionStats()  # a field without a crop: the whole cube, as before
    extract_mesh(SphereField(0.25), res=64, progress=False, stats=plain)
    assert plain.voxel == pytest.approx(2.0 / 63)


def test_crop_boundary_distance():
    crop = CropVolume(0.5, -0.2, 0.3)
    points = np.array([[0.0, 0.0, 0.0], [0.4, 0.0, 0.0], [0.0, -0.15, 0.0], [0.0, 0.5, 0.0],
                       [0.7, 0.0, 0.0], [0.0, 0.0, -0.5]])
    assert crop.boundary_distance(points) == pytest.approx([0.2, 0.1, 0.05, 0.2, 0.2, 0.0])
    assert crop.boundary_normal(points) == pytest.approx(
        np.array([[0, -1, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [1, 0, 0], [0, 0, -1]]))


@pytest.mark.parametrize("coarse, refine", [(8, True), (4, True), (16, True), (4, False)])
def test_narrow_band_gives_the_full_grid_mesh(coarse, refine):
    field = TorusField(0.45, 0.15)
    full, _, full_stats = extract_sdf_mesh(field, res=72, narrow_band=False, progress=False)
    band, _, band_stats = extract_sdf_mesh(
        field, res=72, coarse_factor=coarse, refine=refine, progress=False
    )
    assert band_stats.fine_points < 0.5 * full_stats.fine_points
    assert len(band.vertices) == len(full.vertices) and len(band.faces) == len(full.faces)
    d1, _ = cKDTree(full.vertices).query(band.vertices)
    d2, _ = cKDTree(band.vertices).query(full.vertices)
    assert max(d1.max(), d2.max()) < 1e-6


def test_slabs_stitch_into_the_single_volume_mesh():
    field = SphereField(0.6)
    one, _, s1 = extract_sdf_mesh(field, res=60, progress=False)
    many, _, s2 = extract_sdf_mesh(field, res=60, progress=False, slab_bytes=4 * 60 * 60 * 6)
    assert s1.slabs == 1 and s2.slabs > 5
    assert len(one.vertices) == len(many.vertices) and len(one.faces) == len(many.faces)
    assert many.is_watertight


def test_empty_volume_gives_an_empty_mesh():
    mesh = extract_mesh(SphereField(0.2, center=(5.0, 0.0, 0.0)), res=32, progress=False)
    assert len(mesh.faces) == 0


def test_vertex_colours_follow_the_position_pattern():
    field = SphereField(0.5, center=(0.1, -0.1, 0.0), pattern="position")
    mesh = extract_mesh(field, res=64, color=True, progress=False)
    rgb = np.asarray(mesh.visual.vertex_colors)[:, :3] / 255.0
    expected = np.clip((mesh.vertices + 1) / 2, 0, 1)
    # corners are at most one voxel away from the vertex and the pattern's slope is 1/2
    assert np.abs(rgb - expected).max() < 0.5 * (2 / 63) * np.sqrt(3) + 1 / 255
    assert np.abs(rgb - expected).mean() < 0.01


def test_vertex_colours_keep_stripes_sharp_away_from_their_edges():
    field = SphereField(0.5, pattern="stripes", stripe_width=0.2)
    mesh = extract_mesh(field, res=64, color=True, progress=False)
    rgb = np.asarray(mesh.visual.vertex_colors)[:, :3].astype(float) / 255.0
    x = mesh.vertices[:, 0]
    voxel = 2 / 63
    phase = np.mod(x / 0.2, 1.0) * 0.2
    far = (phase > 1.5 * voxel) & (phase < 0.2 - 1.5 * voxel)
    odd = np.mod(np.floor(x / 0.2), 2) == 1
    assert far.sum() > 100
    assert np.allclose(rgb[far & ~odd], [1, 0, 0], atol=0.02)
    assert np.allclose(rgb[far & odd], [0, 0, 1], atol=0.02)


def test_postprocess_removes_a_small_floater():
    body = SphereField(0.5)
    floater = SphereField(0.03, center=(0.8, 0.8, 0.8))  # diagonal 4% of the whole mesh
    field = UnionField(body, floater)
    raw = extract_mesh(field, res=80, postprocess=RAW, progress=False)
    assert len(raw.split(only_watertight=False)) == 2
    cleaned = extract_mesh(field, res=80, progress=False)
    parts = cleaned.split(only_watertight=False)
    assert len(parts) == 1 and np.linalg.norm(parts[0].vertices, axis=1).max() < 0.52
    kept = extract_mesh(
        field, res=80, postprocess=PostprocessOptions(min_component_diameter=None),
        progress=False,
    )
    assert len(kept.split(only_watertight=False)) == 2
    largest = extract_mesh(
        field, res=80,
        postprocess=PostprocessOptions(min_component_diameter=None, keep_largest=True),
        progress=False,
    )
    assert len(largest.split(only_watertight=False)) == 1
    by_faces = extract_mesh(
        field, res=80,
        postprocess=PostprocessOptions(min_component_diameter=None, min_component_faces=500),
        progress=False,
    )
    assert len(by_faces.split(only_watertight=False)) == 1


def _spheres(centres, radius: float) -> list:
    import trimesh

    return [trimesh.creation.icosphere(2, radius).apply_translation(c) for c in centres]


def test_small_components_in_a_chain_are_judged_together():
    import trimesh

    from hybridneus.meshing.postprocess import postprocess_mesh, remove_small_components

    body = _spheres([(0.0, 0.0, 0.0)], 0.5)
    chain = _spheres([(0.6 + 0.05 * i, 0.0, 0.0) for i in range(8)], 0.02)  # 0.01 apart
    lone = _spheres([(0.0, 0.8, 0.0)], 0.02)
    hugging = _spheres([(-0.53, 0.0, 0.0)], 0.02)  # 0.01 off the body: still a floater
    mesh = trimesh.util.concatenate(body + chain + lone + hugging)
    kept = remove_small_components(mesh, min_diameter=0.1, gap=0.02)
    parts = kept.split(only_watertight=False)
    assert len(parts) == 1 + 8  # the body and every piece of the chain
    assert kept.vertices[:, 1].max() < 0.51 and kept.vertices[:, 0].min() > -0.51
    alone = remove_small_components(mesh, min_diameter=0.1, gap=0.0)
    assert len(alone.split(only_watertight=False)) == 1
    options = PostprocessOptions(merge_distance=0.0, component_gap=0.02 / 2.0)
    # the options' gap is a fraction of the whole diagonal (about 2.0 here)
    by_options = postprocess_mesh(mesh, options)
    assert len(by_options.split(only_watertight=False)) == 9
    by_options = postprocess_mesh(mesh, PostprocessOptions(merge_distance=0.0, component_gap=0))
    assert len(by_options.split(only_watertight=False)) == 1


class _HollowBall(SphereField):
    """A ball of radius 0.5 with a closed hollow of radius 0.25 inside."""

    def _sdf(self, points: torch.Tensor) -> torch.Tensor:
        r = torch.linalg.vector_norm(points, dim=-1)
        return torch.maximum(r - 0.5, 0.25 - r)


def test_postprocess_removes_closed_cavities_only():
    field = _HollowBall()
    raw = extract_mesh(field, res=64, postprocess=RAW, progress=False)
    assert len(raw.split(only_watertight=False)) == 2
    cleaned = extract_mesh(field, res=64, progress=False)
    radii = np.linalg.norm(cleaned.vertices, axis=1)
    assert len(cleaned.split(only_watertight=False)) == 1 and radii.min() > 0.45
    kept = extract_mesh(
        field, res=64, postprocess=PostprocessOptions(remove_cavities=False), progress=False
    )
    assert len(kept.split(only_watertight=False)) == 2
    # two solid balls are two bodies, not a body and a hollow
    pair = UnionField(SphereField(0.3, center=(-0.4, 0, 0)), SphereField(0.3, center=(0.4, 0, 0)))
    assert len(extract_mesh(pair, res=64, progress=False).split(only_watertight=False)) == 2


def test_remove_cavities_keeps_open_and_outward_components():
    import trimesh

    from hybridneus.meshing.postprocess import remove_cavities

    outer = trimesh.creation.icosphere(3, radius=1.0)
    inner = trimesh.creation.icosphere(2, radius=0.5)
    inner.invert()
    closed = trimesh.util.concatenate([outer, inner])
    closed.visual.vertex_colors = np.tile([10, 20, 30, 255], (len(closed.vertices), 1))
    out = remove_cavities(closed)
    assert len(out.faces) == len(outer.faces) and out.volume > 0
    assert (np.asarray(out.visual.vertex_colors)[:, :3] == [10, 20, 30]).all()
    opened = trimesh.Trimesh(inner.vertices, inner.faces[1:], process=False)
    both = trimesh.util.concatenate([outer, opened])
    assert len(remove_cavities(both).faces) == len(both.faces)


def test_decimation_reaches_the_target_and_keeps_colours():
    field = SphereField(0.5)
    mesh = extract_mesh(
        field, res=64, color=True, postprocess=PostprocessOptions(decimate=2000), progress=False
    )
    assert 1800 <= len(mesh.faces) <= 2000
    assert mesh.visual.kind == "vertex"
    assert np.abs(np.linalg.norm(mesh.vertices, axis=1) - 0.5).max() < 0.02


class _ViewColouredSphere(SphereField):
    """Colour = (-dir + 1) / 2: shows which view direction the mesher used."""

    def color(self, points, dirs):
        return ((-dirs + 1.0) * 0.5).clamp(0.0, 1.0)


@pytest.mark.parametrize("normals", ["mesh", "gradient"])
def test_colours_are_seen_along_the_inward_normal(normals):
    field = _ViewColouredSphere(0.5, center=(0.1, 0.0, 0.0))
    mesh = extract_mesh(field, res=64, color=True, color_normals=normals, progress=False)
    rgb = np.asarray(mesh.visual.vertex_colors)[:, :3] / 255.0
    radial = mesh.vertices - [0.1, 0.0, 0.0]
    radial /= np.linalg.norm(radial, axis=1, keepdims=True)
    # view = -outward normal, so the colour encodes the outward normal
    assert np.abs(rgb - (radial + 1) / 2).max() < 0.06
    assert np.abs(rgb - (radial + 1) / 2).mean() < 0.015


class _HalfNanSphere(SphereField):
    """A sphere whose SDF is NaN for z > 0.4 (as a diverged field might be somewhere)."""

    def _sdf(self, points):
        d = super()._sdf(points)
        return torch.where(points[:, 2] > 0.4, torch.full_like(d, float("nan")), d)


def test_non_finite_sdf_values_warn_and_count_as_outside():
    with pytest.warns(RuntimeWarning, match="non-finite"):
        mesh = extract_mesh(_HalfNanSphere(0.5), res=48, progress=False)
    # the NaN region acts as empty space: the sphere is cut flat near z = 0.4, still closed
    voxel = 2 / 47
    assert len(mesh.faces) > 1000 and mesh.is_watertight
    assert mesh.vertices[:, 2].max() < 0.4 + voxel
    assert mesh.vertices[:, 2].max() > 0.4 - voxel
