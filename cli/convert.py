"""``hybridneus convert``: a recording, its poses and calibration -> an EventNeRF-layout dataset."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def convert(
    recording: Annotated[Path, typer.Argument(
        help="Event file: .aedat4, .raw (EVT2/EVT3), .dat, .es, .h5/.hdf5 (DSEC, TUM-VIE), "
             ".bag or a ROS 2 bag folder, .txt/.csv, .npz/.npy.", show_default=False)],
    out: Annotated[Path, typer.Argument(help="Output dataset folder (written atomically).",
                                        show_default=False)],
    poses: Annotated[Path | None, typer.Option(
        help="Pose track: TUM text (t tx ty tz qx qy qz qw), a CSV naming its columns, or a "
             "COLMAP model folder (with --frame-times unless image names are times).")]
        = None,
    frame_times: Annotated[Path | None, typer.Option(
        help="For a COLMAP model: rows of image name and time (in --pose-time-unit).",
        show_default=False)] = None,
    turntable: Annotated[Path | None, typer.Option(
        help="Instead of --poses: a turntable description (JSON/YAML: axis, speed_deg_s, "
             "camera, ...).")] = None,
    calib: Annotated[Path | None, typer.Option(
        help="Calibration: Kalibr camchain YAML, OpenCV YAML/JSON, or plain JSON.")] = None,
    camera: Annotated[str | None, typer.Option(
        help="Camera of a Kalibr camchain or a DSEC cam_to_cam.yaml (default cam0).")] = None,
    views: Annotated[str, typer.Option(
        help="Views placed along the track, or frames: one at each of the camera's own "
             "frames (AEDAT4), which are kept as the rgb/ files.")] = "1000",
    frames_eps: Annotated[float, typer.Option(
        help="With --views frames: eps of the frames' log mapping log(c^2.2 + eps), "
             "stated as the preset's tonemap_eps.")] = 1e-3,
    spacing: Annotated[str, typer.Option(
        help="time: views uniform in time; path: uniform in the camera's path length.")]
        = "time",
    start: Annotated[float | None, typer.Option(
        help="Time of the first view, in seconds on the event file's clock; earlier events "
             "are dropped. [default: the first event inside the pose track]",
        show_default=False)] = None,
    end: Annotated[float | None, typer.Option(
        help="Time of the last view; later events are dropped. [default: the last event "
             "inside the pose track]", show_default=False)] = None,
    time_unit: Annotated[str | None, typer.Option(
        help="Unit of the event file's timestamps where its format does not fix it: s, ms, "
             "us or ns. [default: the format's, or a guess that is printed]",
        show_default=False)] = None,
    columns: Annotated[str, typer.Option(
        help="Column order of a text event file, e.g. txyp or xytp.")] = "txyp",
    topic: Annotated[str | None, typer.Option(
        help="Event topic of a ROS bag holding several. [default: the only one]",
        show_default=False)] = None,
    events_track: Annotated[int | None, typer.Option(
        "--track", help="Events track (stream id) of an AEDAT4 file holding several. "
                        "[default: the first]", show_default=False)] = None,
    pose_time_unit: Annotated[str | None, typer.Option(
        help="Unit of the pose file's timestamps. [default: s; ns for a rostopic echo -p "
             "export]", show_default=False)] = None,
    max_gap: Annotated[float | None, typer.Option(
        help="Longest dropout of the pose track (seconds without a pose) that views may be "
             "placed in by interpolation. [default: none; a view in a dropout is refused]",
        show_default=False)] = None,
    clock_offset: Annotated[str, typer.Option(
        help="Seconds to add to an event time to get the pose clock's time, or auto: "
             "estimated from the event rate and the track's speed (refused, with the reason, "
             "where the motion cannot pin it).")] = "0",
    world_to_camera: Annotated[bool, typer.Option(
        "--world-to-camera", help="The poses map world to camera (COLMAP's); default: "
                                  "camera (or body) to world.")] = False,
    opengl: Annotated[bool, typer.Option(
        "--opengl", help="The poses use OpenGL camera axes (y up, z backward).")] = False,
    hand_eye: Annotated[str | None, typer.Option(
        help="Camera pose in the tracked body's frame (marker or flange to camera): a file "
             "or 16 comma-separated numbers, row-major.")] = None,
    sensor: Annotated[str, typer.Option(
        help="The sensor's colour filter: mono, or a Bayer layout RGGB (DAVIS346C), BGGR, "
             "GRBG, GBRG.")] = "mono",
    threshold: Annotated[float | None, typer.Option(
        help="Contrast threshold C, if known. [default: not stated]", show_default=False)]
        = None,
    up: Annotated[str | None, typer.Option(
        help="Up direction in the recording frame, X,Y,Z. [default: the cameras' mean up]",
        show_default=False)] = None,
    box: Annotated[str | None, typer.Option(
        help="Region of interest in the recording frame, X0,Y0,Z0,X1,Y1,Z1: the centre and "
             "the crop. [default: where the cameras look; crop from the events]",
        show_default=False)] = None,
    cyclic: Annotated[bool | None, typer.Option(
        "--cyclic/--no-cyclic", help="The track closes a loop. [default: from the track]",
        show_default=False)] = None,
    keep_hot_pixels: Annotated[bool, typer.Option(
        "--keep-hot-pixels", help="Write the events of hot pixels (pixels firing far more "
                                  "than their neighbours) too; by default they are left "
                                  "out.")] = False,
    check: Annotated[bool, typer.Option(
        "--check", help="Also write pictures to OUT/check: the camera track, event frames with "
                        "--point/--box projected.")] = False,
    point: Annotated[list[str] | None, typer.Option(
        help="A point X,Y,Z in the recording frame to mark in the --check pictures "
             "(repeatable).")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
) -> None:
    """Convert a recording with its poses and calibration into the EventNeRF layout.

    OUT gets train/{pose,intrinsics,events} and scene.json (sensor, preset, the transform to
    the unit sphere); `hybridneus fit OUT` trains on it and `hybridneus mesh` writes the mesh
    back in the recording's frame.

    Example: hybridneus convert rec.aedat4 --poses mocap.txt --calib camchain.yaml data/rec
    """
    import logging

    import numpy as np

    from hybridneus.cli.options import log_to_stderr
    from hybridneus.errors import ConfigError, RecordingError
    from hybridneus.recordings import (
        ConvertOptions,
        convert_recording,
        is_colmap_model,
        open_events,
        read_calibration,
        read_colmap_track,
        read_matrix,
        read_pose_table,
        read_turntable,
    )
    from hybridneus.recordings.events import TIME_UNITS

    log_to_stderr(logging.WARNING)  # what the conversion drops or doubts, one line each
    if (poses is None) == (turntable is None):
        raise RecordingError("convert: give exactly one of --poses and --turntable")
    if pose_time_unit is not None and pose_time_unit not in TIME_UNITS:
        raise RecordingError(f"--pose-time-unit: expected one of {', '.join(TIME_UNITS)}, got "
                             f"{pose_time_unit!r}")
    if calib is None:
        raise RecordingError("convert: --calib is needed (the camera's intrinsics)")
    calibration = read_calibration(calib, camera)
    if poses is not None and is_colmap_model(poses):
        track = read_colmap_track(
            poses, frame_times, TIME_UNITS[pose_time_unit or "s"], opengl=opengl,
            hand_eye=read_matrix(hand_eye, "--hand-eye") if hand_eye else None)
    elif poses is not None:
        if frame_times is not None:
            raise RecordingError("--frame-times: applies to a COLMAP model given as --poses")
        track = read_pose_table(
            poses, TIME_UNITS[pose_time_unit] if pose_time_unit else None,
            world_to_camera=world_to_camera, opengl=opengl,
            hand_eye=read_matrix(hand_eye, "--hand-eye") if hand_eye else None)
    else:
        if world_to_camera or opengl or hand_eye:
            raise RecordingError("--turntable: its camera pose states its own conventions; "
                                 "--world-to-camera, --opengl and --hand-eye apply to --poses")
        track = read_turntable(turntable)
    source = open_events(recording, time_unit=time_unit, columns=columns, topic=topic,
                         track=events_track)
    from hybridneus.data.mosaic import check_mosaic

    try:
        mosaic = check_mosaic(sensor)
    except ConfigError:
        raise RecordingError(f"--sensor: expected mono, RGGB, BGGR, GRBG or GBRG, got "
                             f"{sensor!r}") from None
    marks = [_floats("--point", p, 3) for p in point or []]
    box_values = np.asarray(_floats("--box", box, 6)).reshape(2, 3) if box else None
    if box_values is not None:
        box_values = np.sort(box_values, axis=0)
        if np.any(box_values[1] - box_values[0] <= 0):
            raise RecordingError(f"--box: {box} has no volume")
    options = ConvertOptions(
        views=_views(views), spacing=spacing, start=start, end=end, frames_eps=frames_eps,
        clock_offset=_clock_offset(clock_offset),
        mosaic=mosaic, threshold=threshold,
        up=np.asarray(_floats("--up", up, 3)) if up else None, box=box_values, cyclic=cyclic,
        max_gap=max_gap, keep_hot_pixels=keep_hot_pixels)
    typer.echo(f"{recording}: {source.note}")
    doc = convert_recording(source, track, calibration, out, options, progress=not quiet)
    ev = doc["events"]
    typer.echo(f"{ev['n_written']:,} of {ev['n_read']:,} events written"
               + (f"; {ev['n_outside_pose_track']:,} outside the pose track dropped"
                  if ev["n_outside_pose_track"] else "")
               + (f"; {ev['n_read'] - ev['n_in_window']:,} outside --start/--end"
                  if ev["n_in_window"] != ev["n_read"] else "")
               + (f"; {ev['hot_pixels']['events']:,} of {ev['hot_pixels']['n']} hot pixels "
                  "left out" if ev["hot_pixels"]["n"] else ""))
    est = doc["poses"].get("clock_offset_estimate")
    if est is not None:
        typer.echo(f"clock offset {est['offset_s']:.4f} s +- {est['uncertainty_s'] * 1e3:.2f} ms, "
                   "estimated from the event rate and the camera's speed (coherence "
                   f"{est['coherence']:.2f}; {est['uncertainty_px']:.2f} px at the track's speed)")
    found = doc["sensor"].get("threshold_from_frames")
    if found is not None:
        typer.echo(f"contrast threshold C {found['threshold']:.4g} (ON {found['on']:.4g}, OFF "
                   f"{found['off']:.4g}), estimated from {found['frames_replayed']} of the "
                   f"camera's frames ({100 * found['explained']:.0f}% of the events' counts "
                   "explained)")
    frame = doc["frame"]
    how = "at the camera's frames" if "frames" in doc else f"{spacing} spacing"
    typer.echo(f"{doc['views']['n']} views ({how}, cyclic {doc['preset']['cyclic']}); "
               f"scale {frame['scale']:.4g} per metre; centre: {frame['how']}")
    from hybridneus.data import load_dataset
    from hybridneus.data.hull import background_fires

    written = load_dataset(out)  # a converted dataset holds only its train split
    clutter = background_fires(written["train"])
    if clutter is not None:
        logging.getLogger("hybridneus").warning(
            f"{out}: {clutter}. A fit takes no crop from the events and leaves the hull "
            "prior off; give the object's region with --box (or a backdrop behind it)")
    if check:
        from hybridneus.recordings.check import write_check
        from hybridneus.recordings.frame import read_scene_frame

        pts = list(marks)
        if box_values is not None:
            pts += [[box_values[i, 0], box_values[j, 1], box_values[k, 2]]
                    for i in (0, 1) for j in (0, 1) for k in (0, 1)]
        paths = write_check(written, np.asarray(pts, dtype=np.float64).reshape(-1, 3),
                            read_scene_frame(out), out / "check")
        typer.echo(f"{out / 'check'}: {len(paths)} pictures")
    typer.echo(f"wrote {out}")


def _floats(option: str, text: str, n: int) -> list[float]:
    import math

    from hybridneus.errors import RecordingError

    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != n or not all(math.isfinite(v) for v in values):
        raise RecordingError(f"{option}: expected {n} comma-separated numbers, got {text!r}")
    return values


def _clock_offset(text: str) -> float | str:
    import math

    from hybridneus.errors import RecordingError

    if text.strip().lower() == "auto":
        return "auto"
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise RecordingError(f"--clock-offset: expected seconds or auto, got {text!r}")
    return value


def _views(text: str) -> int | str:
    from hybridneus.errors import RecordingError

    if text.strip().lower() == "frames":
        return "frames"
    try:
        return int(text)
    except ValueError:
        raise RecordingError(f"--views: expected a number or frames, got {text!r}") from None
