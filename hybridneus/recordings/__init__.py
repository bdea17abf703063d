"""Your own recordings: events in common formats, pose tracks, calibrations -> a dataset.

``hybridneus convert`` (see ``docs/recordings.md``) is built from these parts:

- :func:`open_events` reads AEDAT4, Prophesee RAW/DAT, HDF5, ROS bags, text and numpy
  files in chunks;
- :func:`read_pose_table` (TUM, CSV, ``rostopic echo -p``; hidden frames, repeated stamps
  and dropouts reported), :func:`read_colmap_track` (COLMAP models) and
  :func:`read_turntable` give a camera track;
- :func:`estimate_clock_offset` finds the offset between the event and pose clocks;
- :func:`read_frames` reads a DAVIS's own frames from an AEDAT4 file;
- :func:`read_calibration` reads Kalibr, OpenCV and plain calibration files;
- :func:`fit_frame` chooses the unit-sphere frame and keeps the way back;
- :func:`convert_recording` writes the EventNeRF layout with ``scene.json``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hybridneus.lazy import lazy_getattr

if TYPE_CHECKING:
    from hybridneus.recordings.calibration import Calibration, read_calibration
    from hybridneus.recordings.clock import ClockEstimate, estimate_clock_offset
    from hybridneus.recordings.colmap import is_colmap_model, read_colmap_track
    from hybridneus.recordings.convert import ConvertOptions, convert_recording
    from hybridneus.recordings.events import EventChunk, EventSource, open_events
    from hybridneus.recordings.frame import SceneFrame, fit_frame, read_scene_frame
    from hybridneus.recordings.frames import ApsFrame, read_frames
    from hybridneus.recordings.pose_tables import read_pose_table
    from hybridneus.recordings.poses import (
        PoseTrack,
        Turntable,
        make_track,
        read_matrix,
        read_turntable,
    )

# Each name's module, imported on first use: a fit reads a converted dataset's frame
# (recordings.frame) and should not pay for the clock estimate's scipy.signal or the readers.
_MODULES = {
    "Calibration": "calibration", "read_calibration": "calibration",
    "ClockEstimate": "clock", "estimate_clock_offset": "clock",
    "is_colmap_model": "colmap", "read_colmap_track": "colmap",
    "ConvertOptions": "convert", "convert_recording": "convert",
    "EventChunk": "events", "EventSource": "events", "open_events": "events",
    "SceneFrame": "frame", "fit_frame": "frame", "read_scene_frame": "frame",
    "ApsFrame": "frames", "read_frames": "frames",
    "read_pose_table": "pose_tables",
    "PoseTrack": "poses", "Turntable": "poses", "make_track": "poses",
    "read_matrix": "poses", "read_turntable": "poses",
}


__getattr__ = lazy_getattr(__name__, {k: f"{__name__}.{m}" for k, m in _MODULES.items()},
                           globals())


__all__ = [
    "ApsFrame",
    "Calibration",
    "ClockEstimate",
    "ConvertOptions",
    "EventChunk",
    "EventSource",
    "PoseTrack",
    "SceneFrame",
    "Turntable",
    "convert_recording",
    "estimate_clock_offset",
    "fit_frame",
    "is_colmap_model",
    "make_track",
    "open_events",
    "read_calibration",
    "read_colmap_track",
    "read_frames",
    "read_matrix",
    "read_pose_table",
    "read_scene_frame",
    "read_turntable",
]
