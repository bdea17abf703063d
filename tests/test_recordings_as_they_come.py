"""Recordings as real tools write them: motion-capture tracks with hidden frames, repeated
stamps and dropouts; ``rostopic echo -p`` exports; ROS 2 messages with CDR padding; DSEC's
``cam_to_cam.yaml``; AEDAT4 files with several event tracks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from hybridneus.errors import RecordingError
from hybridneus.recordings import (
    ConvertOptions,
    convert_recording,
    open_events,
    read_calibration,
    read_pose_table,
)
from tests.test_recordings import OFFSET, _typestore, _write, simulated_recording

HEADER = "timestamp,tx,ty,tz,qx,qy,qz,qw"


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> dict:
    return simulated_recording(tmp_path_factory.mktemp("recording"))


def _rows(recording: dict) -> list[list[float]]:
    """The recording's TUM track as rows of numbers."""
    return np.loadtxt(recording["root"] / "poses.txt").tolist()


def _csv(path: Path, rows: list[list], header: str = HEADER) -> Path:
    path.write_text(header + "\n" + "\n".join(
        ",".join("" if v is None else f"{v:.15g}" if isinstance(v, float) else str(v)
                 for v in r) for r in rows) + "\n")
    return path


def test_hidden_frames_and_repeated_stamps_are_dropped_and_counted(recording, tmp_path):
    rows = _rows(recording)
    messy = [list(r) for r in rows]
    messy[5][1:] = [None] * 7  # Motive leaves a hidden body's cells empty
    messy[9][4:] = [float("nan")] * 4
    messy[12][1:] = [0.0] * 7  # Vicon writes zeros
    messy.insert(20, list(rows[19]))  # one stamp logged twice
    messy.insert(32, [rows[30][0], *rows[40][1:]])  # ... the second time with other values
    track = read_pose_table(_csv(tmp_path / "mocap.csv", messy))
    assert (track.rows.occluded, track.rows.repeated) == (3, 2)
    keep = [i for i in range(len(rows)) if i not in (5, 9, 12)]
    clean = read_pose_table(_csv(tmp_path / "clean.csv", [rows[i] for i in keep]))
    np.testing.assert_array_equal(track.t, clean.t)
    np.testing.assert_allclose(track.matrices(), clean.matrices(), atol=1e-12)
    assert track.rows.dropouts == []  # one missing sample is no dropout
    assert any("3 occluded row(s)" in w for w in track.rows.warnings(track.source))


def test_a_track_with_nothing_left_names_what_was_dropped(tmp_path):
    path = _csv(tmp_path / "p.csv", [[0.0, *[None] * 7], [1.0, 0, 0, 0, 0, 0, 0, 1.0],
                                     [1.0, 0, 0, 0, 0, 0, 0, 1.0]])
    with pytest.raises(RecordingError, match=r"p.csv: 1 usable pose\(s\) of 3 rows \(1 "
                                             r"occluded, 1 repeated stamps\)"):
        read_pose_table(path)
    path.write_text(HEADER + "\n0,0,0,0,0,0,0,1\n1,0,0,0,world,0,0,1\n")
    with pytest.raises(RecordingError, match="line 3, column qx is not a number"):
        read_pose_table(path)


def _convert(recording: dict, poses: Path, out: Path, **kw):
    events = _write(recording, "npz")
    opts = dict(views=len(recording["view_t"]), start=recording["view_t"][0],
                end=recording["view_t"][-1], clock_offset=OFFSET, mosaic="mono") | kw
    return convert_recording(open_events(events), read_pose_table(poses),
                             read_calibration(recording["root"] / "calib.json"), out,
                             ConvertOptions(**opts), progress=False)


