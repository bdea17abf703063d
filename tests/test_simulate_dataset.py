"""simulate_dataset end to end: layout, conventions against independent computations, the
reader round trip, atomic output and the CLI."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hybridneus.simulate import (
    EventModel,
    NoiseConfig,
    SimulationConfig,
    SimulationError,
    simulate_dataset,
)

W, H = 64, 48
SMALL = SimulationConfig(n_views=40, width=W, height=H, val_views=8, test_views=10,
                         revolutions=4)


@pytest.fixture(scope="module")
def device_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "device"
    simulate_dataset("builtin:device", out, SMALL)
    return out


@pytest.fixture(scope="module")
def thin_dir(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sim") / "thin"
    simulate_dataset("builtin:thin", out, replace(SMALL, val_views=0, test_views=0))
    return out


def _silhouette_from_projection(vertices, faces, K, c2w, width, height) -> np.ndarray:
    """Rasterise the projected triangles with OpenCV: an independent silhouette."""
    import cv2

    w2c = np.linalg.inv(c2w)
    cam = vertices @ w2c[:3, :3].T + w2c[:3, 3]
    assert np.all(cam[:, 2] > 0)
    uv = cam[:, :2] / cam[:, 2:] * np.array([K[0, 0], K[1, 1]]) + K[:2, 2]
    # OpenCV puts integer coordinates at pixel centres; ours sit at +0.5
    pts = np.round((uv - 0.5) * 16).astype(np.int32)
    mask = np.zeros((height, width), np.uint8)
    for tri in faces:
        cv2.fillConvexPoly(mask, pts[tri], 1, lineType=cv2.LINE_8, shift=4)
    return mask.astype(bool)


def _load_view(split_dir: Path, k: int):
    K = np.loadtxt(split_dir / "intrinsics" / f"r_{k:05d}.txt").reshape(-1)
    c2w = np.loadtxt(split_dir / "pose" / f"r_{k:05d}.txt").reshape(4, 4)
    return K[:16].reshape(4, 4)[:3, :3], c2w


def test_layout_and_file_formats(device_dir):
    info = json.loads((device_dir / "scene.json").read_text())
    for split, n in (("train", 40), ("validation", 8), ("test", 10)):
        d = device_dir / split
        for sub, ext in (("intrinsics", "txt"), ("pose", "txt"), ("rgb", "png")):
            names = sorted(p.name for p in (d / sub).iterdir())
            assert names == [f"r_{k:05d}.{ext}" for k in range(n)]
        assert np.loadtxt(d / "intrinsics" / "r_00000.txt").size == 16
        assert np.loadtxt(d / "pose" / "r_00000.txt").size == 16
        assert [p.name for p in (d / "events").iterdir()] == ["events.npz"]
        with np.load(d / "events" / "events.npz", allow_pickle=False) as z:
            assert sorted(z.files) == ["p", "t", "x", "y"]
            x, y, t, p = z["x"], z["y"], z["t"], z["p"]
        assert x.dtype == np.int16 and y.dtype == np.int16
        assert t.dtype == np.float64 and p.dtype == np.int8
        assert set(np.unique(p)) <= {-1, 1}
        assert np.all(np.diff(t) >= 0) and t[0] > 0
        assert t.max() == n - 1  # the reader puts view N-1 at max(t)
        assert x.max() < W and y.max() < H and x.min() >= 0 and y.min() >= 0
        assert info["splits"][split]["n_events"] == t.size
    preset = info["preset"]
    assert preset["threshold"] == 0.2 and preset["tonemap_eps"] == 1e-3
    assert preset["group"] == "simulated" and preset["scene"] == "device"
    assert preset["background"] == [159 / 255] * 3
    import trimesh

    gt = trimesh.load(device_dir / "gt_mesh.ply", process=False)
    assert gt.is_watertight  # the built-in device is closed once seams are merged
    r = np.sqrt(gt.vertices[:, 0] ** 2 + gt.vertices[:, 2] ** 2)
    assert r.max() <= preset["crop_r"]
    assert preset["crop_y_min"] <= gt.vertices[:, 1].min() <= gt.vertices[:, 1].max() <= \
        preset["crop_y_max"]
    assert np.linalg.norm(gt.vertices, axis=1).max() == pytest.approx(0.4, abs=0.05)
    cams = np.stack([np.loadtxt(p).reshape(4, 4)[:3, 3]
                     for p in sorted((device_dir / "train" / "pose").iterdir())])
    np.testing.assert_allclose(np.linalg.norm(cams, axis=1), 1 / 1.1, atol=1e-6)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


@pytest.mark.parametrize("scene", ["device", "thin"])
def test_rendered_silhouette_matches_projection(scene, request):
    import cv2
    import trimesh

    root = request.getfixturevalue(f"{scene}_dir")
    gt = trimesh.load(root / "gt_mesh.ply", process=False)
    split = root / "train"
    for k in (3, 17, 33):  # includes views near the pole and near the equator
        K, c2w = _load_view(split, k)
        rgb = cv2.imread(str(split / "rgb" / f"r_{k:05d}.png"))[..., ::-1].astype(int)
        rendered = np.abs(rgb - 159).max(-1) > 3
        proj = _silhouette_from_projection(gt.vertices, gt.faces, K, c2w, W, H)
        iou = _iou(rendered, proj)
        # thin legs are about one pixel wide at 64 x 48, so partial coverage lowers the IoU
        assert iou > (0.9 if scene == "device" else 0.6), (k, iou)
        if scene == "thin":
            # a flipped y or x convention matches far worse for the asymmetric tripod
            assert _iou(rendered, proj[::-1]) < iou - 0.3, (k, iou)
            assert _iou(rendered, proj[:, ::-1]) < iou - 0.15, (k, iou)


def test_events_lie_where_the_object_projects(device_dir):
    import cv2
    import trimesh

    gt = trimesh.load(device_dir / "gt_mesh.ply", process=False)
    split = device_dir / "train"
    with np.load(split / "events" / "events.npz") as z:
        x, y, t = z["x"].astype(int), z["y"].astype(int), z["t"]
    inside = outside = 0
    for k in (5, 20, 30):
        sel = (t > k - 1) & (t <= k)
        masks = [_silhouette_from_projection(gt.vertices, gt.faces, *_load_view(split, j), W, H)
                 for j in (k - 1, k)]
        region = cv2.dilate((masks[0] | masks[1]).astype(np.uint8), np.ones((3, 3), np.uint8))
        hit = region[y[sel], x[sel]].astype(bool)
        inside += hit.sum()
        outside += (~hit).sum()
        # swapping x and y would put most events outside the (tall, narrow) object
        swapped = region[np.clip(x[sel], 0, H - 1), np.clip(y[sel], 0, W - 1)].astype(bool)
        assert swapped.mean() < hit.mean()
    assert inside > 100 and outside == 0


def test_reader_round_trip(device_dir):
    dataset_mod = pytest.importorskip("hybridneus.data.dataset")
    ds = dataset_mod.load_dataset(device_dir)
    assert ds.preset.threshold == 0.2 and ds.preset.tonemap_eps == 1e-3
    assert set(ds.splits) == {"train", "validation", "test"}
    tr = ds.splits["train"]
    assert tr.width == W and tr.height == H
    assert tr.c2w.shape == (40, 4, 4) and tr.intrinsics.shape == (40, 3, 3)
    K, c2w = _load_view(device_dir / "train", 7)
    np.testing.assert_allclose(tr.c2w[7], c2w)
    np.testing.assert_allclose(tr.intrinsics[7], K)
    with np.load(device_dir / "train" / "events" / "events.npz") as z:
        np.testing.assert_array_equal(tr.events.x, z["x"])
        np.testing.assert_array_equal(tr.events.t, z["t"])
    assert float(tr.events.t.max()) == 39.0


def test_reader_rays_equal_simulator_rays(tmp_path):
    """With distortion, the reader's camera rays hit the pixels that the simulator drew."""
    rays_mod = pytest.importorskip("hybridneus.data.rays")
    dataset_mod = pytest.importorskip("hybridneus.data.dataset")
    import torch

    from hybridneus.simulate import PinholeCamera

    cfg = SimulationConfig(n_views=12, width=32, height=24, val_views=0, test_views=0,
                           distortion=(0.05, -0.01), revolutions=2)
    out = tmp_path / "dist"
    simulate_dataset("builtin:thin", out, cfg)
    assert np.loadtxt(out / "train" / "intrinsics" / "r_00000.txt").size == 20
    tr = dataset_mod.load_dataset(out).splits["train"]
    np.testing.assert_allclose(tr.distortion[0], [0.05, -0.01])
    cam = PinholeCamera.from_fov(32, 24, cfg.fov_y_deg, 0.05, -0.01)
    d_cam = cam.directions(1)[:, :, 0]
    xy = torch.tensor([[0, 0], [31, 23], [5, 17], [20, 3]], dtype=torch.int64)
    k = 4
    origins, dirs = rays_mod.camera_rays(
        torch.as_tensor(tr.intrinsics[k]), torch.as_tensor(tr.distortion[k]),
        torch.as_tensor(tr.c2w[k]), xy)
    ours = d_cam[xy[:, 1].numpy(), xy[:, 0].numpy()] @ tr.c2w[k][:3, :3].T
    ours /= np.linalg.norm(ours, axis=1, keepdims=True)
    np.testing.assert_allclose(dirs.numpy(), ours, atol=1e-5)
    np.testing.assert_allclose(origins.numpy(), np.tile(tr.c2w[k][:3, 3], (4, 1)), atol=1e-6)


