"""A recording, its poses and its calibration -> an EventNeRF-layout dataset + scene.json.

Two streaming passes over the events keep memory bounded whatever the recording's length:
the first counts the events to keep (inside ``--start``/``--end`` and inside the pose track,
pixels checked against the sensor), the second writes them, with their times converted to
view units, column by column into ``.npy`` files that are then stored (not compressed) into
``events.npz``. Views are placed along the track uniformly in time or in path length; view
``i`` of ``N`` sits at time ``i`` in those units, which is where the layout puts it.
"""

from __future__ import annotations

import io
import json
import logging
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hybridneus.errors import RecordingError
from hybridneus.fileio import atomic_dir
from hybridneus.recordings.calibration import Calibration, check_lens
from hybridneus.recordings.events import EventSource
from hybridneus.recordings.frame import fit_frame
from hybridneus.recordings.poses import PoseTrack
from hybridneus.recordings.scene_doc import scene_document
from hybridneus.recordings.views import check_dropouts, closes_loop, view_times

MOSAICS = ("mono", "RGGB", "BGGR", "GRBG", "GBRG")
SPACINGS = ("time", "path")


@dataclass
class ConvertOptions:
    """How :func:`convert_recording` turns a recording into a dataset.

    Attributes:
        views: number of views along the track, or ``"frames"``: one at each of the
            recording's own frames (:mod:`hybridneus.recordings.frames`), which become the
            split's ``rgb/`` files.
        spacing: ``time`` (uniform in time) or ``path`` (uniform in the camera's path length).
        start: event-clock seconds of the first view; earlier events are dropped (None: the
            first event inside the pose track).
        end: event-clock seconds of the last view; later events are dropped (None: the last
            event inside the pose track).
        clock_offset: seconds added to an event time to get the pose clock's time, or
            ``"auto"``: estimated from the event rate and the track's speed
            (:func:`hybridneus.recordings.clock.estimate_clock_offset`).
        mosaic: the sensor's colour filter: ``mono`` or a Bayer layout (``RGGB``, ...).
        threshold: the contrast threshold C, if known (written to the preset).
        up: (3,) the recording frame's up direction, or None.
        box: (2, 3) corners of the region of interest in the recording frame, or None.
        cyclic: whether the track closes a loop; None: decided from the track.
        frames_eps: with ``views="frames"``, the eps of the frames' log mapping
            ``log(c ** 2.2 + eps)``, stated as the preset's ``tonemap_eps``.
        keep_hot_pixels: write the events of hot pixels too (:mod:`hybridneus.data.hot`);
            by default they are left out.
        max_gap: the longest dropout of the pose track (seconds without a sample) that views
            may be placed in by interpolating across it; None: none, a view in a dropout
            is refused.
    """

    views: int | str = 1000
    spacing: str = "time"
    start: float | None = None
    end: float | None = None
    clock_offset: float | str = 0.0
    mosaic: str = "mono"
    threshold: float | None = None
    up: np.ndarray | None = None
    box: np.ndarray | None = None
    cyclic: bool | None = None
    max_gap: float | None = None
    keep_hot_pixels: bool = False
    frames_eps: float = 1e-3
    sources: dict = field(default_factory=dict)

    def check(self) -> None:
        if isinstance(self.views, str):
            if self.views != "frames":
                raise RecordingError(f"--views: expected a number or frames, got "
                                     f"{self.views!r}")
        elif self.views < 2:
            raise RecordingError(f"--views: need at least 2, got {self.views}")
        if not self.frames_eps > 0:
            raise RecordingError(f"--frames-eps: must be > 0, got {self.frames_eps}")
        if self.spacing not in SPACINGS:
            raise RecordingError(f"--spacing: expected time or path, got {self.spacing!r}")
        if self.mosaic not in MOSAICS:
            raise RecordingError(f"--sensor: expected one of {', '.join(MOSAICS)}, got "
                                 f"{self.mosaic!r}")
        if self.threshold is not None and not self.threshold > 0:
            raise RecordingError(f"--threshold: must be > 0, got {self.threshold}")
        if self.start is not None and self.end is not None and self.end <= self.start:
            raise RecordingError(f"--end ({self.end}) must be after --start ({self.start})")
        if isinstance(self.clock_offset, str):
            if self.clock_offset != "auto":
                raise RecordingError(f"--clock-offset: expected seconds or auto, got "
                                     f"{self.clock_offset!r}")
        elif not np.isfinite(self.clock_offset):
            raise RecordingError("--clock-offset: not a finite number")
        if self.max_gap is not None and not self.max_gap >= 0:
            raise RecordingError(f"--max-gap: must be >= 0 seconds, got {self.max_gap}")


