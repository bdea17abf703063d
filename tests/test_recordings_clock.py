"""``convert --clock-offset auto``: the offset between the event clock and the pose clock,
found from the event rate and the camera's speed, or refused where the motion cannot pin it."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hybridneus.errors import RecordingError
from hybridneus.recordings import make_track, read_turntable
from hybridneus.recordings.clock import estimate_clock_offset
from hybridneus.recordings.stream import EventChunk, EventSource

DURATION = 40.0  # seconds the simulated hand takes over the path


@pytest.fixture(scope="module")
def split(tmp_path_factory):
    """A small simulated scene: 240 views, two turns about the object."""
    from hybridneus.data import load_dataset
    from hybridneus.simulate import EventModel, SimulationConfig, simulate_dataset

    root = tmp_path_factory.mktemp("clock")
    cfg = SimulationConfig(n_views=240, width=64, height=48, val_views=0, test_views=0,
                           revolutions=2.0, supersample=1, spiral="even",
                           events=EventModel(mosaic="mono"))
    simulate_dataset("builtin:device", root, cfg, progress=False)
    return load_dataset(root, splits="train")["train"]


class _Events(EventSource):
    def __init__(self, rec) -> None:
        self.rec, self.path, self.size = rec, Path("events.npz"), (64, 48)

    def chunks(self):
        r = self.rec
        yield EventChunk(r.t, r.x.astype(np.int32), r.y.astype(np.int32), r.p > 0)


def _recording(split, variation: float, seed: int, offset: float):
    from hybridneus.simulate.recording import as_recording, handheld_times

    times = handheld_times(split.n_views, DURATION, seed, variation)
    return as_recording(split.events, split.c2w, times, t0=1650000000.0, clock_offset=offset)


@pytest.mark.parametrize("seed, offset", [(0, 0.04), (1, -1.3)])
def test_the_offset_of_a_handheld_capture_is_found_within_its_stated_error(split, seed,
                                                                           offset):
    rec = _recording(split, 1.0, seed, offset)
    track = make_track(rec.pose_t, rec.quat, rec.position, "mocap.txt")
    est = estimate_clock_offset(_Events(rec), track, float(split.intrinsics[0][0, 0]))
    assert est.uncertainty < 0.004
    assert abs(est.offset - offset) < max(3 * est.uncertainty, 0.002)
    assert "clock offset" in est.line() and est.shift_px > 0


def test_an_epoch_clock_finds_the_offset_a_zero_clock_does(split):
    """DV stamps host-epoch microseconds: the speed curve's 1 ms grid must not drift there
    (an ``np.arange`` from 1.65e9 s steps 1e-4 off and put the offset 2 ms off a minute)."""
    from hybridneus.recordings.clock import FINE, camera_speed
    from hybridneus.simulate.recording import as_recording, handheld_times

    times = handheld_times(split.n_views, DURATION, 0, 1.0)
    found, curves = [], []
    for t0 in (0.0, 1650000000.0):
        rec = as_recording(split.events, split.c2w, times, t0=t0, clock_offset=0.04)
        track = make_track(rec.pose_t, rec.quat, rec.position, "mocap.txt")
        start, speed = camera_speed(track)
        assert start == pytest.approx(t0 + 0.04, abs=1e-6)
        curves.append(speed)
        found.append(estimate_clock_offset(_Events(rec), track, 60.0).offset)
    n = min(c.size for c in curves)  # the last sample may round either way
    assert abs(curves[0].size - curves[1].size) <= 1 and n == pytest.approx(times[-1] / FINE,
                                                                              abs=10)
    np.testing.assert_allclose(curves[1][:n], curves[0][:n], rtol=1e-3)
    assert found[1] == pytest.approx(found[0], abs=2e-5)


def test_a_constant_speed_cannot_pin_an_offset_and_is_refused(split, tmp_path):
    rec = _recording(split, 0.0, 0, 0.04)
    track = make_track(rec.pose_t, rec.quat, rec.position, "turntable-mocap.txt")
    with pytest.raises(RecordingError, match=r"turntable-mocap.txt: .*give it with "
                                             r"--clock-offset S"):
        estimate_clock_offset(_Events(rec), track, 60.0)
    (tmp_path / "table.json").write_text(json.dumps(
        {"axis": [0, 1, 0], "speed_deg_s": 20, "camera": np.eye(4).tolist()}))
    with pytest.raises(RecordingError, match="needs a sampled pose track"):
        estimate_clock_offset(_Events(rec), read_turntable(tmp_path / "table.json"), 60.0)


def test_the_cli_converts_with_the_estimated_offset(split, tmp_path, run_cli):
    rec = _recording(split, 1.0, 0, 0.25)
    np.savez(tmp_path / "events.npz", t=np.round(rec.t * 1e6).astype(np.int64), x=rec.x,
             y=rec.y, p=rec.p)
    np.savetxt(tmp_path / "poses.txt", rec.tum_rows(), fmt="%.9f")
    K = split.intrinsics[0]
    (tmp_path / "calib.json").write_text(json.dumps({
        "fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2] - 0.5, "cy": K[1, 2] - 0.5, "width": 64,
        "height": 48}))
    args = ["convert", str(tmp_path / "events.npz"), str(tmp_path / "data"), "--poses",
            str(tmp_path / "poses.txt"), "--calib", str(tmp_path / "calib.json"), "--views",
            "100", "--time-unit", "us", "-q", "--clock-offset"]
    code, text, err = run_cli(*args, "auto")
    assert code == 0, err
    assert "estimated from the event rate" in text
    doc = json.loads((tmp_path / "data" / "scene.json").read_text())
    est = doc["poses"]["clock_offset_estimate"]
    assert doc["poses"]["clock_offset_s"] == est["offset_s"]
    assert abs(est["offset_s"] - 0.25) < max(3 * est["uncertainty_s"], 0.002)
    code, _, err = run_cli(*args, "soon")
    assert code == 2 and "--clock-offset: expected seconds or auto, got 'soon'" in err


def test_handheld_times_vary_the_speed_as_asked_and_keep_the_span():
    from hybridneus.simulate.recording import handheld_times

    steady = handheld_times(101, 20.0, 0, 0.0)
    np.testing.assert_allclose(steady, np.linspace(0.0, 20.0, 101), atol=1e-6)
    for variation in (0.3, 1.0):
        t = handheld_times(401, 20.0, 3, variation)
        assert t[0] == 0.0 and t[-1] == pytest.approx(20.0) and np.all(np.diff(t) > 0)
        spread = np.std(np.log(np.diff(t)))
        assert 0.5 * variation < spread < 1.5 * variation
