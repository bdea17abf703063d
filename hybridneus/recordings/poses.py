"""Camera pose tracks: reading them, fixing their conventions, and sampling them in time.

A :class:`PoseTrack` holds timestamped camera-to-world poses in OpenCV camera axes (x right,
y down, z forward) in the recording's own metric frame. Readers bring every source to that
form: a TUM trajectory or a CSV with named columns (a body or marker pose, optionally
world-to-camera, optionally OpenGL axes, moved to the camera by a hand-eye transform), a
COLMAP model with the times of its images, or a turntable description. Rotations are
interpolated with scipy's ``Slerp``, positions linearly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from hybridneus.errors import RecordingError
from hybridneus.recordings.documents import read_mapping
from hybridneus.recordings.track_rows import RowReport, clean_rows, find_dropouts

#: OpenGL camera axes (x right, y up, z backward) to OpenCV's (x right, y down, z forward).
GL_TO_CV = np.diag([1.0, -1.0, -1.0])


@dataclass
class PoseTrack:
    """Camera poses along a recording.

    Attributes:
        t: (n,) float64 strictly increasing seconds on the pose clock.
        rotation: n camera-to-world rotations (scipy ``Rotation``), OpenCV camera axes.
        position: (n, 3) float64 camera centres in the world frame.
        source: where the track came from, for messages.
        rows: what reading the rows found (rows dropped, dropouts).
    """

    t: np.ndarray
    rotation: Rotation
    position: np.ndarray
    source: str = ""
    rows: RowReport = field(default_factory=RowReport)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def covers(self, t: np.ndarray) -> np.ndarray:
        """(m,) bool: which times lie within the track."""
        return (t >= self.t[0]) & (t <= self.t[-1])

    def at(self, t: np.ndarray) -> np.ndarray:
        """(m, 4, 4) camera-to-world poses at times ``t`` inside the track (Slerp, lerp)."""
        t = np.asarray(t, dtype=np.float64)
        if not np.all(self.covers(t)):
            raise RecordingError(
                f"{self.source}: pose asked at {t.min():.6f}..{t.max():.6f} s, outside the "
                f"track's {self.t[0]:.6f}..{self.t[-1]:.6f} s")
        out = np.zeros((t.shape[0], 4, 4))
        out[:, :3, :3] = Slerp(self.t, self.rotation)(t).as_matrix()
        for k in range(3):
            out[:, k, 3] = np.interp(t, self.t, self.position[:, k])
        out[:, 3, 3] = 1.0
        return out

    def matrices(self) -> np.ndarray:
        """(n, 4, 4) the track's own camera-to-world poses."""
        out = np.zeros((len(self), 4, 4))
        out[:, :3, :3] = self.rotation.as_matrix()
        out[:, :3, 3] = self.position
        out[:, 3, 3] = 1.0
        return out

    def path_length(self, t: np.ndarray) -> np.ndarray:
        """(m,) distance the camera centre has travelled from the start of the track to
        each time ``t`` (linear between samples)."""
        steps = np.linalg.norm(np.diff(self.position, axis=0), axis=1)
        travelled = np.concatenate([[0.0], np.cumsum(steps)])
        return np.interp(t, self.t, travelled)


