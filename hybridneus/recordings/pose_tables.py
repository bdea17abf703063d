"""Pose tables as trackers and tools write them: TUM trajectories, CSVs that name their
columns, ``rostopic echo -p`` exports; their rows cleaned (:mod:`hybridneus.recordings.track_rows`)
and made into a :class:`~hybridneus.recordings.poses.PoseTrack`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hybridneus.errors import RecordingError
from hybridneus.recordings.poses import PoseTrack, make_track
from hybridneus.recordings.track_rows import clean_rows


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


__all__ = ["read_pose_table"]
