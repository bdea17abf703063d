"""The contrast threshold from a recording's own frames, whatever the views' placement.

``convert`` places its views along the track (``--views N``) where a DAVIS's frames come at
their own rate. Where the recording holds frames and no ``--threshold`` is stated, the
thresholds are estimated at conversion as :mod:`hybridneus.data.threshold` does from a split's
``rgb/`` frames: the sensor is replayed over the frames where the camera moved least and C is
the threshold whose replay fires the converted events. The value becomes the preset's C in
``scene.json`` (``sensor.threshold_from_frames`` keeps how it was found), so that a fit does
not take the 0.25 guess of a sensor that the events alone cannot fix.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from hybridneus.errors import RecordingError
from hybridneus.recordings.frames import frame_times, holds_frames, read_frames

#: A frame value at or above this share of full scale is taken as saturated.
SATURATED = 0.98


def threshold_from_frames(path: str | Path, size: tuple[int, int], time_unit: str | None,
                          view_t: np.ndarray, c2w_at, events, mosaic: str, eps: float,
                          start: float, run: int | None = None, max_pixels: int = 50_000,
                          seed: int = 0):
    """The contrast thresholds that a recording's own frames and its converted events imply
    (:mod:`hybridneus.data.threshold`), with the views placed anywhere along the track.

    The replay runs over the consecutive frames inside the views' span over which the camera
    moved least, on the frames' linear values as stored: ``log(v + eps)``, with ``v`` their
    value over full scale. Re-encoding 8-bit linear values as the layout's 8-bit sRGB first
    (as ``rgb/`` holds them) quantises the dark end twice and took C 17-27% low on two of
    three generated scenes; on the stored values it came within 6%. Dark pixels are kept:
    ``eps`` floors the log as the sensor's own response does, and leaving out every pixel
    that touches zero left too few pixels on dark scenes. A pixel saturated in any frame of
    the run is left out.

    Args:
        path: the recording; ``size``, ``time_unit`` as :func:`read_frames`.
        view_t: (n_views,) event-clock seconds of the views: view ``i`` sits at ``t = i`` in
            ``events``.
        c2w_at: event-clock seconds (n,) -> (n, 4, 4) normalised camera-to-world.
        events: the converted split's :class:`~hybridneus.data.events.EventStream`.
        mosaic: the sensor's colour filter (which frame channel each pixel's events see).
        eps: the frames' log mapping ``log(v + eps)``.
        start: the threshold the solve starts from.
        run: frames the replay follows (default :data:`~hybridneus.data.threshold.RUN_VIEWS`).

    Returns:
        (:class:`~hybridneus.data.threshold.ThresholdEstimate` or None, why none, frames
        inside the views' span).
    """
    from hybridneus.data.mosaic import mosaic_weights
    from hybridneus.data.threshold import (
        RUN_VIEWS,
        observed_counts,
        slowest_run,
        solve_thresholds,
    )

    run = RUN_VIEWS if run is None else run
    times = frame_times(path, size, time_unit)
    times = times[(times >= view_t[0]) & (times <= view_t[-1])]
    times = times[np.r_[True, np.diff(times) > 0]] if times.size else times
    if times.size < 2:
        return None, f"{times.size} of the recording's frames lie within the views' span", 0
    first = slowest_run(c2w_at(times), run)
    n = min(run, times.size)
    frames = read_frames(path, size, time_unit, (times[first], times[first + n - 1]))
    w, h = size
    pixels = np.sort(np.random.default_rng(seed).choice(h * w, min(max_pixels, h * w),
                                                       replace=False))
    weights = mosaic_weights(np.stack([pixels % w, pixels // w], axis=1), mosaic)
    light = np.stack([f.image.reshape(h * w, 3)[pixels] for f in frames])
    known = (light < SATURATED).all(axis=(0, 2))
    log_frames = (weights[None] * np.log(light + eps)).sum(-1)
    at = np.interp([frames[0].t, frames[-1].t], view_t, np.arange(view_t.size))
    on, off = observed_counts(events, w, pixels, float(at[0]), float(at[1]))
    est, why = solve_thresholds(log_frames[:, known], on[known], off[known], start, first)
    return est, why, int(times.size)


def frames_threshold(source, size, times, frame, track, options, events_path) -> dict | None:
    """C from the recording's own frames where it holds some (:func:`threshold_from_frames`),
    for :func:`~hybridneus.recordings.convert.convert_recording`: the record ``scene.json``
    keeps, or None, with a warning why where the frames gave none."""
    if not holds_frames(source.path):
        return None
    from hybridneus.data.events import load_events
    from hybridneus.data.presets import GROUP_DEFAULTS
    from hybridneus.errors import DatasetError

    log = logging.getLogger("hybridneus")
    try:
        est, why, n = threshold_from_frames(
            source.path, size, getattr(source, "time_unit", None), times,
            lambda t: frame.poses_to_normalised(track.at(t + options.clock_offset)),
            load_events(events_path, *size), options.mosaic, options.frames_eps,
            GROUP_DEFAULTS["nerf"].threshold)
    except (RecordingError, DatasetError) as exc:
        est, why, n = None, str(exc), 0
    if est is None:
        log.warning(f"{source.path}: the contrast threshold was not taken from its frames "
                    f"({why}); C stays the preset's guess (--threshold C if it is known)")
        return None
    log.info(f"{source.path}: {est.line()}")
    return {"threshold": round(est.threshold, 5), "on": round(est.on, 5),
            "off": round(est.off, 5), "explained": round(est.explained, 3),
            "pixels": est.pixels, "frames_replayed": est.views, "frames_in_span": n,
            "first_frame": est.first, "frames_eps": options.frames_eps}


__all__ = ["frames_threshold", "threshold_from_frames"]