@dataclass
class Scan:
    """What the first pass found."""

    t_first_file: float = np.inf
    n_read: int = 0
    n_window: int = 0
    n_outside_track: int = 0
    n_kept: int = 0
    t_first: float = np.inf
    t_last: float = -np.inf
    t_last_file: float = -np.inf
    counts: np.ndarray | None = None  # (height, width) kept events per pixel
    hot: object = None  # HotPixels of the kept events, when they are left out


def _sensor_size(source: EventSource, calib: Calibration | None) -> tuple[int, int]:
    if calib is not None and source.size is not None and \
            (calib.width, calib.height) != tuple(source.size):
        raise RecordingError(
            f"{calib.source}: calibration is for a {calib.width}x{calib.height} image, but "
            f"{source.path} is from a {source.size[0]}x{source.size[1]} sensor")
    if calib is not None:
        return calib.width, calib.height
    if source.size is None:
        raise RecordingError(f"{source.path}: the file does not state the sensor size; give a "
                             "calibration with --calib")
    return source.size


def _scan(source: EventSource, track: PoseTrack, size: tuple[int, int],
          options: ConvertOptions, progress) -> Scan:
    """Pass 1: count the events to keep and their time span; check pixels and order."""
    scan = Scan()
    last_t = -np.inf
    w, h = size
    scan.counts = np.zeros(w * h, dtype=np.int64)
    for chunk in source.chunks():
        if len(chunk) == 0:
            continue
        if scan.n_read == 0:
            scan.t_first_file = float(chunk.t[0])
        if chunk.t[0] < last_t or np.any(np.diff(chunk.t) < 0):
            raise RecordingError(f"{source.path}: timestamps go backwards near event "
                                 f"{scan.n_read:,} (the file must be sorted by time)")
        last_t = float(chunk.t[-1])
        bad = (chunk.x < 0) | (chunk.x >= w) | (chunk.y < 0) | (chunk.y >= h)
        if bad.any():
            k = int(np.argmax(bad))
            raise RecordingError(
                f"{source.path}: event {scan.n_read + k:,} at pixel ({chunk.x[k]}, "
                f"{chunk.y[k]}) lies outside the {w}x{h} sensor")
        scan.n_read += len(chunk)
        keep = _in_window(chunk.t, options)
        scan.n_window += int(keep.sum())
        inside = track.covers(chunk.t + options.clock_offset)
        scan.n_outside_track += int((keep & ~inside).sum())
        keep &= inside
        n = int(keep.sum())
        if n:
            scan.n_kept += n
            scan.counts += np.bincount(chunk.y[keep].astype(np.int64) * w + chunk.x[keep],
                                       minlength=w * h)
            kept_t = chunk.t[keep]
            scan.t_first = min(scan.t_first, float(kept_t[0]))
            scan.t_last = max(scan.t_last, float(kept_t[-1]))
        progress(len(chunk))
    scan.t_last_file = last_t
    scan.counts = scan.counts.reshape(h, w)
    if scan.n_read == 0:
        raise RecordingError(f"{source.path}: no events")
    if scan.n_window == 0:
        raise RecordingError(
            f"{source.path}: no events between --start and --end (the events run from "
            f"{scan.t_first_file:.6f} to {last_t:.6f} s)")
    if scan.n_kept < 2 or not scan.t_last > scan.t_first:
        raise RecordingError(
            f"{track.source}: the pose track ({track.t[0]:.6f}..{track.t[-1]:.6f} s) does not "
            f"cover the events ({scan.t_first_file + options.clock_offset:.6f}.."
            f"{last_t + options.clock_offset:.6f} s on the pose clock; wrong --clock-offset "
            "or time unit?)")
    return scan