def test_polarity_offset_and_noise_reach_scene_json(tmp_path):
    cfg = SimulationConfig(n_views=20, width=32, height=24, val_views=0, test_views=0,
                           events=EventModel(threshold=0.1, polarity_offset=-0.4),
                           noise=NoiseConfig(background_rate=0.01), seed=5, revolutions=2)
    out = tmp_path / "real"
    info = simulate_dataset("builtin:device", out, cfg)
    assert info["preset"]["polarity_offset"] == -0.4 and info["preset"]["threshold"] == 0.1
    assert info["noise"]["background_rate"] == 0.01 and info["seed"] == 5
    on_disk = json.loads((out / "scene.json").read_text())
    assert on_disk["preset"] == info["preset"]
    tr = info["splits"]["train"]
    # C_pos = 0.06 < C_neg = 0.14: many more positive than negative events
    assert tr["n_positive"] > 1.3 * tr["n_negative"]


def test_circle_trajectory_is_a_closed_turntable_loop(tmp_path):
    """spiral="circle": every training camera at the requested elevation, one turn in equal
    steps, and a preset that lets the reader's windows wrap around (cyclic)."""
    from hybridneus.data import load_dataset

    cfg = SimulationConfig(n_views=12, revolutions=1.0, spiral="circle", elevation_deg=20.0,
                           width=24, height=18, supersample=1, val_views=0, test_views=0)
    info = simulate_dataset("builtin:device", tmp_path / "turntable", cfg)
    assert info["preset"]["cyclic"] is True
    assert info["splits"]["train"]["trajectory_params"]["elevation_deg"] == 20.0
    centres = load_dataset(tmp_path / "turntable")["train"].c2w[:, :3, 3]
    radius = np.linalg.norm(centres, axis=1)
    elevation = np.degrees(np.arcsin(centres[:, 1] / radius))
    assert np.allclose(elevation, 20.0, atol=1e-4)
    azimuth = np.unwrap(np.arctan2(centres[:, 2], centres[:, 0]))
    assert np.allclose(np.abs(np.diff(azimuth)), 2 * np.pi / 12, atol=1e-5)
    two_turns = replace(cfg, revolutions=2.0)
    assert simulate_dataset("builtin:device", tmp_path / "twice", two_turns)["preset"][
        "cyclic"] is False
    with pytest.raises(ValueError, match="elevation_deg"):
        replace(cfg, elevation_deg=90.0)


