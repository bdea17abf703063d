"""Where a conversion's views go along a pose track: their times (even in time or in path
length), the track's dropouts they must keep out of, and whether the track closes a loop."""

from __future__ import annotations

import numpy as np

from hybridneus.errors import RecordingError
from hybridneus.recordings.poses import PoseTrack


def view_times(track: PoseTrack, t_first: float, t_last: float, views: int,
               spacing: str = "time", clock_offset: float = 0.0) -> np.ndarray:
    """(views,) event-clock times of the views, from ``t_first`` to ``t_last``: even in time
    (``spacing="time"``) or in the camera's path length (``"path"``; the track is read at
    event time plus ``clock_offset``)."""
    if spacing == "time":
        return np.linspace(t_first, t_last, views)
    dense = np.linspace(t_first, t_last, max(20 * views, 10_000))
    travelled = track.path_length(dense + clock_offset)
    travelled -= travelled[0]
    if not travelled[-1] > 0:
        raise RecordingError(f"{track.source}: --spacing path needs a moving camera; the "
                             "camera stands still over the kept events")
    targets = np.linspace(0.0, travelled[-1], views)
    # The path length may stand still (a pause): take the first time it reaches each target.
    idx = np.searchsorted(travelled, targets, side="left").clip(0, len(dense) - 1)
    times = dense[idx]
    times[0], times[-1] = t_first, t_last
    if np.any(np.diff(times) <= 0):
        raise RecordingError(f"{track.source}: --spacing path gives views at the same time "
                             "(the camera jumps); use --spacing time")
    return times


def check_dropouts(track: PoseTrack, pose_times: np.ndarray, max_gap: float | None) -> None:
    """Refuse views that fall in a dropout of the track longer than ``max_gap`` seconds:
    their poses would be guessed by interpolation across it.

    Args:
        track: the pose track (its ``rows.dropouts``; a turntable has none).
        pose_times: (views,) the views' times on the pose clock.
        max_gap: the longest dropout interpolated across; None: none.

    Raises:
        RecordingError: naming the dropout, the views in it and the ways out.
    """
    rows = getattr(track, "rows", None)
    for d in rows.dropouts if rows is not None else []:
        inside = int(((pose_times > d.start) & (pose_times < d.end)).sum())
        if inside and (max_gap is None or d.length > max_gap + 1e-9):
            # the suggested value, rounded up to a millisecond, lets this dropout through
            need = np.ceil(round(d.length * 1e3, 6)) / 1e3
            raise RecordingError(
                f"{track.source}: {inside} view(s) fall where the track has {d.describe()}; "
                f"allow interpolation across it with --max-gap {need:g}, or keep the views "
                "out of it with --start/--end")


def closes_loop(c2w: np.ndarray) -> bool:
    """Whether the first and last views nearly coincide (a full turn of a turntable)."""
    steps = np.linalg.norm(np.diff(c2w[:, :3, 3], axis=0), axis=1)
    gap = np.linalg.norm(c2w[-1, :3, 3] - c2w[0, :3, 3])
    cos = (np.trace(c2w[0, :3, :3].T @ c2w[-1, :3, :3]) - 1) / 2
    turn = np.deg2rad(3 * 360 / len(c2w))  # three views' worth of a full turn
    return bool(gap <= 2 * np.median(steps) + 1e-12 and cos > np.cos(turn))


__all__ = ["check_dropouts", "closes_loop", "view_times"]
