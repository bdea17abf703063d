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
clock_offset``). A DAVIS's frames (:func:`aps_frames`) are the rendered views' light averaged
over each exposure; :func:`write_aedat4` writes events and frames as iniVation's DV does,
:func:`write_hdf5` as events_contrast_maximization's ``rosbag_to_h5.py`` does.
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


def aps_frames(view_image, view_t: np.ndarray, fps: float, exposure: float, t0: float = 0.0,
               samples: int = 8, bits: int = 8) -> list:
    """A DAVIS's intensity frames of a re-timed split.

    Args:
        view_image: ``view_image(i)`` -> (height, width, 3) sRGB image of view ``i`` (floats
            in [0, 1] or uint8), the split's ``rgb/`` frame.
        view_t: (n_views,) seconds of the views, from 0 (:func:`handheld_times`).
        fps: frames a second.
        exposure: each frame's exposure, seconds: the light is averaged over ``samples``
            instants of it, each between the two views around it (linear light), so a
            moving camera blurs the frame.
        t0: the event clock's reading at view 0.
        bits: the values are quantised to this many bits (8 or 16), as stored.

    Returns:
        :class:`~hybridneus.recordings.frames.ApsFrame` list: linear values (as the sensor
        gives them), stamped at the middle of their exposure.
    """
    if bits not in (8, 16):
        raise ValueError(f"bits must be 8 or 16, got {bits}")
    from hybridneus.recordings.frames import GAMMA, ApsFrame

    cache: dict[int, np.ndarray] = {}

    def linear(i: int) -> np.ndarray:
        if i not in cache:
            img = np.asarray(view_image(i))
            img = img / 255.0 if img.dtype == np.uint8 else img.astype(np.float64)
            cache[i] = np.clip(img, 0.0, 1.0) ** GAMMA
        return cache[i]

    n = view_t.shape[0]
    frames = []
    start = float(view_t[0])
    while start + exposure <= view_t[-1]:
        at = start + (np.arange(samples) + 0.5) / samples * exposure
        s = np.interp(at, view_t, np.arange(n))
        light = np.zeros_like(linear(0))
        for v in s:
            a = min(int(np.floor(v)), n - 2)
            w = v - a
            light += (1.0 - w) * linear(a) + w * linear(a + 1)
        for key in [k for k in cache if k < int(np.floor(s[0]))]:
            del cache[key]  # behind every later frame
        top = float(2**bits - 1)
        image = (np.round(top * light / samples) / top).astype(np.float32)
        frames.append(ApsFrame(t=t0 + start + 0.5 * exposure, image=image, exposure=exposure,
                               bits=bits))
        start += 1.0 / fps
    return frames


def _bgr_values(frame) -> np.ndarray:
    """An :class:`~hybridneus.recordings.frames.ApsFrame` as stored: its bits' unsigned
    integers, in OpenCV's blue-green-red order."""
    top, dtype = (65535.0, np.uint16) if frame.bits == 16 else (255.0, np.uint8)
    return np.round(np.clip(frame.image, 0.0, 1.0) * top).astype(dtype)[..., ::-1]


def write_aedat4(path, rec: Recording, frames: list, size: tuple[int, int]) -> None:
    """Events (track 0) and frames (track 1) of a recording as an AEDAT4 file, written by
    iniVation's dv-processing as DV writes a DAVIS346's (``pip install -e ".[recordings]"``).

    Args:
        path: the file.
        rec: the events (seconds on the event clock).
        frames: :class:`~hybridneus.recordings.frames.ApsFrame` list (may be empty).
        size: (width, height) of the sensor.
    """
    from pathlib import Path

    from hybridneus.recordings.stream import need

    dv = need("dv_processing", Path(path), "writing AEDAT4 files")
    config = dv.io.MonoCameraWriter.Config("DAVIS346")
    config.addEventStream(tuple(size))
    if frames:
        config.addFrameStream(tuple(size))
    writer = dv.io.MonoCameraWriter(str(path), config)
    t = np.round(np.asarray(rec.t) * 1e6).astype(np.int64)
    for a in range(0, t.size, 1 << 20):
        store = dv.EventStore()
        push = store.push_back
        b = min(a + (1 << 20), t.size)
        for args in zip(t[a:b].tolist(), np.asarray(rec.x[a:b]).tolist(),
                        np.asarray(rec.y[a:b]).tolist(), (np.asarray(rec.p[a:b]) > 0).tolist(),
                        strict=True):
            push(*args)
        writer.writeEvents(store)
    for f in frames:
        start = int(round((f.t - 0.5 * f.exposure) * 1e6))
        bgr = np.ascontiguousarray(_bgr_values(f))  # DV stores OpenCV's channel order
        writer.writeFrame(dv.Frame(start, int(round(f.exposure * 1e6)), 0, 0, bgr,
                                   dv.FrameSource.SENSOR))
    del writer  # closes the file


def write_hdf5(path, rec: Recording, frames: list, size: tuple[int, int]) -> None:
    """Events and frames of a recording as an HDF5 file in the layout
    events_contrast_maximization's ``rosbag_to_h5.py`` writes: ``events/{xs, ys, ts, ps}``
    (``ts`` float seconds, ``ps`` 0 or 1), ``images/image<nnnnnnnnn>`` (``color_bgr``,
    stamped by a ``timestamp`` attribute, no exposure) and the ``sensor_resolution``
    (height, width) attribute.

    Args:
        path: the file.
        rec: the events (seconds on the event clock).
        frames: :class:`~hybridneus.recordings.frames.ApsFrame` list (may be empty).
        size: (width, height) of the sensor.
    """
    from pathlib import Path

    from hybridneus.recordings.stream import need

    h5py = need("h5py", Path(path), "writing HDF5 files")
    with h5py.File(path, "w") as f:
        f.create_dataset("events/xs", data=np.asarray(rec.x, dtype=np.uint16))
        f.create_dataset("events/ys", data=np.asarray(rec.y, dtype=np.uint16))
        f.create_dataset("events/ts", data=np.asarray(rec.t, dtype=np.float64))
        f.create_dataset("events/ps", data=(np.asarray(rec.p) > 0).astype(np.uint8))
        for i, fr in enumerate(frames):
            dset = f.create_dataset(f"images/image{i:09d}", data=_bgr_values(fr))
            dset.attrs["timestamp"] = float(fr.t)
            dset.attrs["type"] = "color_bgr"
        f.attrs["sensor_resolution"] = (int(size[1]), int(size[0]))
        f.attrs["num_events"] = int(np.asarray(rec.t).size)
        f.attrs["num_imgs"] = len(frames)


__all__ = ["Recording", "aps_frames", "as_recording", "handheld_times", "write_aedat4",
           "write_hdf5"]
