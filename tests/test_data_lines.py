"""Silent lines: runs of unchanged pixels along the image motion, and their three rays."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from hybridneus.data.lines import changed_mask, image_motion, silent_lines
from hybridneus.training.priors.silent_lines import line_residual, plane_depth


def _strips(width: int = 60, height: int = 40, columns=(10, 40)) -> np.ndarray:
    fired = np.zeros((height, width), dtype=bool)
    for c in columns:
        fired[5:35, c] = True
    return fired


def test_a_run_between_two_fired_columns_ends_a_margin_inside_them():
    lines = silent_lines(_strips(), np.array([1.0, 0.0]), 50, np.random.default_rng(0))
    assert len(lines) > 10
    # fired at 10 and 40, one pixel of margin: the run is columns 12 .. 38
    assert (lines.start[:, 0] == 12).all() and (lines.end[:, 0] == 38).all()
    assert (lines.start[:, 1] == lines.middle[:, 1]).all()
    assert (lines.end[:, 1] == lines.middle[:, 1]).all()
    assert ((lines.middle[:, 0] > 12) & (lines.middle[:, 0] < 38)).all()
    np.testing.assert_allclose(lines.t, (lines.middle[:, 0] - 12) / 26.0, atol=1e-6)
    # rows 5 .. 34 hold the fired pixels, and a run needs them on both sides
    assert ((lines.middle[:, 1] >= 5) & (lines.middle[:, 1] < 35)).all()


def test_runs_into_the_border_short_runs_and_an_empty_window_give_no_line():
    rng = np.random.default_rng(1)
    assert len(silent_lines(_strips(columns=(10,)), np.array([1.0, 0.0]), 50, rng)) == 0
    assert len(silent_lines(_strips(columns=(10, 16)), np.array([1.0, 0.0]), 50, rng)) == 0
    short = silent_lines(_strips(columns=(10, 16)), np.array([1.0, 0.0]), 50, rng,
                         min_length=2)
    assert len(short) > 0
    assert len(silent_lines(np.zeros((20, 30), bool), np.array([1.0, 0.0]), 50, rng)) == 0
    # along the strips, a run meets no fired pixel before the border
    assert len(silent_lines(_strips(), np.array([0.0, 1.0]), 50, rng)) == 0


def test_a_diagonal_motion_walks_diagonal_runs():
    fired = np.zeros((50, 50), dtype=bool)
    idx = np.arange(50)
    for off in (-15, 15):  # two anti-diagonal bands cross every diagonal walk
        ok = (idx + off >= 0) & (idx + off < 50)
        fired[idx[ok], (49 - idx - off)[ok]] = True
    fired = changed_mask(np.stack([np.zeros_like(fired), fired], -1).astype(np.int64))
    lines = silent_lines(fired, np.array([1.0, 1.0]), 40, np.random.default_rng(2),
                         min_length=4)
    assert len(lines) > 0
    d = lines.end - lines.start
    assert (d[:, 0] == d[:, 1]).all() and (d[:, 0] > 0).all()


def test_a_pixel_whose_events_cancel_has_not_changed():
    counts = np.zeros((9, 9, 2), dtype=np.int64)
    counts[2, 2] = (3, 3)  # an edge passed and the brightness came back
    counts[6, 6] = (0, 2)
    changed = changed_mask(counts)
    assert not changed[2, 2]
    assert changed[5:8, 5:8].all() and changed.sum() == 9  # grown by one pixel


def test_the_image_motion_of_a_camera_moving_right_is_to_the_left():
    K = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    c2w0 = np.eye(4)
    c2w0[:3, 3] = (0.0, 0.0, -3.0)
    c2w1 = c2w0.copy()
    c2w1[0, 3] = 0.2
    np.testing.assert_allclose(image_motion(K, c2w0, c2w1), [-1.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(image_motion(K, c2w0, c2w0), [1.0, 0.0])


def _plane_rays(xs: np.ndarray, slope: float, bulge: float = 0.0):
    """Rays from the origin along +z through image columns xs (normalised coordinates) and
    their distances to the plane z = 2 + slope * x (plus ``bulge`` at the middle one)."""
    dirs = np.stack([xs, np.zeros_like(xs), np.ones_like(xs)], -1)
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    z = 2.0 / (1.0 - slope * dirs[:, 0] / dirs[:, 2])  # where x = z * dx / dz meets it
    dist = z / dirs[:, 2]
    dist[1] += bulge / dirs[1, 2]
    return torch.tensor(dist, dtype=torch.float32), torch.tensor(dirs, dtype=torch.float32)


@pytest.mark.parametrize("slope", [0.0, 0.4, -0.7])
def test_the_middle_of_a_line_on_a_plane_lies_on_it(slope):
    xs = np.array([-0.3, 0.05, 0.25])  # start, middle, end
    t = torch.tensor([(0.05 + 0.3) / 0.55])
    dist, dirs = _plane_rays(xs, slope)
    forward = torch.tensor([0.0, 0.0, 1.0])
    gap = line_residual(dist, torch.ones(3), dirs, forward, t)
    assert float(gap) == pytest.approx(0.0, abs=1e-5)
    sunk, _ = _plane_rays(xs, slope, bulge=0.05)
    assert float(line_residual(sunk, torch.ones(3), dirs, forward, t)) == pytest.approx(
        0.05, rel=1e-3)
    # a middle in front of its plane is not pulled, a line that misses is not counted
    proud, _ = _plane_rays(xs, slope, bulge=-0.05)
    assert float(line_residual(proud, torch.ones(3), dirs, forward, t)) == 0.0
    empty = line_residual(sunk, torch.tensor([1.0, 0.3, 1.0]), dirs, forward, t)
    assert float(empty) == 0.0


def test_plane_depth_interpolates_inverse_depth():
    z = plane_depth(torch.tensor([1.0]), torch.tensor([3.0]), torch.tensor([0.5]))
    assert float(z) == pytest.approx(1.5)


def test_a_middle_far_behind_its_ends_looks_past_something_and_is_left_out():
    """A gap of 0.05 over a line about 1.1 long bends it by 5%: counted under a max_bend of
    0.1, left out under 0.02."""
    xs = np.array([-0.3, 0.05, 0.25])
    t = torch.tensor([(0.05 + 0.3) / 0.55])
    sunk, dirs = _plane_rays(xs, 0.0, bulge=0.05)
    forward = torch.tensor([0.0, 0.0, 1.0])
    ones = torch.ones(3)
    assert float(line_residual(sunk, ones, dirs, forward, t, 0.1)) == pytest.approx(0.05,
                                                                                  rel=1e-3)
    assert float(line_residual(sunk, ones, dirs, forward, t, 0.02)) == 0.0