def make_track(
    t: np.ndarray,
    quat_xyzw: np.ndarray,
    position: np.ndarray,
    source: str,
    *,
    world_to_camera: bool = False,
    opengl: bool = False,
    hand_eye: np.ndarray | None = None,
    rows: RowReport | None = None,
) -> PoseTrack:
    """Build a :class:`PoseTrack` from raw samples, fixing conventions.

    Args:
        t: (n,) seconds on the pose clock, strictly increasing.
        quat_xyzw: (n, 4) unit quaternions (x, y, z, w) of the given poses.
        position: (n, 3) translations of the given poses.
        source: file name for messages.
        world_to_camera: the samples are world-to-camera (COLMAP's); inverted here.
        opengl: the camera axes are OpenGL's (y up, z backward).
        hand_eye: (4, 4) pose of the camera in the tracked body's frame (marker or flange to
            camera): ``world_from_camera = world_from_body @ hand_eye``. None: the samples
            are the camera's own poses.
        rows: what cleaning the rows found (:func:`~hybridneus.recordings.track_rows.clean_rows`);
            the track's dropouts are added to it.

    Raises:
        RecordingError: fewer than two samples, non-finite values, zero quaternions, or
            times that do not increase.
    """
    t = np.asarray(t, dtype=np.float64)
    q = np.asarray(quat_xyzw, dtype=np.float64)
    p = np.asarray(position, dtype=np.float64)
    if t.shape[0] < 2:
        raise RecordingError(f"{source}: {t.shape[0]} pose(s); a track needs at least two")
    for name, arr in (("timestamp", t), ("quaternion", q), ("position", p)):
        bad = ~np.isfinite(arr.reshape(arr.shape[0], -1)).all(axis=1)
        if bad.any():
            raise RecordingError(f"{source}: pose {int(np.argmax(bad)) + 1} has a non-finite "
                                 f"{name} ({int(bad.sum())} such poses)")
    norms = np.linalg.norm(q, axis=1)
    if np.any(norms < 1e-6):
        raise RecordingError(f"{source}: pose {int(np.argmax(norms < 1e-6)) + 1} has a zero "
                             "quaternion")
    far = np.abs(norms - 1.0) > 1e-3
    if far.any():
        raise RecordingError(
            f"{source}: pose {int(np.argmax(far)) + 1} has a quaternion of norm "
            f"{norms[far][0]:.4g}, not a unit quaternion (wrong column order?)")
    step = np.diff(t)
    if np.any(step <= 0):
        k = int(np.argmax(step <= 0))
        raise RecordingError(f"{source}: timestamps do not increase at pose {k + 2} "
                             f"({t[k]:.6f} then {t[k + 1]:.6f})")
    R = Rotation.from_quat(q / norms[:, None]).as_matrix()
    if world_to_camera:
        p = -np.einsum("nji,nj->ni", R, p)
        R = np.transpose(R, (0, 2, 1))
    if hand_eye is not None:
        he = np.asarray(hand_eye, dtype=np.float64)
        p = p + np.einsum("nij,j->ni", R, he[:3, 3])
        R = R @ he[:3, :3]
    if opengl:
        R = R @ GL_TO_CV
    report = rows if rows is not None else RowReport()
    report.dropouts = find_dropouts(t)
    return PoseTrack(t=t, rotation=Rotation.from_matrix(R), position=p, source=source,
                     rows=report)


def _fields(text: str) -> list[str]:
    """A row's cells: split on commas, semicolons or tabs where the row has them (an empty
    cell stays, as motion capture leaves one for a hidden body), else on whitespace."""
    for sep in (",", ";", "\t"):
        if sep in text:
            return [v.strip() for v in text.split(sep)]
    return text.split()


def _number(cell: str) -> float | None:
    """A cell as a float: NaN for an empty cell, None for text."""
    if not cell:
        return float("nan")
    try:
        return float(cell)
    except ValueError:
        return None


@dataclass
class _Table:
    """A text table: its header (lower-case names, or None) and its rows."""

    header: list[str] | None
    values: np.ndarray  # (n, m) float, NaN where a cell is empty or text
    text: np.ndarray  # (n, m) bool, where a cell holds text
    lines: np.ndarray  # (n,) the file's line number of each row


def _read_rows(path: Path) -> _Table:
    """A text table. The first non-comment line is a header when a cell of it is not a
    number (a ``#`` line too: TUM files often name their columns so)."""
    try:
        lines = path.read_text().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: cannot read ({exc})") from None
    header: list[str] | None = None
    rows: list[list[float | None]] = []
    numbers: list[int] = []
    for i, raw in enumerate(lines, 1):
        line = raw.strip()
        if not line:
            continue
        comment = line.startswith("#")
        cells = _fields(line.lstrip("#").strip() if comment else line)
        values = [_number(v) for v in cells]
        if any(v is None for v in values):
            if not rows and header is None:
                header = [v.strip().lower().lstrip("%") for v in cells]
                continue
            if comment:
                continue
            if header is None:
                raise RecordingError(f"{path}: line {i} is not a row of numbers: "
                                     f"{line[:60]!r}")
        elif comment:
            continue
        if rows and len(values) != len(rows[0]):
            raise RecordingError(f"{path}: line {i} has {len(values)} values, the first row "
                                 f"{len(rows[0])}")
        rows.append(values)
        numbers.append(i)
    if not rows:
        raise RecordingError(f"{path}: no pose rows")
    text = np.array([[v is None for v in r] for r in rows], dtype=bool)
    values = np.array([[np.nan if v is None else v for v in r] for r in rows], dtype=np.float64)
    return _Table(header, values, text, np.asarray(numbers))


