"""Pose refinement: the exponential map, moving rays onto corrected poses, recovering known
pose errors, and a fit that learns, saves and resumes its corrections."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from fitting import tiny
from scipy.spatial.transform import Rotation

from hybridneus.data.rays import camera_rays
from hybridneus.model.poses import PoseCorrections, pose_errors, so3_exp


@pytest.mark.parametrize("scale", [1e-9, 1e-5, 1e-3, 0.3, 3.0])
def test_the_exponential_map_matches_scipy(scale):
    w = np.random.default_rng(0).normal(size=(64, 3)) * scale
    ours = so3_exp(torch.as_tensor(w)).numpy()
    np.testing.assert_allclose(ours, Rotation.from_rotvec(w).as_matrix(), atol=1e-12)


@pytest.mark.parametrize("scale", [0.0, 1e-6, 0.5, 2.0])
def test_the_exponential_maps_gradient_matches_finite_differences(scale):
    w = torch.as_tensor(np.random.default_rng(1).normal(size=(3, 3)) * scale,
                        dtype=torch.float64).requires_grad_()
    assert torch.autograd.gradcheck(so3_exp, (w,), eps=1e-7, atol=1e-6)


def _look_at(centre: np.ndarray) -> np.ndarray:
    forward = -centre / np.linalg.norm(centre)
    right = np.cross([0.0, -1.0, 0.0], forward)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    c2w = np.eye(4)
    c2w[:3, :3] = np.stack([right, down, forward], axis=1)
    c2w[:3, 3] = centre
    return c2w


def _errors(n: int, rot_deg: float, move: float, seed: int) -> np.ndarray:
    """(n, 4, 4) camera-frame pose errors of ``rot_deg`` and ``move`` (world units)."""
    rng = np.random.default_rng(seed)
    e = np.tile(np.eye(4), (n, 1, 1))
    axes = rng.normal(size=(n, 3))
    e[:, :3, :3] = Rotation.from_rotvec(
        np.radians(rot_deg) * axes / np.linalg.norm(axes, axis=1, keepdims=True)).as_matrix()
    e[:, :3, 3] = rng.normal(size=(n, 3)) * move / np.sqrt(3)
    return e


def test_moved_rays_are_the_rays_of_the_corrected_pose():
    K = np.array([[20.0, 0, 8], [0, 20.0, 6], [0, 0, 1]])
    c2w = _look_at(np.array([0.3, 0.5, 2.0]))
    xy = np.stack(np.meshgrid(np.arange(16), np.arange(12)), -1).reshape(-1, 2)
    poses = PoseCorrections(3).double()
    with torch.no_grad():
        poses.delta[1] = torch.tensor([0.01, -0.02, 0.03, 0.05, -0.01, 0.02])
    o, d = camera_rays(K, None, c2w, xy)
    moved = poses.move_rays(o.double(), d.double(), torch.as_tensor(c2w[:3, :3]), 1.0)
    o2, d2 = camera_rays(K, None, poses.corrected(np.stack([c2w] * 3))[1], xy)
    np.testing.assert_allclose(moved[0].detach().numpy(), o2.numpy(), atol=1e-5)
    np.testing.assert_allclose(moved[1].detach().numpy(), d2.numpy(), atol=1e-5)
    half = poses.at(0.5)  # between views the correction is interpolated
    assert torch.allclose(half, 0.5 * poses.delta[1])


def _sphere_colours(o: torch.Tensor, d: torch.Tensor, radius: float = 0.6) -> torch.Tensor:
    """Colour where rays meet a sphere at the origin, a smooth pattern of the hit point."""
    b = (o * d).sum(-1)
    c = (o * o).sum(-1) - radius**2
    t = -b - torch.sqrt((b * b - c).clamp_min(1e-9))
    p = o + t[:, None] * d
    return torch.stack([torch.sin(3 * p[:, 0]), torch.cos(2 * p[:, 1] + p[:, 2]),
                        torch.sin(2 * p[:, 2] - p[:, 0])], -1)


def test_known_pose_errors_are_recovered_against_a_fixed_scene():
    K = np.array([[40.0, 0, 16], [0, 40.0, 16], [0, 0, 1]])
    angles = np.linspace(0, 2 * np.pi, 6, endpoint=False)
    truth = np.stack([_look_at(np.array([2.2 * np.sin(a), 0.4, 2.2 * np.cos(a)]))
                      for a in angles])
    given = truth @ np.linalg.inv(_errors(6, 1.0, 0.03, seed=3))
    xy = np.stack(np.meshgrid(np.arange(0, 32, 2), np.arange(0, 32, 2)), -1).reshape(-1, 2)
    rays = [camera_rays(K, None, g, xy) for g in given]
    targets = [_sphere_colours(*camera_rays(K, None, t, xy)) for t in truth]
    poses = PoseCorrections(6)
    opt = torch.optim.Adam(poses.parameters(), lr=2e-3)
    for _ in range(400):
        loss = sum(((_sphere_colours(*poses.move_rays(o, d, torch.as_tensor(g[:3, :3],
                                                                          dtype=torch.float32),
                                                      float(i))) - tgt) ** 2).mean()
                   for i, ((o, d), g, tgt) in enumerate(zip(rays, given, targets, strict=True)))
        opt.zero_grad()
        loss.backward()
        opt.step()
    deg_before, moved_before = pose_errors(given, truth)
    deg_after, moved_after = pose_errors(poses.corrected(given), truth)
    assert deg_before.mean() > 0.9 and deg_after.max() < 0.1, deg_after
    assert moved_after.max() < 0.2 * moved_before.mean(), (moved_before, moved_after)


def test_knots_spread_one_correction_over_the_views_between_them():
    poses = PoseCorrections(9, knots=3)
    assert poses.delta.shape == (3, 6) and PoseCorrections(9).delta.shape == (9, 6)
    with torch.no_grad():
        poses.delta.copy_(torch.arange(18.0).reshape(3, 6))
    assert torch.equal(poses.at(4.0), poses.delta[1])  # knots at views 0, 4 and 8
    assert torch.allclose(poses.at(2.0), 0.5 * (poses.delta[0] + poses.delta[1]))
    assert torch.equal(poses.at(8.0), poses.delta[2])
    one = PoseCorrections(9, knots=1)
    with torch.no_grad():
        one.delta.fill_(0.01)
    assert all(torch.equal(one.at(v), one.delta[0]) for v in (0.0, 3.5, 8.0))


def test_a_negative_knot_count_is_refused():
    from hybridneus.config import apply_overrides, preset_config, validate
    from hybridneus.errors import ConfigError

    with pytest.raises(ConfigError, match="refine.pose_knots: expected >= 0"):
        validate(apply_overrides(preset_config("fast"), ["refine.pose_knots=-2"]))


def _circle(n: int, arc: float = 2 * np.pi, tilt: float = 0.4) -> np.ndarray:
    """(n, 4, 4) cameras at unequal steps along ``arc`` (radians) around the origin (the
    motion changes between views, as it does on a spiral)."""
    angles = np.linspace(0, arc, n, endpoint=False) ** 1.2 / arc**0.2
    return np.stack([_look_at(np.array([2.2 * np.sin(a), tilt + 0.3 * np.sin(3 * a),
                                        2.2 * np.cos(a)])) for a in angles])


def test_a_clock_offset_moves_every_view_along_the_track():
    from hybridneus.data.rays import interpolate_pose

    track = _circle(12)
    poses = PoseCorrections(12, knots=1, clock_track=track).double()
    with torch.no_grad():
        poses.clock.fill_(0.3)
    moved = poses.corrected(track)
    for k in range(11):
        ahead = interpolate_pose(track[k][None], track[k + 1][None], 0.3).reshape(4, 4)
        degrees, shift = pose_errors(moved[k][None], ahead[None])
        assert degrees[0] < 1e-3 and shift[0] < 1e-3, (k, degrees, shift)


def _recover(given: np.ndarray, truth: np.ndarray, poses: PoseCorrections, steps: int,
             weight: float = 0.0, lr: float = 2e-3) -> None:
    """Fit ``poses`` so that a fixed scene seen from the corrected ``given`` poses looks as
    it does from ``truth``."""
    K = np.array([[40.0, 0, 16], [0, 40.0, 16], [0, 0, 1]])
    xy = np.stack(np.meshgrid(np.arange(0, 32, 2), np.arange(0, 32, 2)), -1).reshape(-1, 2)
    rays = [camera_rays(K, None, g, xy) for g in given]
    targets = [_sphere_colours(*camera_rays(K, None, t, xy)) for t in truth]
    opt = torch.optim.Adam(poses.parameters(), lr=lr)
    for _ in range(steps):
        loss = sum(((_sphere_colours(*poses.move_rays(o, d, torch.as_tensor(g[:3, :3],
                                                                          dtype=torch.float32),
                                                      float(i))) - tgt) ** 2).mean()
                   for i, ((o, d), g, tgt) in enumerate(zip(rays, given, targets, strict=True)))
        loss = loss + weight * poses.regulariser(list(range(len(given))))
        opt.zero_grad()
        loss.backward()
        opt.step()


def test_a_drift_and_a_clock_offset_are_recovered_against_a_fixed_scene():
    from hybridneus.simulate.capture import CaptureErrors, written_poses

    truth = _circle(16)
    drift = written_poses(truth, CaptureErrors(rotation_deg=1.5, translation=0.02,
                                               smooth_views=5, seed=2))
    poses = PoseCorrections(16, knots=4)  # the drift's knots: views 0, 5, 10 and 15
    _recover(drift, truth, poses, 300)
    before = pose_errors(drift, truth)[0]
    after = pose_errors(poses.corrected(drift), truth)[0]
    assert before.mean() > 0.8 and after.mean() < 0.1 and after.max() < 0.2, (before, after)

    # steps of 1 to 3 degrees (the datasets': 0.4), where the move along the track is
    # close to first order in the offset
    truth = _circle(16, arc=0.6)
    late = written_poses(truth, CaptureErrors(clock_offset_views=0.4))
    poses = PoseCorrections(16, knots=1, clock_track=late)
    # the knot pays for its size and the clock offset does not: the offset takes the shift
    _recover(late, truth, poses, 300, weight=1.0, lr=5e-3)
    clock = float(poses.clock.detach())
    assert abs(clock + 0.4) < 0.05, clock
    # (the simulator clamps the last view's time to the track's end, which also shortens
    # the motion from the view before it)
    errors = pose_errors(poses.corrected(late), truth)[0][:-2]
    assert errors.max() < 0.1, errors


def test_a_fit_learns_saves_and_resumes_its_pose_corrections(scene, tmp_path, run_cli):
    import cv2

    from hybridneus.api import fit
    from hybridneus.training import runs
    from hybridneus.training.runlog import POSES

    cfg = tiny("train.iters=12", "refine.poses=true", "refine.pose_start=0.25",
               "refine.pose_lr=0.01", "train.seed=3")
    straight = fit(scene, cfg, out=tmp_path / "a", device="cpu")
    state = runs.load_checkpoint(straight.run_dir)
    delta = state["poses"]
    assert delta.shape == (40, 6) and delta.abs().max() > 0  # learned after the start
    saved = np.load(straight.run_dir / POSES)
    assert saved["refined"].shape == (40, 4, 4) and len(saved["views"]) == 40
    assert not np.allclose(saved["refined"], saved["given"])
    np.testing.assert_allclose(state["scene"]["cameras"], saved["refined"][:, :3, 3])
    assert cv2.imread(str(straight.run_dir / "previews" / "poses.png")) is not None
    rows = (straight.run_dir / "metrics.csv").read_text().splitlines()
    assert "loss/pose" in rows[0]
    code, out, err = run_cli("render", str(straight.run_dir), "--views", "events", "--out",
                             str(tmp_path / "r"), "--windows", "1", "--device", "cpu")
    assert code == 0, err
    assert "train: the run's refined poses (poses_refined.npz)" in out

    from fitting import stop_at

    first = fit(scene, cfg, [stop_at(6)], out=tmp_path / "b", device="cpu")
    resumed = fit(None, None, resume=first.run_dir, device="cpu")
    again = runs.load_checkpoint(resumed.run_dir)
    assert torch.equal(again["poses"], delta)
    for k, v in state["model"].items():
        assert torch.equal(v, again["model"][k]), k


@pytest.mark.parametrize("gauge", [False, True])
def test_a_fit_learns_and_resumes_knots_and_a_clock_offset(scene, tmp_path, gauge):
    from fitting import stop_at

    from hybridneus.api import fit
    from hybridneus.training import runs
    from hybridneus.training.runlog import POSES

    cfg = tiny("train.iters=12", "refine.poses=true", "refine.pose_start=0.25",
               "refine.pose_lr=0.01", "refine.pose_knots=4", "refine.clock_offset=true",
               "train.seed=3", *(["refine.pose_gauge=true"] if gauge else []))
    straight = fit(scene, cfg, out=tmp_path / "a", device="cpu")
    state = runs.load_checkpoint(straight.run_dir)
    assert state["poses"].shape == (4, 6) and state["poses"].abs().max() > 0
    assert "gauge" not in str(list(state))  # the gauge map is rebuilt from the poses, not saved
    assert state["pose_clock"].shape == (1,) and float(state["pose_clock"]) != 0
    refined = np.load(straight.run_dir / POSES)["refined"]
    assert refined.shape == (40, 4, 4)
    rows = (straight.run_dir / "metrics.csv").read_text().splitlines()
    assert "clock_offset" in rows[0].split(",")
    first = fit(scene, cfg, [stop_at(6)], out=tmp_path / "b", device="cpu")
    again = runs.load_checkpoint(fit(None, None, resume=first.run_dir, device="cpu").run_dir)
    assert torch.equal(again["poses"], state["poses"])
    assert torch.equal(again["pose_clock"], state["pose_clock"])


def test_with_several_windows_a_step_corrects_the_views_of_every_window(scene, tmp_path,
                                                                         monkeypatch):
    from hybridneus.api import fit
    from hybridneus.model.poses import PoseCorrections
    from hybridneus.training import runs

    # Per-view corrections learn only from the windows that end (or start) at their view: a
    # step of one window moves at most four of them, a step of eight up to 32.
    seen = []
    move = PoseCorrections.move_rays

    def recording(self, origins, dirs, rot, view):
        seen.append(view)
        return move(self, origins, dirs, rot, view)

    monkeypatch.setattr(PoseCorrections, "move_rays", recording)
    moved = {}
    for windows in (1, 8):
        seen.clear()
        cfg = tiny("train.iters=4", "refine.poses=true", "refine.pose_start=0.0",
                   "refine.pose_lr=0.01", "train.seed=3", f"train.windows_per_step={windows}")
        done = fit(scene, cfg, out=tmp_path / str(windows), device="cpu")
        assert len(seen) == 4 * 2 * windows  # both ends of every window, every step
        delta = runs.load_checkpoint(done.run_dir)["poses"]
        moved[windows] = int((delta.abs().sum(1) > 0).sum())
    assert moved[1] <= 4 * 4 < moved[8]


def test_before_its_start_the_correction_stays_zero_and_takes_no_gradient(
        scene, tmp_path, monkeypatch):
    from fitting import stop_at

    from hybridneus.api import fit
    from hybridneus.model.poses import PoseCorrections
    from hybridneus.training import runs

    # Rays that carry a gradient cost the grid's gradient at every sample (the step time):
    # they may only do so once the poses learn.
    tracked = []
    move = PoseCorrections.move_rays

    def recording(self, *args):
        o, d = move(self, *args)
        tracked.append(o.requires_grad or d.requires_grad)
        return o, d

    monkeypatch.setattr(PoseCorrections, "move_rays", recording)
    cfg = tiny("train.iters=10", "refine.poses=true", "refine.pose_start=0.5")
    done = fit(scene, cfg, [stop_at(5)], out=tmp_path / "a", device="cpu")
    assert runs.load_checkpoint(done.run_dir)["poses"].abs().max() == 0
    assert tracked and not any(tracked)
    tracked.clear()
    fit(scene, cfg, out=tmp_path / "b", device="cpu")
    assert tracked[-1] and not tracked[0]


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


def _orbit(n: int = 60) -> np.ndarray:
    """(n, 4, 4) cameras on a tilted circle of radius 0.9, looking at the origin."""
    from hybridneus.simulate.trajectory import look_at_origin

    angles = np.linspace(0, 2 * np.pi, n, endpoint=False)
    dirs = np.stack([np.cos(angles), 0.3 * np.sin(3 * angles), np.sin(angles)], 1)
    return look_at_origin(dirs / np.linalg.norm(dirs, axis=1, keepdims=True), angles, 0.9)


def _similarity_corrections(c2w: np.ndarray, q, t, sigma) -> np.ndarray:
    """(n, 6) camera-frame corrections that turn every camera by the world rotation ``q`` and
    move its centre by ``q x c + t + sigma c``: the whole track moved as one."""
    rot, centre = c2w[:, :3, :3], c2w[:, :3, 3]
    shift = np.cross(q, centre) + t + sigma * centre
    return np.concatenate([np.einsum("nji,j->ni", rot, q),
                           np.einsum("nji,nj->ni", rot, shift)], axis=1)


def test_the_gauge_takes_out_a_motion_of_the_whole_track_and_keeps_the_rest():
    c2w = _orbit(200)
    poses = PoseCorrections(len(c2w), 0, gauge_track=c2w)
    common = _similarity_corrections(c2w, np.array([0.01, -0.02, 0.015]),
                                     np.array([0.01, 0.0, -0.02]), 0.03)
    with torch.no_grad():
        poses.delta.copy_(torch.as_tensor(common, dtype=torch.float32))
    poses.remove_gauge()
    assert poses.delta.abs().max() < 1e-3 * np.abs(common).max()
    relative = np.random.default_rng(0).normal(0, 0.01, (len(c2w), 6))
    with torch.no_grad():
        poses.delta.copy_(torch.as_tensor(relative + common, dtype=torch.float32))
    poses.remove_gauge()
    kept = poses.delta.detach().double().numpy()
    assert np.abs(poses.gauge.double() @ torch.as_tensor(kept).reshape(-1)).max() < 1e-5
    # per-view errors hardly contain a motion of the whole track: most of them stay
    assert np.linalg.norm(kept - relative) < 0.2 * np.linalg.norm(relative)
    again = kept.copy()
    poses.remove_gauge()  # a projection: a second time changes nothing
    assert np.allclose(poses.delta.detach().numpy(), again, atol=1e-6)


def test_the_gauge_works_on_knots_and_takes_a_sideways_offset_as_a_turn_of_the_track():
    c2w = _orbit(80)
    knots = PoseCorrections(len(c2w), 5, gauge_track=c2w)
    with torch.no_grad():
        knots.delta.normal_(0, 0.01)
    knots.remove_gauge()
    d = knots.delta.detach().reshape(-1)
    assert (knots.gauge @ d).abs().max() < 1e-5
    # on an orbit around the object, one sideways camera-frame shift of every view moves
    # every centre along the orbit: nearly the whole track turned about its axis, which the
    # events cannot tell from the object turned the other way
    one = PoseCorrections(len(c2w), 1, gauge_track=c2w)
    offset = torch.tensor([[0.0, 0.0, 0.0, 0.02, 0.0, 0.0]])
    with torch.no_grad():
        one.delta.copy_(offset)
    one.remove_gauge()
    assert torch.linalg.norm(one.delta) < 0.8 * torch.linalg.norm(offset)
