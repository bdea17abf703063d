"""Lens distortion at ray time: OpenCV's radtan and fisheye models through a per-pixel table."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from hybridneus.data import camera_rays
from hybridneus.data.lens import Lens, read_lens
from hybridneus.errors import DatasetError

W, H = 40, 30
K_LAYOUT = np.array([[36.0, 0.0, 20.5], [0.0, 35.0, 15.0], [0.0, 0.0, 1.0]])
RADTAN = (-0.3, 0.12, 0.002, -0.003, -0.02)
FISHEYE = (0.06, -0.02, 0.01, -0.004)


def _radtan(x: np.ndarray, y: np.ndarray, c) -> tuple[np.ndarray, np.ndarray]:
    """Brown-Conrady forward model, written out (the reference the table must invert)."""
    k1, k2, p1, p2, k3 = c
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2**2 + k3 * r2**3
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def _kb4(x: np.ndarray, y: np.ndarray, c) -> tuple[np.ndarray, np.ndarray]:
    """Kannala-Brandt forward model, written out."""
    r = np.hypot(x, y)
    theta = np.arctan(r)
    td = theta * (1 + c[0] * theta**2 + c[1] * theta**4 + c[2] * theta**6 + c[3] * theta**8)
    s = np.where(r > 1e-12, td / np.maximum(r, 1e-12), 1.0)
    return x * s, y * s


@pytest.mark.parametrize(("model", "coeffs", "forward"), [("radtan", RADTAN, _radtan),
                                                          ("equidistant", FISHEYE, _kb4)])
def test_every_pixel_centre_is_the_image_of_its_table_direction(model, coeffs, forward):
    lens = Lens(model, coeffs, K_LAYOUT, W, H)
    xy = lens.table
    assert xy.shape == (H, W, 2)
    xd, yd = forward(xy[..., 0], xy[..., 1], coeffs)
    # layout pixel centres sit at +0.5: pixel (u, v) is at u + 0.5 = fx xd + cx
    u = K_LAYOUT[0, 0] * xd + K_LAYOUT[0, 2] - 0.5
    v = K_LAYOUT[1, 1] * yd + K_LAYOUT[1, 2] - 0.5
    uu, vv = np.meshgrid(np.arange(W), np.arange(H))
    np.testing.assert_allclose(u, uu, atol=1e-6)
    np.testing.assert_allclose(v, vv, atol=1e-6)
    # and the forward projection is the model's
    np.testing.assert_allclose(lens.project(xy.reshape(-1, 2)) - 0.5,
                               np.stack([uu, vv], -1).reshape(-1, 2), atol=1e-6)


def test_rays_through_a_lens_follow_its_table_and_differ_from_the_pinhole():
    lens = Lens("radtan", RADTAN, K_LAYOUT, W, H)
    c2w = np.eye(4)
    c2w[:3, 3] = [0.1, -0.2, 0.3]
    xy = torch.tensor([[0, 0], [W - 1, H - 1], [20, 15]])
    o, d = camera_rays(K_LAYOUT, None, c2w, xy, lens=lens)
    expect = np.concatenate([lens.table[xy[:, 1], xy[:, 0]], np.ones((3, 1))], 1)
    expect /= np.linalg.norm(expect, axis=1, keepdims=True)
    np.testing.assert_allclose(d.numpy(), expect, atol=1e-6)
    np.testing.assert_allclose(o.numpy(), np.broadcast_to(c2w[:3, 3], (3, 3)), atol=1e-7)
    _, pinhole = camera_rays(K_LAYOUT, None, c2w, xy)
    corner_shift = np.degrees(np.arccos(np.clip((pinhole[0] * d[0]).sum().item(), -1, 1)))
    assert corner_shift > 1.0  # barrel distortion bends the corner ray by degrees


@pytest.mark.parametrize(("lens", "message"), [
    ({"model": "division", "coeffs": [0.1]}, "lens model 'division' unknown"),
    ({"model": "radtan", "coeffs": [0.1, 0.2, 0.3]}, "takes 4 or 5 or 8 or 12 or 14"),
    ({"model": "equidistant", "coeffs": [0.1, "x", 0, 0]}, "must be numbers"),
    ({"model": "radtan", "coeffs": [float("nan"), 0, 0, 0]}, "not all finite"),
    ("radtan", "must be an object"),
])
def test_bad_lens_entries_fail_with_the_file_and_the_fault(lens, message):
    K = np.repeat(K_LAYOUT[None], 2, axis=0)
    with pytest.raises(DatasetError, match=message):
        read_lens({"lens": lens}, K, W, H, "scene.json")


def test_a_lens_needs_one_camera_and_zero_coefficients_are_no_lens():
    K = np.repeat(K_LAYOUT[None], 2, axis=0)
    assert read_lens({"lens": {"model": "radtan", "coeffs": [0, 0, 0, 0]}}, K, W, H, "s") \
        is None
    assert read_lens({}, K, W, H, "s") is None
    K[1, 0, 0] += 1.0
    with pytest.raises(DatasetError, match="every view's intrinsics to be the same"):
        read_lens({"lens": {"model": "radtan", "coeffs": list(RADTAN)}}, K, W, H, "s")


def test_a_distorted_recording_loads_with_its_lens_and_projects_back_to_its_pixels(
        tmp_path, run_cli):
    """convert writes the lens into scene.json; the loaded split's rays and the hull's
    projection invert each other through it; absurd coefficients are refused up front."""
    from hybridneus.data import load_dataset
    from hybridneus.data.hull import project_to_pixels
    from hybridneus.errors import RecordingError
    from hybridneus.recordings import (
        ConvertOptions,
        convert_recording,
        make_track,
        open_events,
        read_calibration,
    )

    t = np.linspace(0.0, 1.0, 9)
    angle = 2 * np.pi * t
    pos = np.stack([np.sin(angle), np.zeros_like(t), -np.cos(angle)], 1) * 2.0
    from scipy.spatial.transform import Rotation

    # cameras on a circle, each looking at the origin (OpenCV axes, y down)
    rot = Rotation.from_euler("y", -angle[:, None])
    track = make_track(t, rot.as_quat(), pos, "circle")
    rng = np.random.default_rng(0)
    n = 4000
    np.savez(tmp_path / "ev.npz", t=np.sort(rng.uniform(0, 1, n)), x=rng.integers(0, W, n),
             y=rng.integers(0, H, n), p=rng.choice([-1, 1], n))
    calib = {"fx": 36.0, "fy": 35.0, "cx": 20.0, "cy": 14.5, "width": W, "height": H,
             "model": "radtan", "coeffs": list(RADTAN)}
    (tmp_path / "calib.json").write_text(json.dumps(calib))
    opts = ConvertOptions(views=9, start=0.0, end=1.0, mosaic="mono")
    doc = convert_recording(open_events(tmp_path / "ev.npz"), track,
                            read_calibration(tmp_path / "calib.json"), tmp_path / "out", opts,
                            progress=False)
    assert doc["lens"] == {"model": "radtan", "coeffs": list(RADTAN)}
    sp = load_dataset(tmp_path / "out")["train"]
    assert sp.lens is not None and sp.lens.model == "radtan"
    xy = torch.tensor([[0, 0], [W - 1, 0], [5, H - 1], [20, 14], [33, 21]])
    o, d = camera_rays(sp.intrinsics[3], sp.distortion[3], sp.c2w[3], xy, lens=sp.lens)
    points = (o + 0.7 * d).double()
    u, v, front = project_to_pixels(sp, 3, points)
    assert front.all()
    assert (u == xy[:, 0]).all() and (v == xy[:, 1]).all()
    code, text, _ = run_cli("info", str(tmp_path / "out"))
    assert code == 0 and "radtan lens (-0.3, 0.12" in text
    for coeffs, message in (([-2.0, 0, 0, 0], "does not invert over the 40x30 image"),
                            ([1e9, 0, 0, 0], "times as wide as without it")):
        calib["coeffs"] = coeffs
        (tmp_path / "calib.json").write_text(json.dumps(calib))
        with pytest.raises(RecordingError, match=message):
            convert_recording(open_events(tmp_path / "ev.npz"), track,
                              read_calibration(tmp_path / "calib.json"), tmp_path / "bad",
                              opts, progress=False)
        assert not (tmp_path / "bad").exists()
