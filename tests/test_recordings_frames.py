"""A DAVIS's own frames through ``convert``: the contrast threshold taken from them wherever
the views sit, and with ``--views frames`` views at the frames, kept as ``rgb/``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from hybridneus.data import load_dataset
from hybridneus.errors import RecordingError

THRESHOLD = (0.25, -0.15)  # C and polarity offset the scene is simulated with
FPS, EXPOSURE = 10.0, 0.005


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """A small scene simulated with unequal ON / OFF thresholds, re-timed as a 24-second
    hand-held capture and written as DV writes a DAVIS346: events and 10 Hz frames in one
    AEDAT4 file, a 200 Hz TUM track and a calibration."""
    from hybridneus.simulate import EventModel, SimulationConfig, simulate_dataset
    from hybridneus.simulate.recording import (
        aps_frames,
        as_recording,
        handheld_times,
        write_aedat4,
        write_hdf5,
    )

    root = tmp_path_factory.mktemp("frames")
    cfg = SimulationConfig(n_views=240, width=64, height=48, val_views=0, test_views=0,
                           revolutions=2.0, supersample=1, spiral="even",
                           events=EventModel(threshold=THRESHOLD[0],
                                             polarity_offset=THRESHOLD[1], mosaic="mono"))
    simulate_dataset("builtin:device", root / "sim", cfg, progress=False)
    sp = load_dataset(root / "sim", splits="train")["train"]
    times = handheld_times(sp.n_views, 24.0, 0, 0.3)
    rec = as_recording(sp.events, sp.c2w, times, t0=100.0)
    frames = aps_frames(lambda i: np.asarray(Image.open(sp.rgb_paths[i]).convert("RGB")),
                        times, FPS, EXPOSURE, t0=100.0)
    write_aedat4(root / "davis.aedat4", rec, frames, (sp.width, sp.height))
    write_hdf5(root / "davis.h5", rec, frames, (sp.width, sp.height))
    np.savetxt(root / "poses.txt", rec.tum_rows(), fmt="%.9f")
    K = sp.intrinsics[0]
    (root / "calib.json").write_text(json.dumps({
        "fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2] - 0.5, "cy": K[1, 2] - 0.5,
        "width": sp.width, "height": sp.height}))
    return {"root": root, "rec": rec, "frames": frames, "split": sp}


def _convert(capture, run_cli, out: Path, *extra: str, recording: str = "davis.aedat4"):
    root = capture["root"]
    return run_cli("convert", str(root / recording), str(out), "--poses",
                   str(root / "poses.txt"), "--calib", str(root / "calib.json"), "--sensor",
                   "mono", "-q", *extra)


@pytest.mark.parametrize("recording", ["davis.aedat4", "davis.h5"])
def test_views_sit_at_the_frames_which_become_the_rgb_files(capture, tmp_path, run_cli,
                                                            recording):
    from hybridneus.recordings import read_pose_table, read_scene_frame
    from hybridneus.recordings.frames import encode_srgb

    code, text, err = _convert(capture, run_cli, tmp_path / "data", "--views", "frames",
                               recording=recording)
    assert code == 0, err
    frames = capture["frames"]
    assert f"{len(frames)} views (at the camera's frames" in text
    doc = json.loads((tmp_path / "data" / "scene.json").read_text())
    assert doc["frames"]["n"] == len(frames) and doc["preset"]["tonemap_eps"] == 1e-3
    # an HDF5 file carries no exposure times
    exposure = EXPOSURE if recording.endswith("aedat4") else 0.0
    assert doc["frames"]["mean_exposure_s"] == pytest.approx(exposure)
    sp = load_dataset(tmp_path / "data")["train"]
    assert sp.n_views == len(frames) and len(sp.rgb_paths) == len(frames)
    for k in (0, len(frames) // 2, len(frames) - 1):
        kept = np.asarray(Image.open(sp.rgb_paths[k]).convert("RGB"))
        np.testing.assert_array_equal(kept, encode_srgb(frames[k].image))
    # each view's pose is the track's at the middle of its frame's exposure
    track = read_pose_table(capture["root"] / "poses.txt")
    truth = track.at(np.array([f.t for f in frames]))
    frame = read_scene_frame(tmp_path / "data")
    np.testing.assert_allclose(frame.to_recording(sp.c2w[:, :3, 3]), truth[:, :3, 3],
                               atol=1e-6)
    # events between the first and the last frame, none left out between
    rec = capture["rec"]
    inside = (rec.t >= frames[0].t) & (rec.t <= frames[-1].t)
    assert len(sp.events) == int(inside.sum())


@pytest.mark.parametrize("recording", ["davis.aedat4", "davis.h5"])
def test_the_threshold_comes_from_the_kept_frames(capture, tmp_path, run_cli, recording):
    from hybridneus.data.threshold import estimate_thresholds

    code, _, err = _convert(capture, run_cli, tmp_path / "data", "--views", "frames",
                            recording=recording)
    assert code == 0, err
    ds = load_dataset(tmp_path / "data")
    est, reason = estimate_thresholds(ds["train"], ds.preset)
    assert est is not None, reason
    c, o = THRESHOLD
    assert est.threshold == pytest.approx(c, rel=0.1)
    assert est.polarity_offset == pytest.approx(o, abs=0.05)


@pytest.mark.parametrize("recording", ["davis.aedat4", "davis.h5"])
def test_convert_takes_the_threshold_from_the_frames_wherever_the_views_sit(
        capture, tmp_path, run_cli, recording):
    code, text, err = _convert(capture, run_cli, tmp_path / "data", "--views", "300",
                               recording=recording)
    assert code == 0, err
    doc = json.loads((tmp_path / "data" / "scene.json").read_text())
    found = doc["sensor"]["threshold_from_frames"]
    c, o = THRESHOLD
    assert doc["preset"]["threshold"] == found["threshold"] == pytest.approx(c, rel=0.1)
    assert found["on"] == pytest.approx(c * (1 + o), rel=0.1)
    assert found["off"] == pytest.approx(c * (1 - o), rel=0.1)
    assert found["frames_in_span"] >= len(capture["frames"]) - 2 and found["explained"] > 0.5
    assert f"contrast threshold C {found['threshold']:.4g}" in text
    assert "frames" not in doc and "tonemap_eps" not in doc["preset"]  # views along the track
    ds = load_dataset(tmp_path / "data")
    assert ds["train"].n_views == 300 and ds["train"].rgb_paths is None
    assert ds.preset.threshold == found["threshold"] and "threshold" in ds.stated
    # a stated threshold stands
    code, text, err = _convert(capture, run_cli, tmp_path / "told", "--threshold", "0.3",
                               recording=recording)
    assert code == 0, err
    doc = json.loads((tmp_path / "told" / "scene.json").read_text())
    assert doc["preset"]["threshold"] == 0.3 and "threshold_from_frames" not in doc["sensor"]
    assert "contrast threshold C" not in text


def test_frames_that_do_not_show_the_events_leave_the_guess(capture, tmp_path, run_cli):
    from hybridneus.simulate.recording import aps_frames, write_aedat4

    root = capture["root"]
    times = np.array([f.t for f in capture["frames"]]) - 100.0
    still = aps_frames(lambda i: np.full((48, 64, 3), 0.5), times, FPS, EXPOSURE, t0=100.0)
    write_aedat4(tmp_path / "still.aedat4", capture["rec"], still, (64, 48))
    write_aedat4(tmp_path / "none.aedat4", capture["rec"], [], (64, 48))
    for name, warned in (("still", True), ("none", False)):
        code, text, err = run_cli("convert", str(tmp_path / f"{name}.aedat4"),
                                  str(tmp_path / name), "--poses", str(root / "poses.txt"),
                                  "--calib", str(root / "calib.json"), "-q")
        assert code == 0, err
        doc = json.loads((tmp_path / name / "scene.json").read_text())
        assert "threshold" not in doc["preset"] and "threshold_from_frames" not in doc["sensor"]
        assert (f"{name}.aedat4: the contrast threshold was not taken from its frames (the "
                "frames do not change" in err) == warned
        assert "contrast threshold C" not in text


def test_frames_are_refused_where_there_are_none(capture, tmp_path, run_cli):
    from hybridneus.recordings.frames import read_frames
    from hybridneus.simulate.recording import write_aedat4, write_hdf5

    write_aedat4(tmp_path / "events-only.aedat4", capture["rec"], [], (64, 48))
    with pytest.raises(RecordingError, match="events-only.aedat4: no frame track"):
        read_frames(tmp_path / "events-only.aedat4", (64, 48))
    with pytest.raises(RecordingError, match="covers 64x48 at \\(0, 0\\), not the 32x24"):
        read_frames(capture["root"] / "davis.aedat4", (32, 24))
    write_hdf5(tmp_path / "events-only.h5", capture["rec"], [], (64, 48))
    with pytest.raises(RecordingError, match="events-only.h5: no frames \\(expected images/"):
        read_frames(tmp_path / "events-only.h5", (64, 48))
    np.savez(tmp_path / "e.npz", x=capture["rec"].x, y=capture["rec"].y,
             t=np.round(capture["rec"].t * 1e6).astype(np.int64), p=capture["rec"].p)
    root = capture["root"]
    code, _, err = run_cli("convert", str(tmp_path / "e.npz"), str(tmp_path / "o"), "--poses",
                           str(root / "poses.txt"), "--calib", str(root / "calib.json"),
                           "--views", "frames", "-q")
    assert code == 2 and "only AEDAT4 (iniVation DV) and HDF5 files hold here" in err
    code, _, err = _convert(capture, run_cli, tmp_path / "o", "--views", "some")
    assert code == 2 and "--views: expected a number or frames, got 'some'" in err


def test_aps_frames_average_the_light_over_their_exposure():
    from hybridneus.simulate.recording import aps_frames

    dark, bright = np.zeros((2, 3, 3)), np.ones((2, 3, 3))
    views = [dark, bright, dark]
    times = np.array([0.0, 1.0, 2.0])
    short = aps_frames(lambda i: views[i], times, fps=1.0, exposure=0.01)
    assert [f.t for f in short] == pytest.approx([0.005, 1.005])
    assert short[1].image.max() >= 252 / 255  # at the bright view
    long = aps_frames(lambda i: views[i], times, fps=1.0, exposure=1.0)
    assert len(long) == 2 and long[0].t == pytest.approx(0.5)
    # over a ramp from dark to bright the light averages to a half: linear, not sRGB
    assert long[0].image.mean() == pytest.approx(0.5, abs=0.01)
    grey = aps_frames(lambda i: np.full((2, 3, 3), 0.5), times, fps=1.0, exposure=0.01)
    assert grey[0].image.mean() == pytest.approx(0.5**2.2, abs=1 / 255)
    deep = aps_frames(lambda i: np.full((2, 3, 3), 0.1), times, fps=1.0, exposure=0.01,
                      bits=16)
    assert deep[0].bits == 16 and deep[0].image.mean() == pytest.approx(0.1**2.2, abs=1e-5)
    assert abs(grey[0].image.mean() * 255 - round(grey[0].image.mean() * 255)) < 1e-4


def test_sixteen_bit_frames_keep_their_dark_end(capture, tmp_path):
    from hybridneus.recordings.frames import read_frames
    from hybridneus.simulate.recording import aps_frames, write_aedat4

    sp = capture["split"]
    times = np.linspace(0.0, 2.0, sp.n_views)
    frames = aps_frames(lambda i: np.full((48, 64, 3), 0.1 + 0.0005 * i), times, 20.0, 0.01,
                        t0=100.0, bits=16)
    write_aedat4(tmp_path / "deep.aedat4", capture["rec"], frames, (64, 48))
    back = read_frames(tmp_path / "deep.aedat4", (64, 48))
    assert len(back) == len(frames) and all(f.bits == 16 for f in back)
    for a, b in zip(frames, back, strict=True):
        assert b.t == pytest.approx(a.t, abs=1e-6)
        np.testing.assert_allclose(b.image, a.image, atol=1 / 65535)
    # the dark end: 8 bits cannot tell these frames apart, 16 bits can
    assert len({round(float(f.image.mean()) * 255) for f in back}) < len(back)
    assert len({float(f.image.mean()) for f in back}) == len(back)


def test_greyscale_hdf5_frames_on_a_microsecond_clock(tmp_path):
    import h5py

    from hybridneus.recordings.frames import frame_times, holds_frames, read_frames

    raw = np.arange(48 * 64, dtype=np.uint32).reshape(48, 64) % 251
    with h5py.File(tmp_path / "grey.h5", "w") as f:
        for i, stamp in enumerate([2_500_000, 1_000_000]):  # integer stamps, out of order
            d = f.create_dataset(f"images/image{i:09d}", data=(raw + i).astype(np.uint8))
            d.attrs["timestamp"] = np.int64(stamp)
            d.attrs["type"] = "greyscale"
        f.create_dataset("images/image000000002", data=raw.astype(np.uint8))
    with pytest.raises(RecordingError, match="grey.h5: images/image000000002 has no timestamp"):
        read_frames(tmp_path / "grey.h5", (64, 48))
    with h5py.File(tmp_path / "grey.h5", "a") as f:
        del f["images/image000000002"]
    frames = read_frames(tmp_path / "grey.h5", (64, 48))
    assert [f.t for f in frames] == pytest.approx([1.0, 2.5])
    assert frames[0].image.shape == (48, 64, 3) and frames[0].bits == 8
    # each pixel keeps its own value in every channel (a raw Bayer frame's pixel its colour's)
    np.testing.assert_allclose(frames[0].image[..., 1], (raw + 1) / 255.0, atol=1e-6)
    np.testing.assert_array_equal(frames[0].image[..., 0], frames[0].image[..., 2])
    assert read_frames(tmp_path / "grey.h5", (64, 48), "ms")[1].t == pytest.approx(2500.0)
    # the times of all, the pixels of those inside a span only
    np.testing.assert_allclose(frame_times(tmp_path / "grey.h5", (64, 48)), [1.0, 2.5])
    inside = read_frames(tmp_path / "grey.h5", (64, 48), span=(2.0, 3.0))
    assert [f.t for f in inside] == pytest.approx([2.5])
    assert holds_frames(tmp_path / "grey.h5") and not holds_frames(tmp_path / "none.h5")
