"""A simulated split re-timed as a recording: the camera's speed varying as a hand moves it,
events in seconds on the sensor's clock, and a pose track sampled at a tracker's rate on a
clock of its own.

The simulator places view ``i`` at time ``i`` and fires the events between views from the
rendered frames; the geometry does not depend on how fast the camera went. Giving the views
real times ``t_i`` with uneven steps (a hand speeds up, slows down, pauses) and mapping each
event's view-unit time onto them linearly gives the event stream a camera moving at that
varying speed would fire: the same events, spread over the real time it spent between views.
The pose track is the views' poses interpolated (``Slerp``, linear) at a tracker's sample
times, shifted onto its own clock by ``clock_offset`` (``pose time = event time +
clock_offset``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation, Slerp


@dataclass
class Recording:
    """Events and a pose track with real clocks.

    Attributes:
        t: (n_events,) seconds on the event clock.
        x: (n_events,) pixel columns.
        y: (n_events,) pixel rows.
        p: (n_events,) polarity, -1 or +1.
        view_t: (n_views,) seconds on the event clock of each view.
        pose_t: (n_poses,) seconds on the pose clock of each tracker sample.
        quat: (n_poses, 4) camera-to-world rotations (x, y, z, w).
        position: (n_poses, 3) camera centres.
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    p: np.ndarray
    view_t: np.ndarray
    pose_t: np.ndarray
    quat: np.ndarray
    position: np.ndarray

    def tum_rows(self) -> np.ndarray:
        """(n_poses, 8) rows of a TUM trajectory: ``t tx ty tz qx qy qz qw``."""
        return np.column_stack([self.pose_t, self.position, self.quat])


SCALES = (0.1, 0.3, 1.0, 3.0)


def handheld_times(n_views: int, duration: float, seed: int = 0, variation: float = 0.5
                   ) -> np.ndarray:
    """(n_views,) view times from 0 to ``duration`` seconds at a speed that varies as a hand
    moves it, without repeating: its logarithm is random noise smoothed over 0.3, 1 and 3
    seconds (a hand's jerks, sweeps and slow drifts), scaled so that its standard deviation
    is ``variation``; 0 gives a constant speed."""
    from scipy.ndimage import gaussian_filter1d

    rng = np.random.default_rng(seed)
    fine = np.linspace(0.0, duration, max(20 * n_views, 4000))
    step = fine[1] - fine[0]
    log_speed = np.zeros_like(fine)
    for scale in SCALES:
        wave = gaussian_filter1d(rng.normal(size=fine.size), scale / step, mode="wrap")
        log_speed += wave / max(wave.std(), 1e-12)
    if log_speed.std() > 0:
        log_speed *= variation / log_speed.std()
    # the path's progress (in views) is the integral of the speed over time
    progress = np.concatenate([[0.0], np.cumsum(np.exp(log_speed[1:]) * np.diff(fine))])
    progress *= (n_views - 1) / progress[-1]
    return np.interp(np.arange(n_views), progress, fine)


def as_recording(events, c2w: np.ndarray, view_t: np.ndarray, *, t0: float = 0.0,
                 pose_rate: float = 200.0, clock_offset: float = 0.0) -> Recording:
    """Re-time a simulated split as a recording.

    Args:
        events: the split's :class:`~hybridneus.data.events.EventStream` (times in views).
        c2w: (n_views, 4, 4) the views' camera-to-world poses.
        view_t: (n_views,) increasing seconds of the views, from 0.
        t0: the event clock's reading at view 0.
        pose_rate: tracker samples a second.
        clock_offset: seconds added to an event time to get the pose clock's time.
    """
    view_t = np.asarray(view_t, dtype=np.float64)
    n = view_t.shape[0]
    t = t0 + np.interp(np.asarray(events.t, dtype=np.float64), np.arange(n), view_t)
    sample = np.arange(0.0, view_t[-1], 1.0 / pose_rate)
    rot = Slerp(view_t, Rotation.from_matrix(c2w[:, :3, :3]))(sample)
    pos = np.stack([np.interp(sample, view_t, c2w[:, k, 3]) for k in range(3)], axis=1)
    return Recording(t=t, x=np.asarray(events.x), y=np.asarray(events.y),
                     p=np.asarray(events.p), view_t=t0 + view_t,
                     pose_t=t0 + clock_offset + sample, quat=rot.as_quat(), position=pos)


__all__ = ["Recording", "as_recording", "handheld_times"]