_TIME_NAMES = ("t", "time", "timestamp", "stamp", "ts", "t[s]", "time[s]")
_POS_NAMES = (("tx", "ty", "tz"), ("x", "y", "z"), ("px", "py", "pz"),
              ("pos_x", "pos_y", "pos_z"), ("p_x", "p_y", "p_z"))
_QUAT_NAMES = (("qx", "qy", "qz", "qw"), ("q_x", "q_y", "q_z", "q_w"),
               ("rot_x", "rot_y", "rot_z", "rot_w"), ("quat_x", "quat_y", "quat_z", "quat_w"))
#: ``rostopic echo -p`` names a message's fields by their path (``field.pose.position.x``
#: for a PoseStamped, ``field.pose.pose.position.x`` for an Odometry,
#: ``field.transform.translation.x`` for a TransformStamped); its stamps are nanoseconds.
_ROS_TIME_NAMES = ("field.header.stamp", "time")
_ROS_POS = ("position", "translation")
_ROS_QUAT = ("orientation", "rotation")


def _ros_columns(col: dict[str, int], parents: tuple[str, ...], axes: str
                 ) -> list[int] | None:
    """The columns whose names end in ``<parent>.<axis>`` for one of ``parents``, if that
    picks exactly one column per axis."""
    for parent in parents:
        found = [[i for n, i in col.items() if n.endswith(f".{parent}.{a}")] for a in axes]
        if all(len(f) == 1 for f in found):
            return [f[0] for f in found]
    return None


def read_pose_table(path: str | Path, time_scale: float | None = None,
                    **conventions) -> PoseTrack:
    """A TUM trajectory (``t tx ty tz qx qy qz qw``, ``#`` comments), a CSV whose header
    names its columns (time, position ``tx ty tz`` or ``x y z``, quaternion ``qx qy qz qw``,
    in any order), or a ``rostopic echo -p`` export of PoseStamped, Odometry or
    TransformStamped messages (``%time,field.header.stamp,...``).

    Rows as trackers write them are taken: occluded rows (NaN, empty cells, a zero
    quaternion) and rows repeating the previous stamp are dropped and counted in the
    track's :attr:`PoseTrack.rows`, with the gaps in time (dropouts).

    Args:
        path: the file.
        time_scale: seconds per unit of its time column; None: the file's own (seconds,
            nanoseconds for a ``rostopic echo -p`` export).
        **conventions: ``world_to_camera``, ``opengl``, ``hand_eye`` of :func:`make_track`.
    """
    path = Path(path)
    table = _read_rows(path)
    header, rows = table.header, table.values
    if header is not None and len(header) == rows.shape[1]:
        col = {name: i for i, name in enumerate(header)}
        ros = any(n.startswith("field.") for n in header)
        if ros:
            t_i = next((col[n] for n in _ROS_TIME_NAMES if n in col), None)
            pos_cols = _ros_columns(col, _ROS_POS, "xyz")
            quat_cols = _ros_columns(col, _ROS_QUAT, "xyzw")
            default_scale = 1e-9
        else:
            t_i = next((col[n] for n in _TIME_NAMES if n in col), None)
            pos = next((g for g in _POS_NAMES if all(n in col for n in g)), None)
            quat = next((g for g in _QUAT_NAMES if all(n in col for n in g)), None)
            pos_cols = [col[n] for n in pos] if pos else None
            quat_cols = [col[n] for n in quat] if quat else None
            default_scale = 1.0
        if t_i is None or pos_cols is None or quat_cols is None:
            raise RecordingError(
                f"{path}: header {' '.join(header)} lacks a time column, position (tx ty tz) "
                "or quaternion (qx qy qz qw) columns")
        used = [t_i, *pos_cols, *quat_cols]
        bad = table.text[:, used]
        if bad.any():
            r, c = np.argwhere(bad)[0]
            raise RecordingError(f"{path}: line {table.lines[r]}, column {header[used[c]]} is "
                                 "not a number")
        t, p, q = rows[:, t_i], rows[:, pos_cols], rows[:, quat_cols]
    else:
        if table.text.any():
            r = int(np.argwhere(table.text)[0][0])
            raise RecordingError(f"{path}: line {table.lines[r]} is not a row of numbers")
        if rows.shape[1] != 8:
            raise RecordingError(
                f"{path}: rows have {rows.shape[1]} values; a TUM trajectory has 8 "
                "(t tx ty tz qx qy qz qw), or name the columns in a header")
        t, p, q = rows[:, 0], rows[:, 1:4], rows[:, 4:8]
        default_scale = 1.0
    scale = default_scale if time_scale is None else time_scale
    t, q, p, report = clean_rows(t * scale, q, p)
    if t.shape[0] < 2:
        raise RecordingError(f"{path}: {t.shape[0]} usable pose(s) of {rows.shape[0]} rows "
                             f"({report.occluded} occluded, {report.repeated} repeated "
                             "stamps); a track needs at least two")
    return make_track(t, q, p, str(path), rows=report, **conventions)