def test_failed_run_leaves_no_output(tmp_path):
    out = tmp_path / "never"
    cfg = SimulationConfig(n_views=6, width=16, height=12, val_views=0, test_views=0,
                           events=EventModel(threshold=50.0))
    with pytest.raises(SimulationError, match="final frame interval"):
        simulate_dataset("builtin:device", out, cfg)
    assert not out.exists()
    assert list(tmp_path.iterdir()) == []  # no temporary folder left behind either


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "hybridneus.cli.app", *args],
                          capture_output=True, text=True, timeout=120)


def test_cli_simulate_builtin_and_errors(tmp_path):
    out = tmp_path / "thin"
    res = _cli("simulate", "builtin:thin", str(out), "--views", "16", "--width", "32",
               "--height", "24", "--val-views", "0", "--test-views", "6", "--revolutions", "2",
               "--spiral", "even", "--noise", "real", "--background", "0.8", "--headlight",
               "--ambient", "0.2", "--diffuse", "0.9", "-q")
    assert res.returncode == 0, res.stderr
    info = json.loads((out / "scene.json").read_text())
    assert info["preset"]["background"] == [0.8] * 3
    assert info["render"]["headlight"] and info["render"]["ambient"] == 0.2
    assert info["config"]["shading"]["diffuse"] == 0.9
    assert info["trajectory"] == "even" and info["splits"]["train"]["trajectory"] == "even"
    assert info["preset"]["polarity_offset"] == -0.4 and info["noise"]["threshold_sigma"] > 0
    assert set(info["splits"]) == {"train", "test"}
    loop = _cli("simulate", "builtin:thin", str(tmp_path / "loop"), "--views", "8", "--width",
                "16", "--height", "12", "--val-views", "0", "--test-views", "0", "--spiral",
                "circle", "--revolutions", "1", "--elevation", "15", "-q")
    assert loop.returncode == 0, loop.stderr
    info = json.loads((tmp_path / "loop" / "scene.json").read_text())
    assert info["trajectory"] == "circle" and info["preset"]["cyclic"] is True
    assert info["splits"]["train"]["trajectory_params"]["elevation_deg"] == 15.0
    bad = _cli("simulate", str(tmp_path / "missing.obj"), str(tmp_path / "o"))
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == [f"error: {tmp_path / 'missing.obj'}: no such "
                                               "mesh file"]
    assert not (tmp_path / "o").exists()
    neg = _cli("simulate", "builtin:thin", str(tmp_path / "o"), "--views", "1")
    assert neg.returncode == 2 and neg.stderr.startswith("error: ")
    for opt, value, msg in [("--light", "1,2", "--light: expected 3 comma-separated numbers"),
                            ("--background", "1.5", "background must be 3 sRGB values"),
                            ("--background", "grey", "--background: expected 1 or 3"),
                            ("--elevation", "95", "elevation_deg must be in (-90, 90)")]:
        res = _cli("simulate", "builtin:thin", str(tmp_path / "o"), opt, value)
        assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1, res.stderr
        assert msg in res.stderr
        assert not (tmp_path / "o").exists()
    assert _cli("simulate", "--help").returncode == 0