def _in_window(t: np.ndarray, options: ConvertOptions) -> np.ndarray:
    keep = np.ones(t.shape[0], bool)
    if options.start is not None:
        keep &= t >= options.start
    if options.end is not None:
        keep &= t <= options.end
    return keep


class _ColumnWriter:
    """One ``.npy`` file of a known length, filled chunk by chunk."""

    def __init__(self, path: Path, dtype: np.dtype, n: int) -> None:
        self.path, self.dtype, self.n, self.filled = path, np.dtype(dtype), n, 0
        self.file = open(path, "wb")
        header = {"descr": np.lib.format.dtype_to_descr(self.dtype), "fortran_order": False,
                  "shape": (n,)}
        np.lib.format.write_array_header_2_0(self.file, header)

    def write(self, values: np.ndarray) -> None:
        self.file.write(np.ascontiguousarray(values, dtype=self.dtype).tobytes())
        self.filled += values.shape[0]

    def close(self) -> None:
        self.file.close()
        if self.filled != self.n:
            raise RecordingError(f"{self.path}: wrote {self.filled} of {self.n} values (the "
                                 "recording changed between passes?)")


def _write_events(source: EventSource, track: PoseTrack, scan: Scan, times: np.ndarray,
                  options: ConvertOptions, out: Path, progress) -> int:
    """Pass 2: the kept events, times in view units, into ``out`` (an npz)."""
    cols = {"x": np.int16, "y": np.int16, "t": np.float64, "p": np.int8}
    writers = {k: _ColumnWriter(out.parent / f".{k}.npy", d, scan.n_kept)
               for k, d in cols.items()}
    index = np.arange(times.shape[0], dtype=np.float64)
    n_pos = 0
    try:
        for chunk in source.chunks():
            if len(chunk) == 0:
                continue
            keep = _in_window(chunk.t, options)
            keep &= track.covers(chunk.t + options.clock_offset)
            if scan.hot is not None:
                keep &= ~scan.hot.mask[chunk.y, chunk.x]
            part = chunk.select(keep)
            if len(part) == 0:
                progress(len(chunk))
                continue
            writers["x"].write(part.x)
            writers["y"].write(part.y)
            writers["t"].write(np.interp(part.t, times, index))
            writers["p"].write(np.where(part.on, 1, -1))
            n_pos += int(part.on.sum())
            progress(len(chunk))
    finally:
        for w in writers.values():
            w.file.close()
    for w in writers.values():
        w.close()
    with zipfile.ZipFile(out, "w", compression=zipfile.ZIP_STORED, allowZip64=True) as zf:
        for k, w in writers.items():
            zf.write(w.path, arcname=f"{k}.npy")
            w.path.unlink()
        # The last view's time, which the last event need not reach (see docs/data.md).
        buf = io.BytesIO()
        np.save(buf, np.array([times.shape[0] - 1], dtype=np.float64))
        zf.writestr("t_end.npy", buf.getvalue())
    return n_pos


#: What a conversion writes in its output folder (``check/``: ``convert --check``'s pictures).
WRITTEN = frozenset({"scene.json", "train", "check"})


def check_replaceable(out: Path) -> None:
    """Refuse an output folder that a conversion would replace but did not write: the
    folder is replaced whole, so other files in it would be lost.

    Raises:
        RecordingError: ``out`` is a file, or a folder holding other files.
    """
    from hybridneus.errors import OutputError
    from hybridneus.fileio import check_output

    try:
        check_output(out, folder=True)
    except OutputError as exc:
        raise RecordingError(str(exc)) from None
    if not out.is_dir():
        return
    names = sorted(p.name for p in out.iterdir())
    if names and not (set(names) <= WRITTEN and (out / "scene.json").is_file()):
        raise RecordingError(f"{out}: holds files a conversion did not write ("
                             f"{', '.join(names[:3])}{', ...' if len(names) > 3 else ''}); the "
                             "folder is replaced whole, so give a new or empty one")


