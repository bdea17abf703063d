"""Smoothing a jittery camera track (``refine.pose_smoothing``), and captures simulated with
known pose errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from fitting import tiny
from scipy.spatial.transform import Rotation

from hybridneus.data.track import choose_window, filter_is_exact, pose_errors, smooth_track


def _orbit(n: int, turns: float = 2.0, radius: float = 1.0) -> np.ndarray:
    """Cameras on a rising orbit, each looking at the origin (OpenCV axes)."""
    c2w = np.tile(np.eye(4), (n, 1, 1))
    for k, a in enumerate(np.linspace(0.0, 2 * np.pi * turns, n)):
        centre = radius * np.array([np.cos(a), np.sin(a), 0.3 * np.sin(a / turns)])
        forward = -centre / np.linalg.norm(centre)
        right = np.cross(forward, [0.0, 0.0, 1.0])
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        c2w[k, :3, :3] = np.stack([right, down, forward], axis=1)
        c2w[k, :3, 3] = centre
    return c2w


def _jitter(c2w: np.ndarray, degrees: float, shift: float, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    out = c2w.copy()
    turn = Rotation.from_rotvec(rng.normal(0, np.radians(degrees) / np.sqrt(3), (len(c2w), 3)))
    out[:, :3, :3] = c2w[:, :3, :3] @ turn.as_matrix()
    out[:, :3, 3] += rng.normal(0, shift / np.sqrt(3), (len(c2w), 3))
    return out


def test_jitter_is_taken_out_and_the_motion_kept():
    truth = _orbit(600)
    given = _jitter(truth, 0.5, 0.01, seed=0)
    smoothed = smooth_track(given, 31)
    before, after = pose_errors(given, truth), pose_errors(smoothed, truth)
    assert after[0].mean() < before[0].mean() / 2.5
    assert after[1].mean() < before[1].mean() / 2.5
    # on a track without jitter the filter changes (almost) nothing, at the ends too
    kept = pose_errors(smooth_track(truth, 31), truth)
    assert kept[0].max() < 0.01 and kept[1].max() < 1e-4


def test_a_turn_through_half_a_revolution_keeps_its_quaternions_continuous():
    # scipy may return q or -q for neighbouring views; unaligned signs would average to
    # nonsense and the orientations would flip
    angles = np.linspace(0.0, 2.5 * np.pi, 200)
    c2w = np.tile(np.eye(4), (200, 1, 1))
    c2w[:, :3, :3] = Rotation.from_rotvec(angles[:, None] * [0.0, 1.0, 0.0]).as_matrix()
    quat = Rotation.from_matrix(c2w[:, :3, :3]).as_quat()
    assert (np.einsum("ij,ij->i", quat[1:], quat[:-1]) < 0).any()  # the case is exercised
    assert pose_errors(smooth_track(c2w, 21), c2w)[0].max() < 0.01


def test_a_track_too_short_for_the_window_is_shortened_or_kept():
    truth = _orbit(12, turns=0.2)
    given = _jitter(truth, 0.5, 0.01, seed=1)
    np.testing.assert_array_equal(smooth_track(given[:6], 31), given[:6])  # 5 views < 7
    assert smooth_track(given, 31).shape == (12, 4, 4)  # an 11-view window
    np.testing.assert_array_equal(smooth_track(given, 0), given)
    with pytest.raises(ValueError, match="window"):
        smooth_track(given, -1)


def test_windows_whose_filter_scipy_cannot_compute_are_refused():
    # scipy's coefficients lose precision for long windows of high order; such a filter
    # pulls the track towards the origin instead of smoothing it
    from scipy.signal import savgol_filter

    from hybridneus.config import apply_overrides, preset_config, validate
    from hybridneus.errors import ConfigError

    truth = _orbit(600)
    assert filter_is_exact(41, 5) and filter_is_exact(111, 7)
    assert not filter_is_exact(181, 7) and not filter_is_exact(801, 5)
    shrunk = savgol_filter(truth[:, :3, 3], 181, 7, axis=0, mode="interp")
    assert np.linalg.norm(shrunk - truth[:, :3, 3], axis=1).max() > 0.5  # the case is real
    with pytest.raises(ValueError, match="numerically unstable"):
        smooth_track(truth, 181, order=7)
    cfg = apply_overrides(preset_config("fast"),
                          ["refine.pose_smoothing=181", "refine.pose_smoothing_order=7"])
    with pytest.raises(ConfigError, match=r"refine.pose_smoothing: .* at most 1\d\d views"):
        validate(cfg)
    validate(apply_overrides(preset_config("fast"), ["refine.pose_smoothing=-1"]))
    with pytest.raises(ConfigError, match="refine.pose_smoothing"):
        validate(apply_overrides(preset_config("fast"), ["refine.pose_smoothing=-2"]))


def test_the_track_chooses_a_longer_window_the_more_it_jitters():
    truth = _orbit(900, turns=3.0)
    shortest = 7  # order 5 + 2
    assert choose_window(truth, 5) == shortest  # nothing to take out: bend the motion least
    chosen = {}
    for degrees, shift in ((0.1, 0.002), (0.5, 0.01), (2.0, 0.04)):
        given = _jitter(truth, degrees, shift, seed=3)
        w = chosen[degrees] = choose_window(given, 5)
        errors = {v: pose_errors(smooth_track(given, v), truth) for v in (shortest, w, 21, 61)}
        # the chosen window does better than the shortest and near the best of the others
        assert errors[w][0].mean() < errors[shortest][0].mean()
        best = min(e[0].mean() + 50 * e[1].mean() for e in errors.values())
        assert errors[w][0].mean() + 50 * errors[w][1].mean() < 1.25 * best
    assert chosen[0.1] < chosen[0.5] < chosen[2.0]
    assert choose_window(truth[:20], 5) == 0  # too short to score


def test_a_fit_trains_on_the_smoothed_track_and_saves_it(scene, tmp_path, run_cli):
    import cv2

    from hybridneus.api import fit
    from hybridneus.data.dataset import load_dataset
    from hybridneus.training import runs
    from hybridneus.training.runlog import POSES

    given = load_dataset(scene, splits=["train"]).splits["train"].c2w
    done = fit(scene, tiny("train.iters=2", "refine.pose_smoothing=9"), out=tmp_path / "a",
               device="cpu")
    saved = np.load(done.run_dir / POSES)
    np.testing.assert_allclose(saved["given"], given)
    np.testing.assert_allclose(saved["refined"], smooth_track(given, 9))
    assert not np.allclose(saved["refined"], given)
    state = runs.load_checkpoint(done.run_dir)
    np.testing.assert_allclose(state["scene"]["cameras"], saved["refined"][:, :3, 3])
    assert cv2.imread(str(done.run_dir / "previews" / "poses.png")) is not None
    code, out, err = run_cli("render", str(done.run_dir), "--views", "events", "--out",
                             str(tmp_path / "r"), "--windows", "1", "--device", "cpu")
    assert code == 0, err
    assert "train: the run's smoothed poses (poses_refined.npz)" in out
    plain = fit(scene, tiny("train.iters=2"), out=tmp_path / "b", device="cpu")
    assert not (plain.run_dir / POSES).exists()


def test_a_fit_chooses_its_window_from_the_track_and_records_it(scene, tmp_path):
    from hybridneus.api import fit
    from hybridneus.data.dataset import load_dataset
    from hybridneus.training.runlog import POSES
    from hybridneus.training.scene import FILENAME, SceneRecord

    given = load_dataset(scene, splits=["train"]).splits["train"].c2w
    done = fit(scene, tiny("train.iters=2", "refine.pose_smoothing=-1"), out=tmp_path,
               device="cpu")
    record = SceneRecord.load(done.run_dir / FILENAME)
    assert record.pose_window == choose_window(given, 5)
    np.testing.assert_allclose(np.load(done.run_dir / POSES)["refined"],
                               smooth_track(given, record.pose_window))
    assert any("smoothed over" in line or "too short" in line for line in record.lines())


def test_a_resumed_fit_smooths_over_the_recorded_window_and_ends_as_one_never_stopped(
        scene, tmp_path):
    """The window chosen from the track is prepared again from ``scene.yaml`` on --resume
    (nothing is estimated again), so the resumed fit trains on the same track."""
    from fitting import params, stop_at

    from hybridneus.api import fit

    cfg = tiny("train.iters=8", "train.seed=5", "refine.pose_smoothing=-1")
    straight = fit(scene, cfg, out=tmp_path / "a", device="cpu")
    first = fit(scene, cfg, [stop_at(4)], out=tmp_path / "b", device="cpu")
    assert first.interrupted
    resumed = fit(None, None, resume=first.run_dir, device="cpu")
    a, b = params(straight), params(resumed)
    for k in a:
        assert torch.equal(a[k], b[k]), k


def test_a_realistic_capture_writes_erroneous_poses_and_keeps_the_truth(tmp_path):
    from hybridneus.data import load_dataset
    from hybridneus.simulate import CaptureErrors, SimulationConfig, simulate_dataset

    base = dict(n_views=40, width=32, height=24, val_views=0, test_views=2, revolutions=1.0,
                supersample=1)
    simulate_dataset("builtin:device", tmp_path / "exact", SimulationConfig(**base))
    capture = CaptureErrors(rotation_deg=0.5, translation=0.01, clock_offset_views=0.25)
    simulate_dataset("builtin:device", tmp_path / "noisy",
                     SimulationConfig(**base, capture=capture))
    exact = load_dataset(tmp_path / "exact")
    noisy = load_dataset(tmp_path / "noisy")
    truth = np.stack([np.loadtxt(p) for p in
                      sorted((tmp_path / "noisy" / "train" / "pose_true").glob("*.txt"))])
    np.testing.assert_allclose(truth, exact["train"].c2w, atol=1e-9)
    # the same events (rendered from the truth); only the written training poses differ
    np.testing.assert_array_equal(noisy["train"].events.t, exact["train"].events.t)
    np.testing.assert_allclose(noisy["test"].c2w, exact["test"].c2w)
    degrees, moved = pose_errors(noisy["train"].c2w, truth)
    step = np.degrees(np.arccos(np.clip((np.trace(truth[1, :3, :3].T @ truth[0, :3, :3]) - 1)
                                        / 2, -1, 1)))
    assert 0.3 < np.sqrt(np.mean(degrees**2)) < 0.5 + 0.25 * step + 0.2
    assert 0.004 < np.sqrt(np.mean(moved**2)) / np.linalg.norm(truth[0, :3, 3])
