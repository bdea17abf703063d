"""``hybridneus render`` and the view renderer, on a (barely) trained run of a tiny scene."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch

W, H = 24, 18  # conftest.TINY_SIZE


@pytest.fixture(scope="module")
def scene(tiny_scene):
    return tiny_scene


def test_render_all_writes_views_metrics_orbit_and_event_sheet(scene, run_cli):
    out = scene / "pictures"
    code, _, err = run_cli("render", "--runs-root", str(scene / "runs"), "--views", "all",
                           "--frames", "3", "--size", "32", "--windows", "2", "--out", str(out))
    assert code == 0, err
    for i in (0, 1, 2):
        for kind in ("color", "normal", "depth"):
            img = cv2.imread(str(out / f"test_{i:05d}_{kind}.png"))
            assert img is not None and img.shape == (H, W, 3)
    metrics = json.loads((out / "metrics.json").read_text())
    assert [v["view"] for v in metrics["views"]] == [0, 1, 2]
    # The simulator writes real rgb frames, so every view is scored.
    assert all(np.isfinite(v["psnr"]) and -1 <= v["ssim"] <= 1 for v in metrics["views"])
    assert np.isclose(metrics["mean_psnr"], np.mean([v["psnr"] for v in metrics["views"]]))
    assert len(list(out.glob("orbit_*.png"))) == 3
    assert (out / "orbit.gif").stat().st_size > 0 and (out / "orbit.mp4").stat().st_size > 0
    assert cv2.imread(str(out / "events_vs_render.png")) is not None
    assert not list(out.glob("*.tmp*")), "temporary files left behind"


def test_render_bad_views_option_exits_2(scene, run_cli):
    code, _, err = run_cli("render", "--runs-root", str(scene / "runs"), "--views", "side")
    assert code == 2
    assert err.strip().startswith("error: --views side")
    assert len(err.strip().splitlines()) == 1


def test_rendered_depth_is_where_the_field_crosses_zero(scene):
    """The centre pixel's depth matches an independent search for the SDF's zero crossing."""
    from hybridneus.data import camera_rays, load_dataset
    from hybridneus.rendering.views import render_view
    from hybridneus.training.runs import latest_run, load_field

    field = load_field(latest_run(scene / "runs"), device="cpu")
    # The barely trained field is still its initial sphere: sharpen NeuS so depth is crisp.
    with torch.no_grad():
        field.variance.fill_(0.6)  # inv_s = exp(6) ~ 400
    split = load_dataset(scene / "device").splits["test"]
    img = render_view(field, split.intrinsics[0], split.distortion[0], split.c2w[0], W, H)
    assert img.color.shape == (H, W, 3) and img.depth.shape == (H, W)
    x, y = W // 2, H // 2
    o, d = camera_rays(split.intrinsics[0], split.distortion[0], split.c2w[0], [[x, y]])
    t = torch.linspace(0.0, 2.0, 4001)
    sdf = field.sdf(o + t[:, None] * d)
    inside = torch.nonzero(sdf < 0)
    assert len(inside) > 0, "the centre ray should hit the initial sphere"
    t_hit = float(t[inside[0, 0]])
    assert img.opacity[y, x] > 0.9
    assert abs(float(img.depth[y, x]) - t_hit) < 0.02


def test_predicted_event_frame_records_the_training_target(scene):
    from hybridneus.data import event_frame, load_dataset
    from hybridneus.rendering.views import predicted_event_frame
    from hybridneus.training.runs import latest_run, load_field

    field = load_field(latest_run(scene / "runs"), device="cpu")
    ds = load_dataset(scene / "device")
    split = ds.splits["train"]
    t1 = split.t_max
    t0 = 0.5 * t1
    predicted, recorded = predicted_event_frame(field, split, ds.preset, t0, t1)
    expected = event_frame(split, t0, t1, ds.preset.polarity_offset) * ds.preset.threshold
    assert predicted.shape == recorded.shape == (H, W)
    np.testing.assert_allclose(recorded, expected, rtol=1e-6)
    assert np.isfinite(predicted).all()


def test_render_refuses_a_missing_split_before_making_its_folder(scene, run_cli, tmp_path):
    out = tmp_path / "r"
    code, _, err = run_cli("render", "--runs-root", str(scene / "runs"), "--views", "test",
                           "--split", "nosuch", "--out", str(out), "--device", "cpu")
    assert code == 2 and "no split 'nosuch' to render" in err
    assert not out.exists()
    (tmp_path / "file").write_text("x")
    code, _, err = run_cli("render", "--runs-root", str(scene / "runs"), "--out",
                           str(tmp_path / "file"), "--device", "cpu")
    assert code == 2 and "file: is a file; give a folder name" in err
