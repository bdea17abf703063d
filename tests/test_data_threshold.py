"""Contrast thresholds from a split's frames (hybridneus.data.threshold, estimate.threshold)."""

import json
import shutil

import cv2
import numpy as np
import pytest

from hybridneus.config import DataConfig, EstimateConfig
from hybridneus.data import load_dataset
from hybridneus.data.estimate import estimate_scene
from hybridneus.data.threshold import RUN_VIEWS, _log_frames, estimate_thresholds, replay_counts


@pytest.fixture(scope="module")
def unequal(tmp_path_factory):
    """The built-in device with ON / OFF thresholds 0.2 / 0.3 and a real sensor's noise
    (per-pixel threshold spread, background activity, hot pixels)."""
    from hybridneus.simulate import SimulationConfig, simulate_dataset
    from hybridneus.simulate.events import REALISTIC_NOISE, EventModel

    folder = tmp_path_factory.mktemp("thr") / "device"
    simulate_dataset("builtin:device", folder, SimulationConfig(
        n_views=60, width=96, height=72, val_views=0, test_views=2, supersample=1,
        events=EventModel(threshold=0.25, polarity_offset=-0.2), noise=REALISTIC_NOISE))
    return folder


@pytest.fixture(scope="module")
def textured(tmp_path_factory):
    """A generated object painted with a fine pattern, ON / OFF 0.2 / 0.3, realistic noise:
    most pixels change by less than a threshold between views and fire against a reference
    that lags their brightness, which a fit of frame differences against the counts between
    them cannot see (it read ON 0.135 / OFF 0.165 here)."""
    from hybridneus.simulate import SimulationConfig, simulate_dataset
    from hybridneus.simulate.events import REALISTIC_NOISE, EventModel

    folder = tmp_path_factory.mktemp("thr") / "blob"
    simulate_dataset("generated:blob:1", folder, SimulationConfig(
        n_views=200, width=96, height=72, val_views=0, test_views=2, supersample=1,
        events=EventModel(threshold=0.25, polarity_offset=-0.2), noise=REALISTIC_NOISE))
    return folder


def _unstated(folder, tmp_path, *keys):
    """A copy of the dataset whose scene.json no longer states ``keys``."""
    copy = tmp_path / folder.name
    shutil.copytree(folder, copy)  # (makes tmp_path too)
    doc = json.loads((copy / "scene.json").read_text())
    for key in keys:
        doc["preset"].pop(key)
    (copy / "scene.json").write_text(json.dumps(doc))
    return copy


def test_on_and_off_thresholds_come_back_from_the_frames(unequal):
    ds = load_dataset(unequal)
    est, why = estimate_thresholds(ds["train"], ds.preset)
    assert est is not None, why
    assert est.on == pytest.approx(0.2, rel=0.05)
    assert est.off == pytest.approx(0.3, rel=0.05)
    assert est.threshold == pytest.approx(0.25, rel=0.05)
    assert est.polarity_offset == pytest.approx(-0.2, abs=0.02)
    assert est.explained > 0.9


def test_thresholds_come_back_where_a_pattern_changes_by_less_than_a_threshold(textured):
    # the scene's own C, then one 40% off either way: the preset's C only starts the solve
    for overrides in ({}, {"threshold": 0.15}, {"threshold": 0.35}):
        ds = load_dataset(textured, overrides=overrides)
        est, why = estimate_thresholds(ds["train"], ds.preset)
        assert est is not None, why
        assert est.on == pytest.approx(0.2, rel=0.05)
        assert est.off == pytest.approx(0.3, rel=0.05)
        assert est.views == RUN_VIEWS and est.explained > 0.9


def test_the_replay_fires_the_simulators_events_at_the_true_thresholds(tmp_path):
    from hybridneus.simulate import SimulationConfig, simulate_dataset
    from hybridneus.simulate.events import EventModel

    folder = tmp_path / "clean"
    simulate_dataset("generated:blob:1", folder, SimulationConfig(
        n_views=60, width=64, height=48, val_views=0, test_views=2, supersample=1,
        events=EventModel(threshold=0.25, polarity_offset=-0.2)))
    split = load_dataset(folder)["train"]
    preset = load_dataset(folder).preset
    pixels = np.arange(64 * 48)
    frames, _ = _log_frames(split, preset, range(split.n_views), pixels)
    on = np.bincount((split.events.y * 64 + split.events.x)[split.events.p > 0], minlength=64 * 48)
    off = np.bincount((split.events.y * 64 + split.events.x)[split.events.p < 0], minlength=64 * 48)
    r_on, r_off = replay_counts(frames, 0.2, 0.3)
    # the simulator fires from its float frames, the replay reads the 8-bit ones
    assert r_on.sum() == pytest.approx(on.sum(), rel=0.03)
    assert r_off.sum() == pytest.approx(off.sum(), rel=0.03)
    assert np.mean((r_on == on) & (r_off == off)) > 0.8
    high_on, high_off = replay_counts(frames, 0.24, 0.36)
    assert high_on.sum() < 0.9 * on.sum() and high_off.sum() < 0.9 * off.sum()
    # with no OFF events the reference never comes down: ON fires only at new highs
    assert replay_counts(frames, 0.2, 50.0)[0].sum() < 0.5 * on.sum()