def test_views_in_a_dropout_are_refused_unless_max_gap_allows_them(recording, tmp_path, caplog):
    import logging

    caplog.set_level(logging.WARNING, logger="hybridneus")
    rows = _rows(recording)
    gap = [r for k, r in enumerate(rows) if not 22 <= k < 31]  # 9 samples: views 6 and 7 lost
    poses = _csv(tmp_path / "gap.csv", gap)
    span = rows[31][0] - rows[21][0]
    with pytest.raises(RecordingError, match=r"gap.csv: 2 view\(s\) fall where the track has "
                                             r"no pose for 0.050 s .*--max-gap 0.05,"):
        _convert(recording, poses, tmp_path / "refused")
    assert not (tmp_path / "refused").exists()
    with pytest.raises(RecordingError, match="fall where the track has no pose"):
        _convert(recording, poses, tmp_path / "short", max_gap=0.5 * span)
    doc = _convert(recording, poses, tmp_path / "out", max_gap=span)
    assert doc["poses"]["dropouts_s"] == [[pytest.approx(rows[21][0]),
                                           pytest.approx(rows[31][0])]]
    assert "no pose for 0.050 s" in caplog.text
    # the views there are interpolated across the gap: near the truth on this smooth track
    from hybridneus.data import load_dataset
    from hybridneus.recordings import read_scene_frame

    c2w = load_dataset(tmp_path / "out")["train"].c2w
    back = read_scene_frame(tmp_path / "out").to_recording(c2w[:, :3, 3])
    err = np.linalg.norm(back - recording["c2w"][:, :3, 3], axis=1)
    assert err[[0, 1, 2, 3, 4, 5, 8, 9]].max() < 1e-5 < err[6:8].min()


def test_the_cli_warns_of_a_messy_track_and_points_to_max_gap(recording, tmp_path, run_cli):
    rows = _rows(recording)
    messy = [r for k, r in enumerate(rows) if not 22 <= k < 31]
    messy[3][4:] = [0.0] * 4
    poses = _csv(tmp_path / "mocap.csv", messy)
    events = _write(recording, "npz")
    args = ["convert", str(events), str(tmp_path / "data"), "--poses", str(poses), "--calib",
            str(recording["root"] / "calib.json"), "--views", "16", "--start",
            str(recording["view_t"][0]), "--end", str(recording["view_t"][-1]),
            "--clock-offset", str(OFFSET), "-q"]
    code, _, err = run_cli(*args)
    assert code == 2 and "--max-gap 0.05," in err.splitlines()[-1]
    assert "mocap.csv: 1 occluded row(s)" in err
    code, text, err = run_cli(*args, "--max-gap", "0.05")
    assert code == 0, err
    assert "mocap.csv: no pose for 0.050 s" in err and "wrote" in text
    code, _, err = run_cli(*args, "--max-gap", "-1")
    assert code == 2 and "--max-gap: must be >= 0" in err


@pytest.mark.parametrize("message", ["PoseStamped", "Odometry", "TransformStamped"])
def test_a_rostopic_echo_export_reads_like_the_tum_track(recording, tmp_path, message):
    rows = np.asarray(_rows(recording))
    field = {"PoseStamped": ("pose.position", "pose.orientation"),
             "Odometry": ("pose.pose.position", "pose.pose.orientation"),
             "TransformStamped": ("transform.translation", "transform.rotation")}[message]
    names = (["%time", "field.header.seq", "field.header.stamp", "field.header.frame_id"]
             + ([] if message != "Odometry" else ["field.child_frame_id"])
             + [f"field.{field[0]}.{a}" for a in "xyz"]
             + [f"field.{field[1]}.{a}" for a in "xyzw"]
             + ([] if message != "Odometry" else [f"field.twist.twist.linear.{a}"
                                                  for a in "xyz"]))
    lines = [",".join(names)]
    for k, r in enumerate(rows):
        ns = int(round(r[0] * 1e9))
        cells = [ns + 3_000_000, k, ns, "mocap"] + (["base"] if message == "Odometry" else [])
        cells += [f"{v:.15g}" for v in r[1:]] + ([0, 0, 0] if message == "Odometry" else [])
        lines.append(",".join(str(c) for c in cells))
    (tmp_path / "poses.csv").write_text("\n".join(lines) + "\n")
    track = read_pose_table(tmp_path / "poses.csv")  # nanoseconds, from the header stamps
    truth = read_pose_table(recording["root"] / "poses.txt")
    np.testing.assert_allclose(track.t, truth.t, atol=1e-6)
    np.testing.assert_allclose(track.matrices(), truth.matrices(), atol=1e-9)


