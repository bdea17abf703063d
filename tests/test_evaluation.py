"""Metrics: Chamfer / F-score / SDF-MAE on shapes with known answers, inside tests, images."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from hybridneus.evaluation import (
    chamfer_distance,
    chamfer_floor,
    color_corrected_psnr_ssim,
    inside_mask,
    normalize_eventneus,
    psnr,
    sdf_mae,
    signed_distance,
    ssim,
    unit_cube_transform,
    winding_number,
    winding_number_exact,
)


def sphere(radius: float, subdivisions: int = 5) -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)


def test_unit_cube_transform_maps_the_gt_box():
    gt = trimesh.creation.box(extents=(2.0, 4.0, 1.0))
    gt.apply_translation([1.0, 2.0, 3.0])
    centre, scale = unit_cube_transform(gt)
    mapped = (gt.vertices - centre) * scale + 0.5
    assert np.allclose(mapped.min(axis=0), [0.25, 0.0, 0.375])
    assert np.allclose(mapped.max(axis=0), [0.75, 1.0, 0.625])


def test_chamfer_of_a_mesh_with_itself_is_the_sampling_floor_and_repeatable():
    gt = sphere(0.7)
    a = chamfer_distance(gt, gt)
    b = chamfer_distance(gt, gt)
    assert a == b
    # independent samples on both sides: a small positive floor, not zero
    assert 0.001 < a.chamfer < 0.01
    assert a.fscore > 0.5
    assert chamfer_distance(gt, gt, seed=1).chamfer != a.chamfer


def test_chamfer_of_concentric_spheres_is_the_radial_gap():
    # every point of one sphere is exactly (R1 - R0) from the other, in both directions
    gt, pred = sphere(0.5), sphere(0.55)
    res = chamfer_distance(pred, gt)
    gap = 0.05 / 1.0  # gt's box side is 1.0, so the unit-cube scale is 1
    assert res.accuracy == pytest.approx(gap, abs=0.004)
    assert res.completeness == pytest.approx(gap, abs=0.004)
    assert res.chamfer == pytest.approx(gap, abs=0.004)
    assert res.fscore < 0.01


def test_chamfer_is_measured_in_the_gt_frame_not_renormalised():
    gt, pred = sphere(2.0), sphere(2.2)  # gt box side 4 -> gap 0.2 / 4 = 0.05
    assert chamfer_distance(pred, gt).chamfer == pytest.approx(0.05, abs=0.004)
    shifted = sphere(2.0)
    shifted.apply_translation([0.4, 0.0, 0.0])  # a shift is not normalised away
    assert chamfer_distance(shifted, gt).chamfer > 0.03


def test_the_eventneus_protocol_normalises_each_mesh_and_sums_the_two_directions():
    """Each mesh on its own centroid with its farthest vertex at radius 1: a shifted, scaled
    copy scores as the mesh itself; the score is accuracy + completeness."""
    gt = sphere(2.0)
    moved = sphere(2.0)
    moved.apply_scale(0.3)
    moved.apply_translation([0.5, -0.2, 0.1])
    unit = normalize_eventneus(moved)
    assert np.linalg.norm(unit.vertices, axis=1).max() == pytest.approx(1.0)
    assert np.allclose(unit.centroid, 0.0, atol=1e-9)
    same = chamfer_distance(gt, gt, protocol="eventneus")
    assert chamfer_distance(moved, gt, protocol="eventneus").chamfer == pytest.approx(
        same.chamfer, rel=1e-6)
    assert same.chamfer == pytest.approx(same.accuracy + same.completeness)
    assert same.protocol == "eventneus"
    assert chamfer_distance(moved, gt).chamfer > 5 * same.chamfer  # unit-cube measures it


def test_both_protocols_on_a_sphere_with_an_inner_shell():
    """GT a unit sphere; the prediction adds a concentric shell of radius 0.5 (a fifth of its
    area, 0.5 from GT). Neither normalisation moves the spheres (centroid 0, farthest vertex
    at 1), so eventneus gives accuracy 0.2 x 0.5 = 0.1 and a completeness of sampling noise,
    summed; unit-cube halves every distance (GT's box side is 2) and takes the mean."""
    gt = sphere(1.0)
    pred = trimesh.util.concatenate([sphere(1.0), sphere(0.5)])
    ev = chamfer_distance(pred, gt, protocol="eventneus")
    floor = chamfer_floor(gt, protocol="eventneus")
    assert ev.accuracy == pytest.approx(0.1 + floor / 2, abs=0.006)
    assert ev.chamfer == pytest.approx(0.1 + floor, abs=0.008)
    cube = chamfer_distance(pred, gt)
    assert cube.accuracy == pytest.approx(0.05 + chamfer_floor(gt) / 2, abs=0.004)
    assert cube.chamfer == pytest.approx((cube.accuracy + cube.completeness) / 2)
    with pytest.raises(ValueError, match="protocol"):
        chamfer_distance(pred, gt, protocol="unit-sphere")


def test_a_protocols_floor_is_the_sampling_alone():
    gt = sphere(1.0)
    for protocol in ("unit-cube", "eventneus"):
        floor = chamfer_floor(gt, protocol=protocol)
        assert 0 < floor < 0.05
        assert chamfer_floor(gt, n_samples=40_000, protocol=protocol) < 0.6 * floor
    # the same sampling error in a frame twice as large, summed rather than averaged
    assert chamfer_floor(gt, protocol="eventneus") == pytest.approx(
        4 * chamfer_floor(gt), rel=0.05)


def test_sdf_mae_of_concentric_spheres_is_the_gap_everywhere():
    # |p| - R0 minus |p| - R1 is R1 - R0 at every point, inside or outside
    gt, pred = sphere(0.5), sphere(0.6)
    res = sdf_mae(pred, gt)
    assert res.mae == pytest.approx(0.1, abs=0.003)
    assert res.mae_near == pytest.approx(0.1, abs=0.003)
    assert res.mae_uniform == pytest.approx(0.1, abs=0.003)
    assert sdf_mae(gt, gt).mae == 0.0
    assert sdf_mae(pred, gt) == res


def _open_sphere() -> tuple[trimesh.Trimesh, trimesh.Trimesh]:
    closed = sphere(0.5, subdivisions=3)
    centres = closed.triangles_center
    keep = centres[:, 2] < 0.35  # cut a cap: a hole of ~45 degrees half-angle
    return closed, trimesh.Trimesh(closed.vertices, closed.faces[keep], process=True)


def test_winding_number_on_closed_and_open_meshes():
    closed, opened = _open_sphere()
    assert not opened.is_watertight
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.8, 0.8, size=(800, 3))
    r = np.linalg.norm(pts, axis=1)
    clear = np.abs(r - 0.5) > 0.05
    truth = r < 0.5
    w_closed = winding_number(closed, pts)
    assert np.allclose(w_closed[clear & truth], 1.0, atol=0.01)
    assert np.allclose(w_closed[clear & ~truth], 0.0, atol=0.01)
    w_open = winding_number(opened, pts)
    exact = winding_number_exact(opened, pts)
    assert np.abs(w_open - exact).max() < 0.01  # the fast far field is accurate
    # next to the hole (above z = 0.3) the winding number is ~0.5 by nature: leave it out
    away = clear & (pts[:, 2] < 0.3)
    assert ((w_open >= 0.5) == truth)[away].all()
    assert (w_open[truth & away] > 0.6).all() and (w_open[~truth & away] < 0.4).all()
    for method in ("winding", "auto"):
        assert (inside_mask(opened, pts, method) == truth)[away].all()


