"""The events' visual hull: projection, silhouettes and the crop it gives."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
import trimesh
from conftest import simulate_device

from hybridneus.data import load_dataset
from hybridneus.data.firing import without_noise
from hybridneus.data.hull import (
    EventHull,
    FreeSpace,
    event_free_space,
    event_hull,
    event_hull_crop,
    event_silhouettes,
    project_to_pixels,
)
from hybridneus.data.rays import camera_rays


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    return simulate_device(tmp_path_factory.mktemp("hull") / "device", 60, 64, 48, 2.0)


@pytest.mark.parametrize("distortion", [(0.0, 0.0), (-0.2, 0.05)])
def test_projection_inverts_camera_rays(scene, distortion):
    split = load_dataset(scene)["train"]
    split = dataclasses.replace(split, distortion=np.tile(distortion, (split.n_views, 1)))
    xy = np.stack(np.meshgrid(np.arange(0, 64, 7), np.arange(0, 48, 5)), -1).reshape(-1, 2)
    origins, dirs = camera_rays(split.intrinsics[5], split.distortion[5], split.c2w[5], xy)
    points = (origins + 0.7 * dirs).numpy().astype(np.float64)
    u, v, front = project_to_pixels(split, 5, points)
    assert front.all()
    np.testing.assert_array_equal(np.stack([u, v], 1), xy)


def test_silhouettes_cover_the_object_and_leave_the_background(scene):
    split = load_dataset(scene)["train"]
    views, masks = event_silhouettes(split, window=1, dilate=0, step=10)
    assert len(views) >= 5
    fill = np.mean([m.mean() for m in masks])
    assert 0.02 < fill < 0.9  # an outline of the object, not the whole image


def _outline(h: int = 260, w: int = 346, every: int = 1) -> np.ndarray:
    """A moving object's firing pixels: a 3-pixel-wide ring, optionally one Bayer channel
    only (every other pixel along both axes), plus a short stroke far from it."""
    import cv2

    mask = np.zeros((h, w), np.uint8)
    cv2.ellipse(mask, (170, 130), (60, 40), 0, 0, 360, 1, 3)
    cv2.line(mask, (260, 60), (275, 50), 1, 2)
    mask = mask.astype(bool)
    if every > 1:
        keep = np.zeros_like(mask)
        keep[::every, ::every] = True
        mask &= keep
    return mask


def _hull_area(mask: np.ndarray) -> float:
    import cv2

    ys, xs = np.nonzero(mask)
    return float(cv2.contourArea(cv2.convexHull(np.stack([xs, ys], 1).astype(np.int32))))


def test_without_noise_leaves_a_clean_outline_alone():
    for every in (1, 2):
        clean = _outline(every=every)
        np.testing.assert_array_equal(without_noise(clean), clean)


@pytest.mark.parametrize("every", [1, 2])
@pytest.mark.parametrize("density", [0.002, 0.008])
def test_without_noise_removes_background_activity_and_keeps_the_outline(every, density):
    rng = np.random.default_rng(0)
    clean = _outline(every=every)
    noise = rng.random(clean.shape) < density
    got = without_noise(clean | noise)
    assert got is not None
    assert (got & clean).sum() == clean.sum()  # every outline pixel stays
    # noise pixels well away from the outline are gone: its convex hull is the object's
    assert _hull_area(got) < 1.1 * _hull_area(clean)
    assert _hull_area(clean | noise) > 5 * _hull_area(clean)  # what the filter is for


def test_without_noise_thins_a_slow_cameras_sensor_noise_by_asking_more_events_of_a_cell():
    # a DAVIS346's 0.1 Hz a pixel over two views of 60 ms: one 2x2 cell in 20 fires, too
    # many to tell lone cells from an outline; a passing edge fires each pixel a few times
    rng = np.random.default_rng(2)
    clean = _outline()
    noise = rng.poisson(0.015, clean.shape)
    counts = 3 * clean + noise
    got = without_noise(counts)
    assert got is not None
    assert (got & clean).sum() == clean.sum()
    assert _hull_area(got) < 1.1 * _hull_area(clean)
    assert without_noise(noise > 0) is None or not without_noise(noise > 0).any()


def test_without_noise_gives_up_on_a_window_drowned_in_noise():
    rng = np.random.default_rng(1)
    for density in (0.04, 0.2):
        assert without_noise(_outline() | (rng.random((260, 346)) < density)) is None


def test_silhouettes_of_noisy_events_match_the_clean_ones(scene, tmp_path):
    """Background activity and hot pixels from the simulator: the silhouettes stay the clean
    ones (they would fill the image without the filter) and the free space still spares
    the object."""
    from hybridneus.simulate import NoiseConfig, SimulationConfig, simulate_dataset

    noisy = tmp_path / "noisy"
    cfg = SimulationConfig(n_views=60, width=64, height=48, val_views=0, test_views=0,
                           revolutions=2.0, supersample=1,
                           noise=NoiseConfig(background_rate=0.002, hot_pixel_fraction=2e-3))
    simulate_dataset("builtin:device", noisy, cfg)
    clean_split, noisy_split = load_dataset(scene)["train"], load_dataset(noisy)["train"]
    views, clean = event_silhouettes(clean_split, step=10)
    noisy_views, masks = event_silhouettes(noisy_split, step=10)
    assert noisy_views == views
    covered = [(m & c).sum() / c.sum() for m, c in zip(masks, clean, strict=True)]
    assert min(covered) > 0.97
    assert np.mean([m.mean() for m in masks]) < 1.3 * np.mean([c.mean() for c in clean])
    _, raw = event_silhouettes(noisy_split, step=10, denoise=False)  # what the filter is for
    assert np.mean([m.mean() for m in raw]) > 1.5 * np.mean([c.mean() for c in clean])
    mesh = trimesh.load(scene / "gt_mesh.ply", force="mesh")
    lo, hi = mesh.bounds[0] - 0.3, mesh.bounds[1] + 0.3
    free = event_free_space(noisy_split, lo, hi, resolution=48)
    surface, _ = trimesh.sample.sample_surface(mesh, 3000, seed=0)
    assert free.free(torch.tensor(surface, dtype=torch.float32)).float().mean() < 0.002
    shell = mesh.vertices + 0.2 * mesh.vertex_normals
    assert free.free(torch.tensor(shell, dtype=torch.float32)).float().mean() > 0.5


def test_a_slow_turntable_pools_its_outlines_over_an_arc(scene, tmp_path):
    """On a circle of 240 views (1.5 degrees per view) with sensor noise, one window fires
    a sparse stroke of the outline and the hull carves the object; pooling the windows of
    the views within ``arc_deg`` restores it. Masks only grow, and a trajectory faster than
    the arc (the 60-view spiral: 12 degrees per view) keeps its own masks."""
    from hybridneus.simulate import EventModel, SimulationConfig, simulate_dataset
    from hybridneus.simulate.events import REALISTIC_NOISE

    cfg = SimulationConfig(n_views=240, revolutions=1.0, spiral="circle", elevation_deg=25.0,
                           width=64, height=48, supersample=1, val_views=0, test_views=0,
                           object_radius=0.25, noise=REALISTIC_NOISE,
                           events=EventModel(threshold=0.1, polarity_offset=-0.4))
    simulate_dataset("builtin:device", tmp_path / "turntable", cfg)
    split = load_dataset(tmp_path / "turntable")["train"]
    mesh = trimesh.load(tmp_path / "turntable" / "gt_mesh.ply", force="mesh")
    surface = torch.tensor(trimesh.sample.sample_surface(mesh, 3000, seed=0)[0],
                           dtype=torch.float32)
    lo, hi = mesh.bounds[0] - 0.2, mesh.bounds[1] + 0.2
    carved = {}
    for arc in (0.0, 2.0):
        silhouettes = event_silhouettes(split, step=2, arc_deg=arc)
        free = FreeSpace(event_hull(split, lo, hi, 48, silhouettes=silhouettes))
        carved[arc] = float(free.free(surface).float().mean())
    assert carved[2.0] < 0.5 * carved[0.0], carved
    own, pooled = event_silhouettes(split, step=2, arc_deg=0.0), event_silhouettes(split, step=2)
    common = set(own[0]) & set(pooled[0])
    assert len(common) > 0.9 * len(own[0])
    for view in common:
        mine, wide = own[1][own[0].index(view)], pooled[1][pooled[0].index(view)]
        assert (wide | mine == wide).all()  # pooling only adds to a view's outline
    fast = load_dataset(scene)["train"]
    a, b = event_silhouettes(fast, step=7, arc_deg=0.0), event_silhouettes(fast, step=7)
    assert a[0] == b[0] and all((x == y).all() for x, y in zip(a[1], b[1], strict=True))


def test_silhouettes_are_outlined_once_per_split_and_setting(scene, monkeypatch):
    import hybridneus.data.hull as hull_module

    split = load_dataset(scene)["train"]
    calls = []
    outline = hull_module._silhouettes
    monkeypatch.setattr(
        hull_module, "_silhouettes", lambda *a: calls.append(a[1:]) or outline(*a)
    )
    first = event_silhouettes(split, step=7)
    # the crop and the hull term both ask for these views: the second asks for nothing new
    event_hull_crop(split, (1.0, -1.0, 1.0), step=7)
    event_free_space(split, -np.ones(3), np.ones(3), resolution=16, step=7)
    assert calls == [(1, 2, 7, True, 2.0)]
    again = event_silhouettes(split, step=7)
    assert again[0] == first[0] and all(a is b for a, b in zip(again[1], first[1], strict=True))
    with pytest.raises(ValueError):  # a caller cannot spoil the others' masks
        again[1][0][0, 0] = True
    event_silhouettes(split, step=7, denoise=False)
    event_silhouettes(split, step=8)
    assert calls == [(1, 2, 7, True, 2.0), (1, 2, 7, False, 2.0), (1, 2, 8, True, 2.0)]
    # another split (its own events) outlines its own views
    event_silhouettes(load_dataset(scene)["train"], step=7)
    assert len(calls) == 4


def test_event_hull_takes_given_silhouettes(scene):
    split = load_dataset(scene)["train"]
    lo, hi = -np.ones(3), np.ones(3)
    own = event_hull(split, lo, hi, 20, step=7)
    views, masks = event_silhouettes(split, step=7)
    same = event_hull(split, lo, hi, 20, silhouettes=(views, masks))
    np.testing.assert_array_equal(same.occupied, own.occupied)
    # silhouettes that cover every image carve only what the vote-free rules carve
    whole = event_hull(split, lo, hi, 20, silhouettes=(views, [np.ones_like(m) for m in masks]))
    assert whole.occupied.sum() > 2 * own.occupied.sum()
    assert (whole.occupied | ~own.occupied).all()


def test_event_hull_crop_holds_the_object_and_shrinks_a_loose_crop(scene):
    split = load_dataset(scene)["train"]
    v = trimesh.load(scene / "gt_mesh.ply", force="mesh").vertices
    r, y0, y1 = event_hull_crop(split, (1.0, -1.0, 1.0))
    assert np.hypot(v[:, 0], v[:, 2]).max() <= r
    assert y0 <= v[:, 1].min() and v[:, 1].max() <= y1
    assert r < 0.8 and y1 - y0 < 1.5  # far tighter than the whole volume
    # it never grows a crop that is already tight
    tight = (0.3, -0.2, 0.25)
    got = event_hull_crop(split, tight)
    assert got[0] <= 0.3 and got[1] >= -0.2 and got[2] <= 0.25


def test_free_space_spares_the_object_and_frees_the_space_around_it(scene):
    split = load_dataset(scene)["train"]
    mesh = trimesh.load(scene / "gt_mesh.ply", force="mesh")
    lo, hi = mesh.bounds[0] - 0.3, mesh.bounds[1] + 0.3
    free = event_free_space(split, lo, hi, resolution=48)
    surface, _ = trimesh.sample.sample_surface(mesh, 3000, seed=0)
    assert not free.free(torch.tensor(surface, dtype=torch.float32)).any()
    # a shell 0.2 out from the object is mostly seen against the background somewhere
    shell = mesh.vertices + 0.2 * mesh.vertex_normals
    assert free.free(torch.tensor(shell, dtype=torch.float32)).float().mean() > 0.5
    # outside its grid the hull knows nothing
    far = torch.tensor([[hi[0] + 0.5, 0.0, 0.0], [0.0, lo[1] - 0.5, 0.0]], dtype=torch.float32)
    assert not free.free(far).any()


def test_free_space_grows_the_hull_by_whole_voxels():
    occupied = np.zeros((7, 7, 7), bool)
    occupied[3, 3, 3] = True
    hull = EventHull(occupied, np.array([-3.0, -3.0, -3.0]), 1.0, 1)
    assert (~FreeSpace(hull, grow=0).free_grid).sum() == 1
    free = FreeSpace(hull, grow=1)
    assert (~free.free_grid).sum() == 27
    # nearest voxel: 1.4 from the centre rounds to the grown ring, 1.6 to the free one
    pts = torch.tensor([[1.4, 0.0, 0.0], [1.6, 0.0, 0.0], [0.0, -1.4, 1.4]])
    assert free.free(pts).tolist() == [False, True, False]


def _without_crop(scene, tmp_path):
    """A copy of ``scene`` whose scene.json names no crop: the nerf group's whole volume."""
    import json
    import shutil

    loose = tmp_path / "device"
    shutil.copytree(scene, loose)
    meta = json.loads((loose / "scene.json").read_text())
    for key in ("crop_r", "crop_y_min", "crop_y_max"):
        meta["preset"].pop(key)
    (loose / "scene.json").write_text(json.dumps(meta))
    assert load_dataset(loose).preset.crop_r == 1.0
    return loose


