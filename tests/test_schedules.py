"""The schedules are pure functions of training progress."""

from __future__ import annotations

import math

import pytest

from hybridneus.training import schedules as S


def test_ramp_waits_then_grows_linearly_to_one():
    assert S.ramp(0.0, 0.0, 0.0) == 1.0
    assert S.ramp(0.49, 0.5, 0.0) == 0.0 and S.ramp(0.5, 0.5, 0.0) == 1.0
    assert [S.ramp(p, 0.1, 0.4) for p in (0.05, 0.1, 0.2, 0.3, 0.5, 0.9)] == pytest.approx(
        [0.0, 0.0, 0.25, 0.5, 1.0, 1.0])


def test_lr_warms_up_holds_and_decays_to_its_final_factor():
    assert S.lr_factor(0.005, 0.01, 0.5, 0.1) == pytest.approx(0.5)
    assert S.lr_factor(0.3, 0.01, 0.5, 0.1) == 1.0
    assert S.lr_factor(0.75, 0.01, 0.5, 0.1) == pytest.approx(math.sqrt(0.1))
    assert S.lr_factor(1.0, 0.01, 0.5, 0.1) == pytest.approx(0.1)
    assert S.lr_factor(0.0, 0.0, 1.0, 0.1) == 1.0  # no warm-up, no decay


def test_the_sharpness_floor_grows_geometrically_then_holds():
    assert S.sharpness_floor(0.0, 20.0, 200.0, 0.5) == pytest.approx(20.0)
    assert S.sharpness_floor(0.25, 20.0, 200.0, 0.5) == pytest.approx(math.sqrt(20.0 * 200.0))
    assert S.sharpness_floor(0.5, 20.0, 200.0, 0.5) == pytest.approx(200.0)
    assert S.sharpness_floor(0.9, 20.0, 200.0, 0.5) == pytest.approx(200.0)
    assert S.sharpness_floor(0.1, 20.0, 0.0, 0.5) == 0.0  # no floor
    assert S.sharpness_floor(0.1, 20.0, 5.0, 0.5) == 5.0  # below the start: the floor itself
    # none during the delay; after it, the same curve as without one
    assert S.sharpness_floor(0.09, 20.0, 200.0, 0.5, 0.1) == 0.0
    assert S.sharpness_floor(0.1, 20.0, 200.0, 0.5, 0.1) == S.sharpness_floor(
        0.1, 20.0, 200.0, 0.5)
    # the blend: f ** w, w rising from near 0 to 1 over the blend, then the curve itself
    curve = S.sharpness_floor(0.12, 20.0, 200.0, 0.5)
    assert S.sharpness_floor(0.12, 20.0, 200.0, 0.5, 0.1, 0.04) == pytest.approx(curve ** 0.5)
    assert S.sharpness_floor(0.1, 20.0, 200.0, 0.5, 0.1, 0.04) < 1.01
    assert S.sharpness_floor(0.2, 20.0, 200.0, 0.5, 0.1, 0.04) == pytest.approx(
        S.sharpness_floor(0.2, 20.0, 200.0, 0.5))


def test_eps_eases_geometrically_into_its_value():
    assert S.eased(0.0, 0.1, 0.001, 0.05) == pytest.approx(0.1)
    assert S.eased(0.025, 0.1, 0.001, 0.05) == pytest.approx(0.01)
    assert S.eased(0.05, 0.1, 0.001, 0.05) == S.eased(0.9, 0.1, 0.001, 0.05) == 0.001
    assert S.eased(0.0, None, 0.001, 0.05) == 0.001  # nothing to ease from


def test_fading_falls_linearly_to_zero():
    assert [S.fading(p, 0.5) for p in (0.0, 0.25, 0.5, 0.9)] == pytest.approx([1, 0.5, 0, 0])
    assert S.fading(0.9, 0.0) == 1.0


def test_schedules_are_the_same_at_the_same_progress_whatever_the_length():
    short = [S.lr_factor(S.progress(s + 1, 100), 0.05, 0.5, 0.1) for s in range(0, 100, 10)]
    long = [S.lr_factor(S.progress(s + 1, 1000), 0.05, 0.5, 0.1) for s in range(9, 1000, 100)]
    assert short == pytest.approx(long)


def test_a_timeline_never_resized_is_step_over_total():
    line = S.Timeline(7)
    for step in range(9):
        assert line.progress(step) == S.progress(step, 7)
        assert line.position(step) == float(step)


def test_a_resized_timeline_keeps_the_progress_reached_and_ends_at_one():
    """Shortened at step 30 of 100, then lengthened at step 50 of the new 60: the progress is
    continuous at both knots, linear between them, and 1 at the final length; the steps
    before a resize keep the progress they had."""
    line = S.Timeline(100)
    line.resize(30, 60)
    assert line.progress(30) == pytest.approx(0.3)
    assert line.progress(45) == pytest.approx(0.3 + 15 * 0.7 / 30)
    at_50 = line.progress(50)
    line.resize(50, 150)
    assert line.progress(50) == pytest.approx(at_50)
    assert line.progress(150) == pytest.approx(1.0)
    assert line.progress(100) == pytest.approx(at_50 + 50 * (1 - at_50) / 100)
    for step in (0, 10, 29, 30, 40):
        assert line.progress(step) == pytest.approx(min(step, 30) / 100 + max(step - 30, 0)
                                                    * 0.7 / 30)
    values = [line.progress(s) for s in range(151)]
    assert all(b > a for a, b in zip(values, values[1:], strict=False))
    assert line.position(150) == pytest.approx(150.0)
    assert line.position(50) == pytest.approx(at_50 * 150)