def test_cli_simulates_a_davis346(tmp_path):
    from hybridneus.simulate import DAVIS346_THRESHOLD

    res = _cli("simulate", "builtin:thin", str(tmp_path / "davis"), "--views", "12", "--width",
               "32", "--height", "24", "--val-views", "0", "--test-views", "0", "--noise",
               "davis346", "--view-seconds", "0.05", "--hot-pixel-rate", "7", "-q")
    assert res.returncode == 0, res.stderr
    info = json.loads((tmp_path / "davis" / "scene.json").read_text())
    assert info["preset"]["threshold"] == pytest.approx(DAVIS346_THRESHOLD[0])
    assert info["preset"]["polarity_offset"] == pytest.approx(DAVIS346_THRESHOLD[1])
    noise = info["noise"]
    assert noise["jitter"] == pytest.approx(0.0001 / 0.05)
    assert noise["background_rate"] == pytest.approx(0.1 * 0.05)
    assert noise["hot_pixel_rate"] == 7.0  # an option overrides the preset's value
    res = _cli("simulate", "builtin:thin", str(tmp_path / "o"), "--noise", "davis346",
               "--view-seconds", "0")
    assert res.returncode == 2 and "--view-seconds: must be > 0" in res.stderr


@pytest.mark.slow
def test_full_default_dataset_round_trip(tmp_path):
    """The paper's setting (999 views, 346 x 260, 2x2 supersampling) end to end."""
    dataset_mod = pytest.importorskip("hybridneus.data.dataset")
    out = tmp_path / "device_full"
    info = simulate_dataset("builtin:device", out, SimulationConfig())
    ds = dataset_mod.load_dataset(out)
    for name, n in (("train", 999), ("validation", 100), ("test", 200)):
        split = ds.splits[name]
        assert split.c2w.shape[0] == n and (split.width, split.height) == (346, 260)
        assert float(split.events.t.max()) == n - 1
        assert info["splits"][name]["n_events"] == split.events.t.size
