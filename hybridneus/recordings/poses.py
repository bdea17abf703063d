"""Camera pose tracks: reading them, fixing their conventions, and sampling them in time.

A :class:`PoseTrack` holds timestamped camera-to-world poses in OpenCV camera axes (x right,
y down, z forward) in the recording's own metric frame. Readers bring every source to that
form: a TUM trajectory or a CSV with named columns (:mod:`hybridneus.recordings.pose_tables`;
a body or marker pose, optionally world-to-camera, optionally OpenGL axes, moved to the
camera by a hand-eye transform), a COLMAP model with the times of its images, or a turntable
description. Rotations are
interpolated with scipy's ``Slerp``, positions linearly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from hybridneus.errors import RecordingError
from hybridneus.recordings.documents import read_mapping
from hybridneus.recordings.track_rows import RowReport, find_dropouts

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