def test_frames_that_do_not_show_the_events_give_no_estimate(unequal, tmp_path):
    copy = _unstated(unequal, tmp_path)
    rng = np.random.default_rng(0)
    for path in sorted((copy / "train" / "rgb").glob("*.png")):  # placeholders of noise
        cv2.imwrite(str(path), rng.integers(20, 230, (72, 96, 3), dtype=np.uint8))
    ds = load_dataset(copy)
    est, why = estimate_thresholds(ds["train"], ds.preset)
    assert est is None and "explains only" in why
    shutil.rmtree(copy / "train" / "rgb")
    est, why = estimate_thresholds(load_dataset(copy)["train"], ds.preset)
    assert est is None and why == "no rgb/ frames"


def test_a_fit_takes_the_frames_thresholds_only_where_nothing_states_c(unequal, tmp_path):
    on = EstimateConfig(threshold=True)
    stated = estimate_scene(load_dataset(unequal), on)
    assert "threshold" not in stated.taken  # scene.json states it

    copy = _unstated(unequal, tmp_path, "threshold", "polarity_offset")
    assert "threshold" not in estimate_scene(load_dataset(copy), EstimateConfig()).taken  # off
    found = estimate_scene(load_dataset(copy), on)
    assert found.dataset.preset.threshold == pytest.approx(0.25, rel=0.05)
    assert found.dataset.preset.polarity_offset == pytest.approx(-0.2, abs=0.02)
    assert "rgb/ frames" in found.taken["threshold"]
    assert any(line.startswith("thresholds from the frames: ON") for line in found.lines)
    assert found.balance is None  # the frames' ON/OFF ratio, not the balance's

    told = estimate_scene(load_dataset(copy, overrides={"threshold": 0.4}), on,
                          DataConfig(threshold=0.4))
    assert "threshold" not in told.taken and told.dataset.preset.threshold == 0.4
    off = estimate_scene(load_dataset(copy), EstimateConfig(threshold=False))
    assert "threshold" not in off.taken and "polarity_offset" in off.taken  # the balance's

    # an eps of another log mapping (the fallback's 0.1 for the simulated 0.001) would move C
    # by a factor of three: without a stated eps the frames are not used
    no_eps = _unstated(unequal, tmp_path / "eps", "threshold", "polarity_offset", "tonemap_eps")
    unmapped = estimate_scene(load_dataset(no_eps), on)
    assert "threshold" not in unmapped.taken
    assert any("no tonemap eps states the frames' log mapping" in line
               for line in unmapped.lines)

    shutil.rmtree(copy / "train" / "rgb")
    guessed = estimate_scene(load_dataset(copy), on)
    assert "threshold" not in guessed.taken
    assert any("guess, stated nowhere (no rgb/ frames)" in line for line in guessed.lines)


def test_the_replay_runs_where_the_camera_moved_least():
    from scipy.spatial.transform import Rotation

    from hybridneus.data.threshold import slowest_run

    n = 300
    speed = np.ones(n - 1)
    speed[180:240] = 0.2  # a slow stretch: views 180 .. 240
    angle = np.concatenate([[0.0], np.cumsum(0.02 * speed)])
    c2w = np.tile(np.eye(4), (n, 1, 1))
    c2w[:, :3, :3] = Rotation.from_euler("y", angle[:, None]).as_matrix()
    c2w[:, :3, 3] = 3.0 * np.stack([np.sin(angle), np.zeros(n), -np.cos(angle)], axis=1)
    assert slowest_run(c2w, 60) == 180
    assert slowest_run(c2w, 400) == 0  # shorter than the run: all of it
    c2w[:, :3, 3] = c2w[0, :3, 3]  # turning on the spot moves the scene across the image too
    assert slowest_run(c2w, 60) == 180