def test_ros2_event_messages_with_cdr_padding_are_read(recording, tmp_path):
    from rosbags.rosbag2 import Writer

    store = _typestore(True)
    Event, Array = store.types["dvs_msgs/msg/Event"], store.types["dvs_msgs/msg/EventArray"]
    Time, Header = store.types["builtin_interfaces/msg/Time"], store.types["std_msgs/msg/Header"]
    n, padded = 0, 0
    with Writer(tmp_path / "padded", version=9) as w:
        conn = w.add_connection("/events", "dvs_msgs/msg/EventArray", typestore=store)
        for k, s in enumerate(range(0, 40, 8)):
            sl = slice(s, s + 3 + k)  # message lengths 3..7 events: several paddings
            t = recording["t_us"][sl]
            events = [Event(x=int(x), y=int(y), ts=Time(sec=int(v // 10**6),
                                                         nanosec=int(v % 10**6) * 1000),
                            polarity=bool(p > 0))
                      for x, y, v, p in zip(recording["x"][sl], recording["y"][sl], t,
                                            recording["p"][sl], strict=True)]
            msg = Array(header=Header(stamp=Time(sec=1, nanosec=0), frame_id="dvs"),
                        height=recording["size"][1], width=recording["size"][0],
                        events=events)
            raw = bytes(store.serialize_cdr(msg, "dvs_msgs/msg/EventArray"))
            pad = -len(raw) % 4  # rclcpp ends a serialised message on a 4-byte boundary
            padded += pad > 0
            w.write(conn, int(t[0]) * 1000, raw + b"\0" * pad)
            n += len(events)
    assert padded >= 2
    chunks = list(open_events(tmp_path / "padded").chunks())
    assert sum(len(c) for c in chunks) == n
    with Writer(tmp_path / "long", version=9) as w:  # 4 bytes more is not padding
        conn = w.add_connection("/events", "dvs_msgs/msg/EventArray", typestore=store)
        w.write(conn, 1, raw + b"\0" * (pad + 4))
    with pytest.raises(RecordingError, match=r"does not decode as EventArray \(\d bytes left"):
        list(open_events(tmp_path / "long").chunks())


DSEC_CAM_TO_CAM = """\
disparity_to_depth:
  cams_03:
  - [1.0, 0.0, 0.0, -335.0]
  - [0.0, 1.0, 0.0, -221.0]
  - [0.0, 0.0, 0.0, 569.0]
  - [0.0, 0.0, 1.67, -0.0]
extrinsics:
  R_rect0:
  - [0.9999, -0.0058, 0.0114]
  - [0.0058, 0.9999, 0.0022]
  - [-0.0114, -0.0021, 0.9999]
  T_10:
  - [0.9999, -0.0027, 0.0098, -0.0474]
  - [0.0026, 0.9999, 0.0021, 0.0003]
  - [-0.0098, -0.0021, 0.9999, -0.0134]
  - [0.0, 0.0, 0.0, 1.0]
intrinsics:
  cam0:
    camera_matrix: [553.47, 553.27, 346.65, 216.28]
    camera_model: pinhole
    distortion_coeffs: [-0.0936, 0.1946, 7.37e-05, 0.00036]
    distortion_model: radtan
    resolution: [640, 480]
  cam1:
    camera_matrix: [1164.6, 1164.6, 713.6, 570.6]
    camera_model: pinhole
    distortion_coeffs: [-0.3937, 0.1825, 0.0, 0.0]
    distortion_model: radtan
    resolution: [1440, 1080]
  cam3:
    camera_matrix: [552.18, 551.94, 320.5, 230.1]
    camera_model: pinhole
    distortion_coeffs: [-0.0884, 0.1805, 0.0002, -0.0004]
    distortion_model: radtan
    resolution: [640, 480]
  camRect0:
    camera_matrix: [569.78, 569.78, 335.07, 221.07]
    resolution: [640, 480]
"""


def test_a_dsec_cam_to_cam_yaml_gives_its_event_cameras(tmp_path):
    path = tmp_path / "cam_to_cam.yaml"
    path.write_text(DSEC_CAM_TO_CAM)
    left = read_calibration(path)  # cam0: the left event camera
    assert (left.width, left.height, left.model) == (640, 480, "radtan")
    np.testing.assert_allclose(left.K, [[553.47, 0, 346.65], [0, 553.27, 216.28], [0, 0, 1]])
    np.testing.assert_allclose(left.coeffs, [-0.0936, 0.1946, 7.37e-05, 0.00036])
    assert left.source == f"{path}:cam0"
    right = read_calibration(path, "cam3")
    assert right.K[0, 2] == 320.5
    rect = read_calibration(path, "camRect0")
    assert rect.model == "pinhole" and rect.K[0, 0] == 569.78
    with pytest.raises(RecordingError, match=r"camera 'cam9' not in the camchain \(have cam0, "
                                             r"cam1, cam3, camRect0"):
        read_calibration(path, "cam9")


def _aedat4_two_tracks(path: Path, first: np.ndarray, second: np.ndarray,
                       size: tuple[int, int]) -> Path:
    """An AEDAT4 file as DV records a stereo pair: two event tracks, ids 0 and 1."""
    from faery import aedat

    A = aedat.DescriptionAttribute

    def track(i: int, name: str):
        info = aedat.DescriptionNode(
            name="info", path=f"/mainloop/Recorder/outInfo/{i}/info/",
            attributes={"sizeX": A("int", size[0]), "sizeY": A("int", size[1]),
                        "source": A("string", "DAVIS346")}, nodes=[])
        return aedat.DescriptionNode(
            name=str(i), path=f"/mainloop/Recorder/outInfo/{i}/",
            attributes={"compression": A("string", "LZ4"),
                        "originalOutputName": A("string", name),
                        "typeIdentifier": A("string", "EVTS")}, nodes=[info])

    description = [aedat.DescriptionNode(name="outInfo", path="/mainloop/Recorder/outInfo/",
                                         attributes={},
                                         nodes=[track(0, "events"), track(1, "events_right")])]
    with aedat.Encoder(path, description, aedat.LZ4_DEFAULT) as encoder:
        encoder.write(0, first)
        encoder.write(1, second)
    return path


def test_track_picks_one_event_track_of_an_aedat4_file(recording, tmp_path, run_cli):
    import faery

    n = len(recording["t_us"])
    arr = np.zeros(n, dtype=faery.EVENTS_DTYPE)
    arr["t"], arr["x"], arr["y"] = recording["t_us"], recording["x"], recording["y"]
    arr["on"] = recording["p"] > 0
    path = _aedat4_two_tracks(tmp_path / "stereo.aedat4", arr[: n // 3], arr,
                              recording["size"])
    assert sum(len(c) for c in open_events(path).chunks()) == n // 3
    right = open_events(path, track=1)
    assert sum(len(c) for c in right.chunks()) == n and "track 1" in right.note
    with pytest.raises(RecordingError, match=r"stereo.aedat4: .*track 5 not found .*\[0, 1\]"):
        open_events(path, track=5)
    root = recording["root"]
    args = ["convert", str(path), str(tmp_path / "data"), "--poses", str(root / "poses.txt"),
            "--calib", str(root / "calib.json"), "--views", "16", "--start",
            str(recording["view_t"][0]), "--end", str(recording["view_t"][-1]),
            "--clock-offset", str(OFFSET), "-q"]
    code, text, err = run_cli(*args, "--track", "1")
    assert code == 0, err
    doc = json.loads((tmp_path / "data" / "scene.json").read_text())
    assert doc["events"]["n_written"] == n
    code, _, err = run_cli("convert", str(_write(recording, "evt3")), str(tmp_path / "x"),
                           *args[3:], "--track", "1")
    assert code == 2 and "--track: applies to AEDAT4 files" in err


def test_hand_eye_files_named_either_way_give_the_camera_in_the_body_frame(tmp_path):
    import yaml
    from scipy.spatial.transform import Rotation

    from hybridneus.recordings import make_track, read_matrix

    body_cam = np.eye(4)  # the camera 5 cm ahead of the marker tree, turned about x and z
    body_cam[:3, :3] = Rotation.from_euler("xz", [90, 15], degrees=True).as_matrix()
    body_cam[:3, 3] = [0.01, -0.02, 0.05]
    cam_body = np.linalg.inv(body_cam)
    files = {"T.yaml": {"T": body_cam.tolist()},
             "T_cam_body.json": {"T_cam_body": cam_body.reshape(-1).tolist()},
             "camchain-imucam.yaml": {"cam0": {"T_cam_imu": cam_body.tolist(),
                                               "intrinsics": [200, 200, 170, 130]}}}
    for name, doc in files.items():
        (tmp_path / name).write_text(yaml.safe_dump(doc) if name.endswith("yaml")
                                     else json.dumps(doc))
    np.savetxt(tmp_path / "he.txt", body_cam)
    for given in [*(str(tmp_path / n) for n in files), str(tmp_path / "he.txt"),
                  ",".join(f"{v:.17g}" for v in body_cam.reshape(-1))]:
        np.testing.assert_allclose(read_matrix(given, "--hand-eye"), body_cam, atol=1e-12,
                                   err_msg=given)
    # the track then holds the camera: the body's pose times the hand-eye transform
    t = np.array([0.0, 1.0])
    body = Rotation.from_euler("y", [[0], [30]], degrees=True)
    pos = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    track = make_track(t, body.as_quat(), pos, "mocap", hand_eye=read_matrix(
        str(tmp_path / "T_cam_body.json"), "--hand-eye"))
    world_body = np.tile(np.eye(4), (2, 1, 1))
    world_body[:, :3, :3], world_body[:, :3, 3] = body.as_matrix(), pos
    np.testing.assert_allclose(track.matrices(), world_body @ body_cam, atol=1e-12)
    (tmp_path / "bad.yaml").write_text("R: [1, 0, 0]\n")
    with pytest.raises(RecordingError, match="bad.yaml: no transform entry"):
        read_matrix(str(tmp_path / "bad.yaml"), "--hand-eye")


@pytest.mark.parametrize("bad, message", [
    (np.nan, "non-finite quaternion"), (0.0, "zero quaternion")])
def test_make_track_itself_still_refuses_a_bad_sample(bad, message):
    from hybridneus.recordings import make_track

    q = np.array([[0, 0, 0, 1.0], [0, 0, 0, 1.0]])
    q[1] = [bad] * 4 if bad == 0 else [0, 0, bad, 1.0]
    with pytest.raises(RecordingError, match=message):
        make_track(np.array([0.0, 1.0]), q, np.zeros((2, 3)), "samples")


def test_hot_pixels_stand_out_from_edges_thin_lines_and_quiet_corners():
    from hybridneus.data.hot import find_hot_pixels

    rng = np.random.default_rng(0)
    yy, xx = np.mgrid[0:60, 0:80]
    counts = rng.poisson(40 + 30 * np.sin(xx / 9.0) ** 2).astype(np.int64)
    counts[:, 30] += 400  # a thin bright line that the camera kept crossing
    counts[40, 1::2] += 400  # one seen behind a Bayer mosaic: every other pixel fires
    counts[:10, 60:] = rng.poisson(2, (10, 20))  # a corner where little happens
    hot = [(5, 7), (70, 3), (44, 50), (1, 20)]  # (1, 20): its mirror image would be itself
    for x, y in hot:
        counts[y, x] = 3000
    found = find_hot_pixels(counts)
    assert sorted(found.pixels()) == sorted(hot)
    assert found.events == 12000 and "hot pixels: 4" in found.line()
    assert find_hot_pixels(np.zeros((6, 8), np.int64)).n == 0


def test_convert_leaves_a_hot_pixel_out_and_says_so(recording, tmp_path, run_cli):
    rec = dict(recording)
    span = rec["t_us"][[0, -1]]
    n_hot = 600
    t_hot = np.linspace(span[0], span[1], n_hot).astype(np.int64)
    order = np.argsort(np.concatenate([rec["t_us"], t_hot]), kind="stable")
    w, h = rec["size"]
    for key, extra in (("t_us", t_hot), ("x", np.full(n_hot, w - 3)),
                       ("y", np.full(n_hot, 2)), ("p", np.ones(n_hot, rec["p"].dtype))):
        rec[key] = np.concatenate([rec[key], extra.astype(rec[key].dtype)])[order]
    events = tmp_path / "hot.npz"
    np.savez(events, x=rec["x"], y=rec["y"], t=rec["t_us"], p=rec["p"])
    root = recording["root"]
    args = ["convert", str(events), "--poses", str(root / "poses.txt"), "--calib",
            str(root / "calib.json"), "--views", "16", "--start", str(rec["view_t"][0]),
            "--end", str(rec["view_t"][-1]), "--clock-offset", str(OFFSET), "-q"]
    code, text, err = run_cli(args[0], args[1], str(tmp_path / "out"), *args[2:])
    assert code == 0, err
    assert f"hot pixels: 1 fire far more than their neighbours (({w - 3}, 2)" in err
    assert "600 of 1 hot pixels left out" in text
    from hybridneus.data import load_dataset

    ev = load_dataset(tmp_path / "out")["train"].events
    assert len(ev) == len(recording["x"]) and not np.any((ev.x == w - 3) & (ev.y == 2))
    doc = json.loads((tmp_path / "out" / "scene.json").read_text())
    assert doc["events"]["hot_pixels"] == {"n": 1, "events": 600, "pixels": [[w - 3, 2]]}
    code, text, err = run_cli(args[0], args[1], str(tmp_path / "kept"), *args[2:],
                              "--keep-hot-pixels")
    assert code == 0, err
    assert len(load_dataset(tmp_path / "kept")["train"].events) == len(recording["x"]) + 600
    code, text, _ = run_cli("info", str(tmp_path / "kept"))
    assert code == 0 and f"hot pixels: 1 fire far more than their neighbours (({w - 3}, 2)" \
        in text and "a fit and convert leave such pixels out" in text
