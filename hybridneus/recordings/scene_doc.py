"""The ``scene.json`` a conversion writes beside its dataset
(:mod:`hybridneus.recordings.convert`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hybridneus.recordings.frame import SceneFrame, box_crop


def scene_document(source, track, calib, options, scan, times, frame: SceneFrame, cyclic,
                   n_pos, size, estimate=None, frames=None, found=None) -> dict:
    """``scene.json`` of a conversion: what was read, how, and the preset for the reader.

    Args are :func:`~hybridneus.recordings.convert.convert_recording`'s inputs and what its
    passes found: the first pass's counts (``scan``), the views' event-clock ``times``, the
    recording frame, whether the track closes a loop, the positive events written, the
    sensor size, the clock estimate (or None), the frames the views sit at (or None) and the
    thresholds taken from the recording's frames (or None: the preset's C is the stated one
    or the reader's guess).
    """
    w, h = size
    preset: dict = {
        "group": "recording", "scene": Path(source.path).stem, "width": w, "height": h,
        "cyclic": cyclic, "max_window": int(min(100, options.views - 1)),
        "neg_ratio": 0.05, "mosaic": options.mosaic,
    }
    if options.threshold is not None:
        preset["threshold"] = options.threshold
    elif found is not None:
        preset["threshold"] = found["threshold"]
    if options.box is not None:
        preset |= box_crop(frame, options.box)
    if frames is not None:
        preset["tonemap_eps"] = options.frames_eps
    doc = {
        "format": "hybridneus-converted-recording",
        "version": 1,
        "scene": preset["scene"],
        "width": w,
        "height": h,
        "sensor": {"mosaic": options.mosaic, "threshold": options.threshold,
                   **({"threshold_from_frames": found} if found is not None else {})},
        "frame": frame.to_json(),
        "views": {
            "n": options.views, "spacing": options.spacing,
            "event_clock_s": [float(times[0]), float(times[-1])],
            "time_unit": "view index: view i is at t = i",
        },
        "events": {
            "source": str(source.path), "format": source.format, "read_as": source.note,
            "n_read": scan.n_read, "n_in_window": scan.n_window,
            "n_outside_pose_track": scan.n_outside_track, "n_written": scan.n_kept,
            "hot_pixels": ({"n": scan.hot.n, "events": scan.hot.events,
                            "pixels": [list(xy) for xy in scan.hot.pixels()]}
                           if scan.hot is not None else {"n": 0, "events": 0, "pixels": []}),
            "n_positive": n_pos, "start_s": options.start, "end_s": options.end,
            "file_span_s": [scan.t_first_file, scan.t_last_file],
        },
        "poses": {"source": track.source, "n": len(track),
                  "clock_offset_s": options.clock_offset, "max_gap_s": options.max_gap,
                  **(track.rows.to_json() if getattr(track, "rows", None) else {})},
        "calibration": calib.to_json() | {
            "layout_K_note": "principal point + 0.5 px in the layout (pixel centres at +0.5)"},
        **({"lens": {"model": calib.model, "coeffs": list(calib.coeffs)}}
           if calib.distorted else {}),
        "preset": preset,
    }
    if estimate is not None:
        doc["poses"]["clock_offset_estimate"] = estimate.to_json()
    if frames is not None:
        doc["frames"] = {
            "n": len(frames), "source": str(source.path),
            "mean_exposure_s": float(np.mean([f.exposure for f in frames])),
            "written": "rgb/, sRGB-encoded from the sensor's linear values "
                       "(255 (v / 255) ** (1 / 2.2)); one view at the middle of each frame's "
                       "exposure"}
    return doc


__all__ = ["scene_document"]