def test_the_crop_estimate_shrinks_the_crop_unless_one_is_set(scene, tmp_path):
    from hybridneus.api import load_training_data
    from hybridneus.config import apply_overrides, preset_config
    from hybridneus.data.estimate import estimate_scene

    loose = _without_crop(scene, tmp_path)

    def estimated(*overrides):
        cfg = apply_overrides(preset_config("fast"), list(overrides))
        return estimate_scene(load_training_data(cfg, loose), cfg.estimate, cfg.data)

    assert estimated("data.crop_y_min=-0.9").dataset.preset.crop_r == 1.0  # the user's wins
    assert estimated("estimate.crop=false").dataset.preset.crop_r == 1.0
    found = estimated()  # on by default
    p = found.dataset.preset
    assert p.crop_r < 0.8 and p.crop_y_min > -1.0
    assert {"crop_r", "crop_y_min", "crop_y_max"} <= set(found.taken)
    assert "visual hull" in found.taken["crop_r"]


def test_cli_fit_says_which_crop_it_took(scene, tmp_path):
    import subprocess
    import sys

    loose = _without_crop(scene, tmp_path)
    proc = subprocess.run(
        [sys.executable, "-m", "hybridneus.cli.app", "fit", str(loose), "--iters", "1",
         "--device", "cpu", "--out", str(tmp_path / "runs"), "--set", "train.n_rays=32"],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    assert "from the events' visual hull (preset: r 1," in proc.stderr


def _cluttered(scene, tmp_path):
    """A copy of ``_without_crop(scene)`` whose background fires too: a smooth texture behind
    the object, sliding a pixel a view, adds its events everywhere in the image."""
    from scipy.ndimage import gaussian_filter

    from hybridneus.simulate import EventModel, EventSimulator

    loose = _without_crop(scene, tmp_path)
    path = loose / "train" / "events" / "events.npz"
    ev = dict(np.load(path))
    split = load_dataset(loose)["train"]
    rng = np.random.default_rng(0)
    base = 0.5 + 4 * gaussian_filter(rng.normal(0, 0.1, (48, 64 + split.n_views, 3)),
                                     (3, 3, 0))
    frames = [np.clip(base[:, k:k + 64], 0.05, 1) for k in range(split.n_views)]
    sim = EventSimulator(frames[0], EventModel(threshold=0.2))
    back = [sim.step(f) for f in frames[1:]]
    for key in ("x", "y", "t", "p"):
        ev[key] = np.concatenate([ev[key], *[getattr(c, key) for c in back]])
    order = np.argsort(ev["t"], kind="stable")
    np.savez(path, **{k: v[order] for k, v in ev.items()})
    return loose


def test_a_background_that_fires_turns_the_crop_and_the_hull_off_with_a_warning(
        scene, tmp_path, caplog, run_cli):
    import logging

    from hybridneus.api import load_training_data
    from hybridneus.config import preset_config
    from hybridneus.data.estimate import estimate_scene, training_data
    from hybridneus.data.hull import background_fires

    caplog.set_level(logging.WARNING, logger="hybridneus")
    assert background_fires(load_dataset(scene)["train"]) is None
    cluttered = _cluttered(scene, tmp_path)
    why = background_fires(load_dataset(cluttered)["train"])
    assert why is not None and "the background fires events" in why, why
    cfg = preset_config("fast")
    found = estimate_scene(load_training_data(cfg, cluttered), cfg.estimate, cfg.data)
    assert found.dataset.preset.crop_r == 1.0 and "crop_r" not in found.taken
    assert any("--box" in w and "hull prior is off" in w for w in found.warnings)
    data = training_data(found.dataset, cfg)
    assert data.free_space is None and "hull: off, the events fill the image" in caplog.text
    code, text, _ = run_cli("info", str(cluttered))
    assert code == 0 and "warning: the events fill the image" in text