def convert_recording(
    source: EventSource,
    track: PoseTrack,
    calib: Calibration | None,
    out: str | Path,
    options: ConvertOptions,
    progress: bool = True,
) -> dict:
    """Write ``out`` as an EventNeRF-layout dataset (one ``train`` split) with ``scene.json``.

    Returns:
        The ``scene.json`` document.

    Raises:
        RecordingError: the inputs do not fit together (sizes, clocks, pixels, order);
            nothing is left in ``out``.
    """
    from hybridneus.progress import make_progress

    options.check()
    rows = getattr(track, "rows", None)
    for line in rows.warnings(track.source) if rows is not None else []:
        logging.getLogger("hybridneus").warning(line)
    out = Path(out)
    check_replaceable(out)
    size = _sensor_size(source, calib)
    if calib is None:
        raise RecordingError(f"{source.path}: a calibration is needed (--calib) for the "
                             "camera's intrinsics")
    if calib.distorted:
        check_lens(calib, size)
    estimate = None
    if options.clock_offset == "auto":
        from dataclasses import replace

        from hybridneus.recordings.clock import estimate_clock_offset

        estimate = estimate_clock_offset(source, track, float(calib.K[0, 0]))
        logging.getLogger("hybridneus").info(f"{track.source}: {estimate.line()}")
        options = replace(options, clock_offset=estimate.offset)
    frames = None
    if options.views == "frames":
        from dataclasses import replace

        from hybridneus.recordings.frames import frames_for_views, read_frames

        kept = read_frames(source.path, size, getattr(source, "time_unit", None))
        frames = frames_for_views(kept, track, options.start, options.end,
                                  options.clock_offset, source.path)
        options = replace(options, views=len(frames), start=frames[0].t, end=frames[-1].t)
    with make_progress("events", disable=not progress) as bar:
        task = bar.add_task("scan", total=getattr(source, "n_events", None))
        scan = _scan(source, track, size, options,
                     lambda n: bar.advance(task, n))
        if not options.keep_hot_pixels:
            from hybridneus.data.hot import find_hot_pixels

            hot = find_hot_pixels(scan.counts)
            if hot.n:
                scan.hot = hot
                scan.n_kept -= hot.events
                logging.getLogger("hybridneus").warning(
                    f"{source.path}: {hot.line()}; left out (--keep-hot-pixels keeps them)")
        t0 = scan.t_first if options.start is None else options.start
        t1 = scan.t_last if options.end is None else options.end
        if not (track.covers(np.array([t0, t1]) + options.clock_offset).all()):
            raise RecordingError(
                f"{track.source}: the pose track does not cover the views' span "
                f"{t0:.6f}..{t1:.6f} s (+ clock offset {options.clock_offset:g} s); "
                "narrow --start/--end")
        times = (np.array([f.t for f in frames]) if frames is not None else
                 view_times(track, t0, t1, options.views, options.spacing,
                            options.clock_offset))
        check_dropouts(track, times + options.clock_offset, options.max_gap)
        c2w_rec = track.at(times + options.clock_offset)
        frame = fit_frame(c2w_rec, up=options.up, box=options.box)
        c2w = frame.poses_to_normalised(c2w_rec)
        cyclic = closes_loop(c2w) if options.cyclic is None else options.cyclic
        with atomic_dir(out) as tmp:
            split = tmp / "train"
            for sub in ("pose", "intrinsics", "events"):
                (split / sub).mkdir(parents=True)
            task2 = bar.add_task("write", total=scan.n_read)
            n_pos = _write_events(source, track, scan, times, options,
                                  split / "events" / "events.npz",
                                  lambda n: bar.advance(task2, n))
            K4 = np.eye(4)
            K4[:3, :3] = calib.layout_K()
            digits = max(5, len(str(options.views - 1)))
            for i in range(options.views):
                name = f"r_{i:0{digits}d}.txt"
                np.savetxt(split / "pose" / name, c2w[i].reshape(1, 16), fmt="%.10g")
                np.savetxt(split / "intrinsics" / name, K4.reshape(1, 16), fmt="%.10g")
            if frames is not None:
                from hybridneus.recordings.frames import write_frames

                write_frames(frames, split / "rgb", digits)
            found = None
            if options.threshold is None:
                from hybridneus.recordings.frame_threshold import frames_threshold

                found = frames_threshold(source, size, times, frame, track, options,
                                          split / "events" / "events.npz")
            doc = scene_document(source, track, calib, options, scan, times, frame, cyclic,
                                 n_pos, size, estimate, frames, found)
            (tmp / "scene.json").write_text(json.dumps(doc, indent=2) + "\n")
    return doc