@dataclass(frozen=True)
class Turntable:
    """A static camera and an object turning about an axis at constant speed.

    It is a pose track like :class:`PoseTrack` (``covers``, ``at``, ``path_length``),
    expressed in the table's frame (the object stands still, the camera circles): at time
    ``t`` the table has turned by ``start_deg + speed_deg_s * (t - t0)``
    about ``axis`` through ``center`` (right-handed), so the camera has turned by the
    opposite angle.

    Attributes:
        axis: (3,) the rotation axis in the table frame.
        center: (3,) a point on the axis.
        speed_deg_s: angular speed in degrees per second (negative: clockwise about ``axis``).
        start_deg: the table's angle at ``t0``.
        t0: seconds on the event clock where the table's angle is ``start_deg``.
        camera: (4, 4) camera-to-table pose (OpenCV axes) at angle 0.
    """

    axis: tuple[float, float, float]
    center: tuple[float, float, float]
    speed_deg_s: float
    start_deg: float
    t0: float
    camera: tuple[tuple[float, ...], ...]

    source: str = "turntable"

    @property
    def t(self) -> np.ndarray:
        """The span the description covers: all time."""
        return np.array([-np.inf, np.inf])

    def __len__(self) -> int:
        return 0

    def covers(self, t: np.ndarray) -> np.ndarray:
        """(m,) bool: every time (a turntable turns forever)."""
        return np.isfinite(np.asarray(t, dtype=np.float64))

    def at(self, t: np.ndarray) -> np.ndarray:
        """(m, 4, 4) camera-to-table poses at times ``t``, exactly on the circle."""
        t = np.asarray(t, dtype=np.float64)
        angle = np.deg2rad(self.start_deg + self.speed_deg_s * (t - self.t0))
        axis = np.asarray(self.axis, dtype=np.float64)
        axis = axis / np.linalg.norm(axis)
        turn = Rotation.from_rotvec(-angle[:, None] * axis[None, :])
        cam = np.asarray(self.camera, dtype=np.float64)
        c = np.asarray(self.center, dtype=np.float64)
        out = np.zeros((t.shape[0], 4, 4))
        out[:, :3, :3] = (turn * Rotation.from_matrix(cam[:3, :3])).as_matrix()
        out[:, :3, 3] = turn.apply(cam[:3, 3] - c) + c
        out[:, 3, 3] = 1.0
        return out

    def path_length(self, t: np.ndarray) -> np.ndarray:
        """(m,) arc the camera has travelled since ``t0``, in metres."""
        axis = np.asarray(self.axis, dtype=np.float64)
        axis = axis / np.linalg.norm(axis)
        off = np.asarray(self.camera, dtype=np.float64)[:3, 3] - np.asarray(self.center)
        radius = np.linalg.norm(off - axis * (off @ axis))
        return np.abs(np.deg2rad(self.speed_deg_s)) * radius * (np.asarray(t) - self.t0)


