"""``hybridneus convert``: real writers in, the same views, poses and events out."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

from hybridneus.data import load_dataset
from hybridneus.errors import RecordingError
from hybridneus.recordings import (
    ConvertOptions,
    convert_recording,
    make_track,
    open_events,
    read_calibration,
    read_pose_table,
    read_scene_frame,
    read_turntable,
)

T0 = 2.5  # event-clock seconds of view 0 (EVT3 counts 24 bits of microseconds: start low)
DT = 0.02  # seconds between views
OFFSET = 0.25  # pose clock = event clock + OFFSET
SCALE = 0.37  # metres per normalised unit of the simulated scene
ROT = Rotation.from_euler("xyz", [20, -35, 70], degrees=True).as_matrix()
SHIFT = np.array([1.5, -0.3, 2.0])


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> dict:
    """See :func:`simulated_recording`."""
    return simulated_recording(tmp_path_factory.mktemp("recording"))


def simulated_recording(root: Path) -> dict:
    """A simulated scene re-expressed as a recording in ``root``: events in microseconds from
    T0, a 200 Hz TUM track in a metric frame (rotated, scaled, shifted, clock offset), and an
    OpenCV-convention calibration."""
    from hybridneus.simulate import EventModel, SimulationConfig, simulate_dataset

    cfg = SimulationConfig(n_views=16, width=32, height=24, val_views=0, test_views=0,
                           revolutions=1.0, supersample=1, spiral="even",
                           events=EventModel(mosaic="mono"))
    simulate_dataset("builtin:device", root / "sim", cfg, progress=False)
    sp = load_dataset(root / "sim", splits="train")["train"]
    n = sp.n_views
    c2w = sp.c2w.copy()
    c2w[:, :3, :3] = ROT @ sp.c2w[:, :3, :3]
    c2w[:, :3, 3] = SCALE * sp.c2w[:, :3, 3] @ ROT.T + SHIFT
    view_t = T0 + np.arange(n) * DT
    # Four pose samples per view interval, one exactly at each view.
    tp = T0 + OFFSET + np.arange((n - 1) * 4 + 1) * (DT / 4)
    rot = Slerp(view_t + OFFSET, Rotation.from_matrix(c2w[:, :3, :3]))(tp)
    pos = np.stack([np.interp(tp, view_t + OFFSET, c2w[:, k, 3]) for k in range(3)], 1)
    np.savetxt(root / "poses.txt", np.column_stack([tp, pos, rot.as_quat()]), fmt="%.15g",
               header="timestamp tx ty tz qx qy qz qw")
    K = sp.intrinsics[0]
    (root / "calib.json").write_text(json.dumps({
        "fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2] - 0.5, "cy": K[1, 2] - 0.5,
        "width": sp.width, "height": sp.height}))
    ev = sp.events
    t_us = np.round((T0 + ev.t * DT) * 1e6).astype(np.int64)
    return {"root": root, "c2w": c2w, "view_t": view_t, "t_us": t_us, "x": ev.x.copy(),
            "y": ev.y.copy(), "p": ev.p.copy(), "size": (sp.width, sp.height)}


def _write(rec: dict, fmt: str) -> Path:
    """The recording's events in one format, written by that format's own library."""
    root, t_us = rec["root"], rec["t_us"]
    on = rec["p"] > 0
    if fmt in ("aedat4", "evt2", "evt3", "dat"):
        import faery

        arr = np.zeros(t_us.shape[0], dtype=faery.EVENTS_DTYPE)
        arr["t"], arr["x"], arr["y"], arr["on"] = t_us, rec["x"], rec["y"], on
        suffix = {"evt2": "raw", "evt3": "raw"}.get(fmt, fmt)
        path = root / f"events-{fmt}.{suffix}"
        stream = faery.events_stream_from_array(arr, dimensions=rec["size"])
        version = fmt if fmt.startswith("evt") else None
        stream.to_file(path, version=version, zero_t0=False)
    elif fmt == "h5":
        import h5py
        import hdf5plugin

        path = root / "events.h5"
        base = int(t_us[0]) - 1000  # DSEC keeps t small and the epoch in t_offset
        with h5py.File(path, "w") as f:
            g = f.create_group("events")
            g.create_dataset("t", data=t_us - base, **hdf5plugin.Blosc())
            g.create_dataset("x", data=rec["x"].astype(np.uint16), **hdf5plugin.Zstd())
            g.create_dataset("y", data=rec["y"].astype(np.uint16))
            g.create_dataset("p", data=on.astype(np.uint8))
            f.create_dataset("t_offset", data=np.int64(base))
    elif fmt in ("bag1", "bag2"):
        path = _write_bag(rec, root / ("events.bag" if fmt == "bag1" else "events-ros2"),
                          ros2=fmt == "bag2")
    elif fmt == "txt":
        path = root / "events.txt"
        np.savetxt(path, np.column_stack([t_us / 1e6, rec["x"], rec["y"], on.astype(int)]),
                   fmt=["%.6f", "%d", "%d", "%d"])
    else:
        path = root / "events.npz"
        np.savez(path, x=rec["x"], y=rec["y"], t=t_us, p=rec["p"])
    return path


EVENT_MSG = "uint16 x\nuint16 y\ntime ts\nbool polarity\n"
EVENT_ARRAY_MSG = ("std_msgs/Header header\nuint32 height\nuint32 width\n"
                   "dvs_msgs/Event[] events\n")


def _typestore(ros2: bool):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE if ros2 else Stores.ROS1_NOETIC)
    store.register({**get_types_from_msg(EVENT_MSG, "dvs_msgs/msg/Event"),
                    **get_types_from_msg(EVENT_ARRAY_MSG, "dvs_msgs/msg/EventArray")})
    return store


def _write_bag(rec: dict, path: Path, ros2: bool, per_message: int = 997,
               topics: tuple[str, ...] = ("/dvs/events",)) -> Path:
    """The events as dvs_msgs/EventArray messages, serialised and written by rosbags."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2

    store = _typestore(ros2)
    Event, Array = store.types["dvs_msgs/msg/Event"], store.types["dvs_msgs/msg/EventArray"]
    Time, Header = store.types["builtin_interfaces/msg/Time"], store.types["std_msgs/msg/Header"]
    w, h = rec["size"]
    writer = Writer2(path, version=9) if ros2 else Writer1(path)
    with writer:
        conns = [writer.add_connection(t, "dvs_msgs/msg/EventArray", typestore=store)
                 for t in topics]
        writer.add_connection("/imu", "std_msgs/msg/String", typestore=store)
        t_us = rec["t_us"]
        for k, s in enumerate(range(0, len(t_us), per_message)):
            sl = slice(s, s + per_message)
            events = [Event(x=int(x), y=int(y), ts=Time(sec=int(t // 10**6),
                                                         nanosec=int(t % 10**6) * 1000),
                            polarity=bool(p > 0))
                      for x, y, t, p in zip(rec["x"][sl], rec["y"][sl], t_us[sl], rec["p"][sl],
                                            strict=True)]
            stamp = Time(sec=int(t_us[s] // 10**6), nanosec=0)
            header = Header(stamp=stamp, frame_id="dvs" * (k % 3)) if ros2 else \
                Header(seq=k, stamp=stamp, frame_id="dvs" * (k % 3))
            msg = Array(header=header, height=h, width=w, events=events)
            raw = store.serialize_cdr(msg, "dvs_msgs/msg/EventArray") if ros2 else \
                store.serialize_ros1(msg, "dvs_msgs/msg/EventArray")
            for conn in conns:
                writer.write(conn, int(t_us[s]) * 1000, raw)
    return path


def _convert(rec: dict, events: Path, out: Path, **kw) -> dict:
    root = rec["root"]
    opts = dict(views=len(rec["view_t"]), start=rec["view_t"][0], end=rec["view_t"][-1],
                clock_offset=OFFSET, mosaic="mono") | kw
    return convert_recording(open_events(events), read_pose_table(root / "poses.txt"),
                             read_calibration(root / "calib.json"), out, ConvertOptions(**opts),
                             progress=False)


@pytest.mark.parametrize("fmt", ["aedat4", "evt2", "evt3", "dat", "h5", "bag1", "bag2", "txt",
                                 "npz"])
def test_a_recording_converts_back_to_the_same_views_poses_and_events(recording, fmt,
                                                                        tmp_path):
    events = _write(recording, fmt)
    _convert(recording, events, tmp_path / "out")
    ds = load_dataset(tmp_path / "out")
    sp = ds["train"]
    frame = read_scene_frame(tmp_path / "out")
    assert sp.n_views == len(recording["view_t"])
    back_R = frame.rotation.T @ sp.c2w[:, :3, :3]
    back_t = frame.to_recording(sp.c2w[:, :3, 3])
    np.testing.assert_allclose(back_R, recording["c2w"][:, :3, :3], atol=1e-6)
    np.testing.assert_allclose(back_t, recording["c2w"][:, :3, 3], atol=1e-6)
    ev = sp.events
    assert len(ev) == len(recording["x"])
    assert (ev.x == recording["x"]).all() and (ev.y == recording["y"]).all()
    assert (ev.p == recording["p"]).all()
    expected_t = np.interp(recording["t_us"] * 1e-6, recording["view_t"],
                           np.arange(sp.n_views))
    np.testing.assert_allclose(ev.t, expected_t, atol=1e-6)
    assert sp.t_max == sp.n_views - 1  # the last view sits at the end of the span
    assert ds.preset.mosaic == "mono" and ds.preset.width == recording["size"][0]
    # the layout's intrinsics put pixel centres at +0.5: OpenCV's cx moves by half a pixel
    calib = json.loads((recording["root"] / "calib.json").read_text())
    assert sp.intrinsics[0, 0, 2] == pytest.approx(calib["cx"] + 0.5)


def test_events_outside_the_pose_track_are_dropped_and_counted(recording, tmp_path):
    events = _write(recording, "npz")
    span = recording["view_t"]
    doc = _convert(recording, events, tmp_path / "out", start=None, end=None,
                   clock_offset=OFFSET + 0.5 * (span[-1] - span[0]))
    ev = doc["events"]
    assert 0 < ev["n_outside_pose_track"] < ev["n_read"]
    assert ev["n_written"] == ev["n_read"] - ev["n_outside_pose_track"]
    assert len(load_dataset(tmp_path / "out")["train"].events) == ev["n_written"]


def test_path_spacing_puts_views_at_equal_steps_along_the_track(recording, tmp_path):
    events = _write(recording, "npz")
    spread = {}
    for spacing in ("time", "path"):
        _convert(recording, events, tmp_path / spacing, views=41, spacing=spacing)
        c = load_dataset(tmp_path / spacing)["train"].c2w[:, :3, 3]
        steps = np.linalg.norm(np.diff(c, axis=0), axis=1)  # chords: short ones, near arcs
        spread[spacing] = steps.std() / steps.mean()
    assert spread["path"] < 0.05 < spread["time"]


def test_a_track_that_misses_the_events_fails_and_leaves_nothing(recording, tmp_path, run_cli):
    root = recording["root"]
    events = _write(recording, "npz")
    code, _, err = run_cli("convert", str(events), str(tmp_path / "out"), "--poses",
                           str(root / "poses.txt"), "--calib", str(root / "calib.json"),
                           "--clock-offset", "100", "-q")
    assert code == 2 and "does not cover the events" in err and err.count("\n") == 1
    assert not (tmp_path / "out").exists()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]


def test_the_cli_converts_checks_and_meshes_in_the_recording_frame(recording, tmp_path,
                                                                    run_cli):
    from tests.conftest import TINY_FIT

    root = recording["root"]
    events = _write(recording, "h5")
    out = tmp_path / "data"
    centre = ",".join(str(v) for v in SHIFT)
    code, text, err = run_cli(
        "convert", str(events), str(out), "--poses", str(root / "poses.txt"), "--calib",
        str(root / "calib.json"), "--views", "16", "--start", str(recording["view_t"][0]),
        "--end", str(recording["view_t"][-1]), "--clock-offset", str(OFFSET), "--check",
        "--point", centre, "-q")
    assert code == 0, err
    assert (out / "check" / "track.png").is_file()
    code, text, _ = run_cli("info", str(out))
    assert code == 0 and "frame: a converted recording" in text
    assert len(list((out / "check").glob("events_*.png"))) == 4
    args = [f"--set={s}" for s in TINY_FIT]
    code, _, err = run_cli("fit", str(out), "--out", str(tmp_path / "runs"), *args)
    assert code == 0, err
    run = sorted(p for p in (tmp_path / "runs").iterdir() if p.is_dir())[-1]
    for frame in ("normalised", "recording"):
        code, _, err = run_cli("mesh", str(run), "--res", "24", "--no-preview", "--frame",
                               frame, "--out", str(tmp_path / f"{frame}.ply"),
                               "--min-component", "0", "--keep-unseen")
        assert code == 0, err
    import trimesh

    norm = trimesh.load(tmp_path / "normalised.ply", process=False)
    rec = trimesh.load(tmp_path / "recording.ply", process=False)
    frame = read_scene_frame(out)
    np.testing.assert_allclose(frame.to_recording(np.asarray(norm.vertices)),
                               np.asarray(rec.vertices), atol=1e-4)


def test_point_projection_marks_the_principal_point_on_the_optical_axis():
    from hybridneus.recordings.check import project

    K = np.array([[100.0, 0, 16.5], [0, 100.0, 12.5], [0, 0, 1]])
    c2w = np.eye(4)
    c2w[:3, 3] = [0.2, -0.1, -1.0]
    uv, front = project(np.array([[0.2, -0.1, 1.0], [0.2, -0.1, -3.0]]), K, c2w)
    assert front.tolist() == [True, False]
    np.testing.assert_allclose(uv[0], [16.0, 12.0])


def _track_samples():
    t = np.linspace(0.0, 1.0, 11)
    rot = Rotation.from_euler("zyx", np.stack([40 * t, 10 - 30 * t, 5 * t], 1), degrees=True)
    pos = np.stack([np.cos(t), np.sin(t), 0.3 * t], 1)
    return t, rot, pos


def test_world_to_camera_opengl_and_hand_eye_samples_give_the_same_camera():
    t, rot, pos = _track_samples()
    truth = make_track(t, rot.as_quat(), pos, "truth")
    # world-to-camera (COLMAP's convention)
    inv = rot.inv()
    w2c = make_track(t, inv.as_quat(), -inv.apply(pos), "w2c", world_to_camera=True)
    np.testing.assert_allclose(w2c.matrices(), truth.matrices(), atol=1e-12)
    # OpenGL axes: the same camera with y and z flipped
    gl = rot * Rotation.from_matrix(np.diag([1.0, -1.0, -1.0]))
    opengl = make_track(t, gl.as_quat(), pos, "gl", opengl=True)
    np.testing.assert_allclose(opengl.matrices(), truth.matrices(), atol=1e-12)
    # a marker tracked instead of the camera, with the camera's pose in the marker frame
    he = np.eye(4)
    he[:3, :3] = Rotation.from_rotvec([0.1, -0.2, 0.3]).as_matrix()
    he[:3, 3] = [0.05, 0.02, -0.1]
    body = truth.matrices() @ np.linalg.inv(he)
    marker = make_track(t, Rotation.from_matrix(body[:, :3, :3]).as_quat(), body[:, :3, 3],
                        "marker", hand_eye=he)
    np.testing.assert_allclose(marker.matrices(), truth.matrices(), atol=1e-12)


def test_a_csv_with_named_columns_reads_like_a_tum_file(tmp_path):
    t, rot, pos = _track_samples()
    q = rot.as_quat()
    np.savetxt(tmp_path / "a.txt", np.column_stack([t, pos, q]), fmt="%.12f")
    cols = np.column_stack([q[:, 3], pos[:, 2], t * 1e3, q[:, :3], pos[:, :2]])
    np.savetxt(tmp_path / "b.csv", cols, delimiter=",", fmt="%.12f",
               header="qw,z,time,qx,qy,qz,x,y", comments="")
    a = read_pose_table(tmp_path / "a.txt")
    b = read_pose_table(tmp_path / "b.csv", time_scale=1e-3)
    np.testing.assert_allclose(b.t, a.t, atol=1e-12)
    np.testing.assert_allclose(b.matrices(), a.matrices(), atol=1e-9)


@pytest.mark.parametrize("rows, message", [
    ([[0, 0, 0, 0, 0, 0, 0, 1], [1, 0, 0, 0, np.nan, 0, 0, 1]],
     r"1 usable pose\(s\) of 2 rows \(1 occluded"),
    ([[0, 0, 0, 0, 0, 0, 0, 1], [1, 0, 0, 0, 0, 0, 0, 0]], r"\(1 occluded, 0 repeated"),
    ([[0, 0, 0, 0, 0, 0, 0, 1], [0, 0, 0, 0, 0, 0, 0, 1]], r"\(0 occluded, 1 repeated"),
    ([[1, 0, 0, 0, 0, 0, 0, 1], [0, 0, 0, 0, 0, 0, 0, 1]], "do not increase"),
    ([[0, 0, 0, 0, 0, 0, 0, 2], [1, 0, 0, 0, 0, 0, 0, 2]], "not a unit quaternion"),
    ([[0, 0, 0, 0, 0, 0, 1]], "TUM trajectory has 8"),
])
def test_bad_pose_files_fail_with_the_file_and_the_fault(tmp_path, rows, message):
    path = tmp_path / "poses.txt"
    np.savetxt(path, np.asarray(rows, dtype=float))
    with pytest.raises(RecordingError, match=message) as info:
        read_pose_table(path)
    assert str(info.value).startswith(str(path))


def test_turntable_cameras_circle_the_axis_at_the_stated_speed(tmp_path):
    cam = np.eye(4)
    cam[:3, 3] = [0.0, 0.1, -0.5]  # 0.5 m in front of the axis, looking along +z at it
    (tmp_path / "t.json").write_text(json.dumps({
        "axis": [0, -1, 0], "center": [0, 0, 0], "speed_deg_s": 36.0, "start_deg": 0,
        "camera": cam.tolist()}))
    table = read_turntable(tmp_path / "t.json")
    poses = table.at(np.array([0.0, 2.5, 10.0]))
    np.testing.assert_allclose(poses[0], cam, atol=1e-12)
    # a quarter turn after 2.5 s, the whole turn after 10 s, always 0.5 m from the axis
    np.testing.assert_allclose(poses[2], cam, atol=1e-9)
    np.testing.assert_allclose(np.hypot(poses[:, 0, 3], poses[:, 2, 3]), 0.5)
    # the table turns right-handed about -y, so the camera about +y: from -z towards -x
    np.testing.assert_allclose(poses[1, :3, 3], [-0.5, 0.1, 0.0], atol=1e-9)
    # the camera keeps looking at the axis
    to_axis = -poses[:, [0, 2], 3]
    look = poses[:, [0, 2], 2]
    cross = look[:, 0] * to_axis[:, 1] - look[:, 1] * to_axis[:, 0]
    np.testing.assert_allclose(cross, 0.0, atol=1e-9)


def test_calibration_forms_agree(tmp_path):
    import cv2
    import yaml

    K = np.array([[200.0, 0, 170.2], [0, 201.0, 128.9], [0, 0, 1]])
    D = np.array([-0.1, 0.02, 0.001, -0.002])
    yaml.safe_dump({"cam0": {"camera_model": "pinhole", "intrinsics": [200.0, 201.0, 170.2, 128.9],
                             "distortion_model": "radtan", "distortion_coeffs": D.tolist(),
                             "resolution": [346, 260]}}, (tmp_path / "kalibr.yaml").open("w"))
    fs = cv2.FileStorage(str(tmp_path / "opencv.yaml"), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 346)
    fs.write("image_height", 260)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", D.reshape(1, -1))
    fs.release()
    (tmp_path / "plain.json").write_text(json.dumps({
        "fx": 200.0, "fy": 201.0, "cx": 170.2, "cy": 128.9, "width": 346, "height": 260,
        "k1": -0.1, "k2": 0.02, "p1": 0.001, "p2": -0.002}))
    (tmp_path / "K.json").write_text(json.dumps({
        "K": K.tolist(), "D": D.tolist(), "image_size": [346, 260]}))
    for name in ("kalibr.yaml", "opencv.yaml", "plain.json", "K.json"):
        c = read_calibration(tmp_path / name)
        assert (c.width, c.height, c.model) == (346, 260, "radtan"), name
        np.testing.assert_allclose(c.K, K, err_msg=name)
        np.testing.assert_allclose(c.coeffs[:4], D, err_msg=name)


@pytest.mark.parametrize("doc, message", [
    ({"fx": 200, "fy": 200, "cx": 170, "cy": 130}, "no image size"),
    ({"fx": 200, "fy": 200, "cx": -5000, "cy": 130, "width": 346, "height": 260},
     "outside the 346x260 image"),
    ({"fx": 200, "fy": 200, "cx": 170, "cy": 130, "width": 346, "height": 260, "skew": 5000},
     "skew"),
    ({"fx": 200, "fy": 200, "cx": 170, "cy": 130, "width": 346.5, "height": 260},
     "positive integer"),
    ({"fx": 200, "fy": 200, "cx": 170, "cy": 130, "width": 346, "height": 260,
      "model": "division", "coeffs": [0.1]}, "not supported"),
])
def test_bad_calibrations_fail_with_the_file_and_the_fault(tmp_path, doc, message):
    path = tmp_path / "calib.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(RecordingError, match=message) as info:
        read_calibration(path)
    assert str(info.value).startswith(str(path))


def test_a_calibration_for_another_sensor_size_is_refused(recording, tmp_path):
    path = tmp_path / "calib.json"
    path.write_text(json.dumps({"fx": 30, "fy": 30, "cx": 20, "cy": 15, "width": 40,
                                "height": 30}))
    events = _write(recording, "dat")  # its header states the sensor's size
    with pytest.raises(RecordingError, match="calibration is for a 40x30 image"):
        convert_recording(open_events(events), read_pose_table(recording["root"] / "poses.txt"),
                          read_calibration(path), tmp_path / "out", ConvertOptions(),
                          progress=False)
    assert not (tmp_path / "out").exists()


def test_event_readers_refuse_what_they_cannot_read(tmp_path, monkeypatch):
    import h5py

    with h5py.File(tmp_path / "prophesee.hdf5", "w") as f:
        f.create_group("CD").create_dataset("events", data=np.zeros(3))
    with pytest.raises(RecordingError, match="Prophesee HDF5"):
        open_events(tmp_path / "prophesee.hdf5")
    (tmp_path / "e.xyz").write_text("1 2 3 4\n")
    with pytest.raises(RecordingError, match="unknown event file type"):
        open_events(tmp_path / "e.xyz")
    (tmp_path / "e.txt").write_text("0.1 2 3 1\n0.2 2 3\n")
    with pytest.raises(RecordingError, match="do not all have 4 columns"):
        list(open_events(tmp_path / "e.txt").chunks())
    (tmp_path / "p.txt").write_text("0.1 2 3 1\n0.2 2 3 7\n")
    with pytest.raises(RecordingError, match="polarity"):
        list(open_events(tmp_path / "p.txt").chunks())
    import faery

    arr = np.zeros(10, dtype=faery.EVENTS_DTYPE)
    arr["t"] = np.arange(10)
    faery.events_stream_from_array(arr, dimensions=(8, 6)).to_file(
        tmp_path / "v3.raw", version="evt3", zero_t0=False)
    raw = (tmp_path / "v3.raw").read_bytes()
    (tmp_path / "v4.raw").write_bytes(raw.replace(b"evt 3.0", b"evt 4.0")
                                      .replace(b"EVT3", b"EVT4"))
    with pytest.raises(RecordingError, match=r"v4.raw: cannot read as raw .*EVT4"):
        open_events(tmp_path / "v4.raw")
    import sys

    monkeypatch.setitem(sys.modules, "faery", None)  # as if not installed
    (tmp_path / "e.aedat4").write_bytes(b"x")
    with pytest.raises(RecordingError,
                       match=r'pip install -e "\.\[faery\]" in the hybridneus folder$'):
        open_events(tmp_path / "e.aedat4")


def test_text_columns_and_units_are_read_as_told(tmp_path):
    (tmp_path / "e.csv").write_text("x,y,t,p\n3,4,1500,-1\n5,6,2500,1\n")
    src = open_events(tmp_path / "e.csv", columns="xytp", time_unit="ms")
    (chunk,) = list(src.chunks())
    np.testing.assert_allclose(chunk.t, [1.5, 2.5])
    assert chunk.x.tolist() == [3, 5] and chunk.on.tolist() == [False, True]


def test_bags_name_their_topics_when_the_event_topic_is_missing_or_ambiguous(recording,
                                                                             tmp_path):
    rec = {**recording, **{k: recording[k][:50] for k in ("t_us", "x", "y", "p")}}
    two = _write_bag(rec, tmp_path / "two.bag", ros2=False, topics=("/left", "/right"))
    with pytest.raises(RecordingError, match="several event topics.*--topic"):
        open_events(two)
    src = open_events(two, topic="/right")
    assert sum(len(c) for c in src.chunks()) == 50 and src.size == recording["size"]
    with pytest.raises(RecordingError, match="topic /imu holds std_msgs/msg/String"):
        open_events(two, topic="/imu")
    with pytest.raises(RecordingError, match="no topic /nope"):
        open_events(two, topic="/nope")
    from rosbags.rosbag2 import Writer

    store = _typestore(True)
    with Writer(tmp_path / "imu-only", version=9) as w:
        conn = w.add_connection("/imu", "std_msgs/msg/String", typestore=store)
        w.write(conn, 1, store.serialize_cdr(store.types["std_msgs/msg/String"](data="x"),
                                             "std_msgs/msg/String"))
    with pytest.raises(RecordingError, match=r"no event topic \(dvs_msgs/EventArray\).*/imu"):
        open_events(tmp_path / "imu-only")
    (tmp_path / "broken.bag").write_bytes(b"#ROSBAG V2.0\n" + b"\0" * 40)
    with pytest.raises(RecordingError, match="broken.bag: cannot read as a ROS bag"):
        open_events(tmp_path / "broken.bag")


def test_a_colmap_model_gives_the_same_poses_as_the_tum_track(recording, tmp_path):
    """COLMAP (world-to-camera, times from the image names) converts to the same views."""
    import pycolmap

    from hybridneus.recordings import read_colmap_track

    model = pycolmap.Reconstruction()
    w, h = recording["size"]
    model.add_camera_with_trivial_rig(pycolmap.Camera(
        model="PINHOLE", width=w, height=h, params=[30.0, 30.0, w / 2, h / 2], camera_id=1))
    names = []
    for i, c2w in enumerate(recording["c2w"]):
        w2c = np.linalg.inv(c2w)
        q = Rotation.from_matrix(w2c[:3, :3]).as_quat()  # x y z w, pycolmap's order
        names.append(f"frame{i:03d}.png")
        image = pycolmap.Image(name=names[-1], camera_id=1, image_id=i + 1)
        model.add_image_with_trivial_frame(
            image, pycolmap.Rigid3d(pycolmap.Rotation3d(q), w2c[:3, 3]))
    for form in ("bin", "txt"):
        (tmp_path / form).mkdir()
        getattr(model, "write_binary" if form == "bin" else "write_text")(str(tmp_path / form))
    times = tmp_path / "times.txt"
    rows = [f"{n} {int(round(t * 1e6))}" for n, t in zip(names, recording["view_t"] + OFFSET,
                                                         strict=True)]
    times.write_text("name t_us\n" + "\n".join(rows[::-1]) + "\n")
    events = _write(recording, "npz")
    for form in ("bin", "txt"):
        track = read_colmap_track(tmp_path / form, times, 1e-6)
        assert len(track) == len(names)
        root = recording["root"]
        out = tmp_path / f"out-{form}"
        convert_recording(open_events(events), track, read_calibration(root / "calib.json"),
                          out, ConvertOptions(views=len(names), start=recording["view_t"][0],
                                              end=recording["view_t"][-1],
                                              clock_offset=OFFSET, mosaic="mono"),
                          progress=False)
        sp = load_dataset(out)["train"]
        frame = read_scene_frame(out)
        np.testing.assert_allclose(frame.rotation.T @ sp.c2w[:, :3, :3],
                                   recording["c2w"][:, :3, :3], atol=1e-6)
        np.testing.assert_allclose(frame.to_recording(sp.c2w[:, :3, 3]),
                                   recording["c2w"][:, :3, 3], atol=1e-6)
    with pytest.raises(RecordingError, match="has no time in its name; give --frame-times"):
        read_colmap_track(tmp_path / "bin")
    times.write_text("\n".join(rows[1:]) + "\n")
    with pytest.raises(RecordingError, match="no time for 1 of the model's images"):
        read_colmap_track(tmp_path / "bin", times)


def test_a_conversion_keeps_out_of_folders_it_did_not_write(recording, tmp_path, run_cli):
    root = recording["root"]
    events = _write(recording, "npz")
    args = [str(events), str(tmp_path / "out"), "--poses", str(root / "poses.txt"), "--calib",
            str(root / "calib.json"), "--clock-offset", str(OFFSET), "-q"]
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "notes.txt").write_text("mine")
    code, _, err = run_cli("convert", *args)
    assert code == 2 and "out: holds files a conversion did not write (notes.txt)" in err
    assert (tmp_path / "out" / "notes.txt").read_text() == "mine"
    (tmp_path / "out" / "notes.txt").unlink()
    assert run_cli("convert", *args)[0] == 0  # an empty folder, then its own output
    assert run_cli("convert", *args)[0] == 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["scene.json", "train"]


def test_empty_files_and_misshapen_turntables_are_named(tmp_path):
    for name in ("e.raw", "e.aedat4", "e.h5", "e.txt", "e.bag"):
        (tmp_path / name).write_bytes(b"")
        with pytest.raises(RecordingError, match=f"{name}: empty file"):
            open_events(tmp_path / name)
    (tmp_path / "t.json").write_text(json.dumps({"axis": [0, 1, 0], "speed_deg_s": 6,
                                                 "camera": [[1, 0], [0, 1]]}))
    with pytest.raises(RecordingError, match=r"t.json: turntable camera must be a 4x4 matrix"):
        read_turntable(tmp_path / "t.json")