def test_inside_tests_agree_on_a_closed_mesh_and_sign_is_negative_inside():
    closed = sphere(0.5, subdivisions=3)
    pts = np.array([[0.0, 0.0, 0.0], [0.3, 0.1, 0.0], [0.9, 0.0, 0.0], [0.0, -0.7, 0.2]])
    for method in ("winding", "rays", "auto"):
        assert inside_mask(closed, pts, method).tolist() == [True, True, False, False]
    d = signed_distance(closed, pts)
    assert d[0] == pytest.approx(-0.5, abs=0.01) and d[2] == pytest.approx(0.4, abs=0.01)
    with pytest.raises(ValueError, match="sign method"):
        inside_mask(closed, pts, "parity")


def test_psnr_and_ssim_basics():
    rng = np.random.default_rng(0)
    gt = rng.uniform(0.2, 0.8, size=(32, 40, 3))
    assert psnr(gt, gt) == float("inf")
    assert psnr(np.clip(gt + 0.1, 0, 1), gt) == pytest.approx(20.0, abs=1e-6)
    assert ssim(gt, gt) == pytest.approx(1.0)
    mask = np.zeros((32, 40), dtype=bool)
    mask[8:24, 10:30] = True
    noisy = gt.copy()
    noisy[~mask] = 0.0  # background garbage does not count
    assert psnr(noisy, gt, mask) == float("inf")
    with pytest.raises(ValueError):
        psnr(gt[:, :, :2], gt[:, :, :2])


def test_log_colour_correction_undoes_a_per_channel_gain_and_gamma():
    rng = np.random.default_rng(1)
    gt = rng.uniform(0.2, 0.9, size=(48, 48, 3))
    gain = np.array([0.6, 0.9, 0.7])  # no clipping: pred stays below 1
    gamma = np.array([1.2, 0.8, 1.0])
    pred = np.clip(gain * gt**gamma, 0, 1)
    raw = psnr(pred, gt)
    fixed = color_corrected_psnr_ssim(pred, gt)
    assert raw < 25 and fixed.psnr > 38 and fixed.ssim > 0.99
    # gt = pred ** (1 / gamma) / gain ** (1 / gamma): slope 1 / gamma in log space
    assert np.allclose(fixed.gain, 1 / gamma, atol=0.02)


def test_metrics_accept_mesh_files(tmp_path):
    gt, pred = sphere(0.5, 3), sphere(0.55, 3)
    gt.export(tmp_path / "gt.ply")
    pred.export(tmp_path / "pred.obj")
    from_files = chamfer_distance(tmp_path / "pred.obj", str(tmp_path / "gt.ply"), 2000)
    in_memory = chamfer_distance(pred, gt, 2000)
    # same samples; only the files' float32 vertices differ in the last digits
    assert from_files.chamfer == pytest.approx(in_memory.chamfer, rel=1e-5)
    assert from_files.fscore == in_memory.fscore
    assert sdf_mae(tmp_path / "pred.obj", gt, 1000).mae == pytest.approx(0.05, abs=0.003)