def read_turntable(path: str | Path) -> Turntable:
    """A turntable description (JSON or YAML): ``axis``, ``center`` (default origin),
    ``speed_deg_s``, ``start_deg`` (default 0), ``t0`` (default 0) and ``camera``, the
    camera-to-table pose at angle 0 as a 4x4 matrix (OpenCV axes; ``camera_axes: opengl``
    for OpenGL's)."""
    path = Path(path)
    doc = read_mapping(path)
    def value(key: str, shape: tuple[int, ...], default=None) -> np.ndarray:
        if key not in doc and default is None:
            raise RecordingError(f"{path}: turntable needs {key!r} (axis, speed_deg_s, "
                                 "camera)")
        try:
            return np.asarray(doc.get(key, default), dtype=np.float64).reshape(shape)
        except (TypeError, ValueError):
            what = (f"a {shape[0]}x{shape[1]} matrix" if len(shape) == 2 else
                    f"{shape[0]} numbers" if shape else "a number")
            raise RecordingError(f"{path}: turntable {key} must be {what}, got "
                                 f"{doc.get(key)!r}") from None

    axis, camera = value("axis", (3,)), value("camera", (4, 4))
    speed = float(value("speed_deg_s", ()))
    center = value("center", (3,), [0, 0, 0])
    start, t0 = float(value("start_deg", (), 0.0)), float(value("t0", (), 0.0))
    if not (np.isfinite(axis).all() and np.isfinite(camera).all() and np.isfinite(speed)):
        raise RecordingError(f"{path}: turntable values are not all finite")
    if np.linalg.norm(axis) < 1e-9 or speed == 0:
        raise RecordingError(f"{path}: turntable axis is zero or speed_deg_s is 0")
    R = camera[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        raise RecordingError(f"{path}: camera's rotation part is not a rotation")
    if str(doc.get("camera_axes", "opencv")).lower() == "opengl":
        camera[:3, :3] = R @ GL_TO_CV
    return Turntable(axis=tuple(axis), center=tuple(center), speed_deg_s=speed,
                     start_deg=start, t0=t0, camera=tuple(tuple(r) for r in camera),
                     source=str(path))


#: Keys of a transform file that hold the camera's pose in the body's frame (``p_body =
#: T @ p_cam``), as ``--hand-eye`` wants it.
_BODY_FROM_CAMERA = ("T", "matrix", "T_body_cam", "T_body_camera")
#: Keys named the other way (Kalibr's ``T_cam_imu``: ``p_cam = T @ p_imu``): inverted.
_CAMERA_FROM_BODY = ("T_cam_body", "T_camera_body", "T_cam_imu")


def read_matrix(text: str, what: str) -> np.ndarray:
    """A 4x4 rigid transform from a file (16 or 12 numbers, or JSON/YAML with an entry
    named in :data:`_BODY_FROM_CAMERA`, or one in :data:`_CAMERA_FROM_BODY`, which is
    inverted; a Kalibr ``camchain-imucam.yaml``'s ``cam0: T_cam_imu`` is read so) or from
    16 or 12 comma-separated numbers.

    Returns:
        (4, 4) the camera's pose in the body's frame (``p_body = T @ p_cam``).
    """
    path = Path(text)
    invert = False
    if path.exists():
        if path.suffix.lower() in (".json", ".yaml", ".yml"):
            doc = read_mapping(path)
            cam = doc.get("cam0")
            if isinstance(cam, dict) and "T_cam_imu" in cam and not any(
                    k in doc for k in _BODY_FROM_CAMERA + _CAMERA_FROM_BODY):
                doc = cam
            key = next((k for k in _BODY_FROM_CAMERA + _CAMERA_FROM_BODY if k in doc), None)
            if key is None:
                raise RecordingError(
                    f"{path}: no transform entry (one of "
                    f"{', '.join(_BODY_FROM_CAMERA + _CAMERA_FROM_BODY)})")
            values, invert = doc[key], key in _CAMERA_FROM_BODY
        else:
            values = path.read_text().replace(",", " ").split()
        source = str(path)
    else:
        values, source = text.split(","), what
    try:
        m = np.asarray([float(v) for v in np.asarray(values).reshape(-1)], dtype=np.float64)
    except ValueError:
        raise RecordingError(f"{source}: expected 16 or 12 numbers") from None
    if m.size == 12:
        m = np.concatenate([m, [0, 0, 0, 1]])
    if m.size != 16 or not np.isfinite(m).all():
        raise RecordingError(f"{source}: expected 16 or 12 finite numbers, got {m.size}")
    m = m.reshape(4, 4)
    R = m[:3, :3]
    if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
        raise RecordingError(f"{source}: the rotation part is not a rotation")
    if not np.allclose(m[3], [0, 0, 0, 1]):
        raise RecordingError(f"{source}: the last row must be 0 0 0 1")
    if invert:
        inv = np.eye(4)
        inv[:3, :3] = R.T
        inv[:3, 3] = -R.T @ m[:3, 3]
        m = inv
    return m
