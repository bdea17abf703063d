"""Event streams from the files cameras and datasets write, read in chunks.

Every reader yields :class:`EventChunk` s in file order: ``t`` in seconds on the recording's
own clock, ``x`` (column) and ``y`` (row) as int32, ``on`` as bool. Nothing here holds more
than one chunk of a file in memory (npz archives excepted: numpy reads a member whole), so a
recording of 10^9 events converts in bounded memory.

=====================  ======================================  =================================
suffix                 format                                  reader (optional extra)
=====================  ======================================  =================================
``.aedat4``            iniVation DV (DAVIS346C, DVXplorer)     faery (extra ``faery``)
``.raw``               Prophesee EVT2 / EVT3                   faery
``.dat``               Prophesee DAT                           faery
``.es``                Event Stream                            faery
``.h5`` ``.hdf5``      DSEC / TUM-VIE: ``events/{x,y,t,p}``    h5py + hdf5plugin (``[hdf5]``)
                       rosbag_to_h5: ``events/{xs,ys,ts,ps}``
``.txt`` ``.csv``      text columns (``t x y p`` by default)   numpy
``.npz`` ``.npy``      arrays ``x y t p`` or a structured one  numpy
``.bag``, ROS 2 folder ``dvs_msgs/EventArray`` (ROS 1 and 2)   rosbags (``[rosbags]``)
=====================  ======================================  =================================

ROS bags are read by :mod:`hybridneus.recordings.bags`.
"""

from __future__ import annotations

import zipfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from hybridneus.errors import RecordingError
from hybridneus.recordings.bags import BAG_SUFFIXES, BagSource
from hybridneus.recordings.stream import (
    CHUNK,
    TIME_UNITS,
    EventChunk,
    EventSource,
    first_line,
    need,
    polarity_on,
)

FAERY_SUFFIXES = (".aedat4", ".raw", ".dat", ".es")
HDF5_SUFFIXES = (".h5", ".hdf5", ".hdf")
TEXT_SUFFIXES = (".txt", ".csv", ".tsv")
NUMPY_SUFFIXES = (".npz", ".npy")

def _seconds(t: np.ndarray, unit: str) -> np.ndarray:
    return t.astype(np.float64) * TIME_UNITS[unit]


def _compiled_fault(exc: BaseException) -> bool:
    """Whether ``exc`` is a compiled reader's failure on a bad file: any exception, or a
    Rust panic (pyo3's ``PanicException`` derives from ``BaseException``), but not an
    interrupt or a generator's close."""
    if isinstance(exc, KeyboardInterrupt | SystemExit | GeneratorExit):
        return False
    return isinstance(exc, Exception) or type(exc).__name__ == "PanicException"


class FaerySource(EventSource):
    """AEDAT4, Prophesee EVT2/EVT3 RAW, DAT and Event Stream files, decoded by faery."""

    def __init__(self, path: Path, track: int | None = None) -> None:
        self.path = path
        faery = need("faery", path, f"{path.suffix} files")
        self.format = path.suffix.lstrip(".").lower()
        try:
            stream = faery.events_stream_from_file(path, track_id=track)
            self.size = tuple(int(v) for v in stream.dimensions())
        except BaseException as exc:  # faery: RuntimeError/OSError, or a Rust panic
            if not _compiled_fault(exc):
                raise
            raise RecordingError(f"{path}: cannot read as {self.format} ({first_line(exc)})") \
                from None
        self._faery = faery
        self._track = track
        self.time_unit = "us"
        self.note = (f"{self.format}{'' if track is None else f' track {track}'}, "
                     f"{self.size[0]}x{self.size[1]} from the header, t in us")

    def chunks(self) -> Iterator[EventChunk]:
        try:
            stream = self._faery.events_stream_from_file(self.path, track_id=self._track)
            for packet in stream:
                if len(packet) == 0:
                    continue
                yield EventChunk(_seconds(packet["t"], "us"), packet["x"].astype(np.int32),
                                 packet["y"].astype(np.int32), packet["on"].astype(bool))
        except RecordingError:
            raise
        except BaseException as exc:
            if not _compiled_fault(exc):
                raise
            raise RecordingError(f"{self.path}: {self.format} decoding failed "
                                 f"({first_line(exc)})") from None


#: What h5py raises on a damaged file (besides its OSError for unreadable chunks).
H5_FAULTS = (OSError, KeyError, RuntimeError, ValueError, TypeError, IndexError)


#: HDF5 event layouts: the arrays' names (t, x, y, p order) and what to call the layout.
H5_LAYOUTS = (
    (("t", "x", "y", "p"), "DSEC/TUM-VIE layout"),
    (("ts", "xs", "ys", "ps"), "rosbag_to_h5 layout"),
)


class HDF5Source(EventSource):
    """HDF5 event files in two layouts, the arrays in an ``events`` group or at the top level:

    - DSEC and TUM-VIE: ``x, y, t, p``, ``t`` in microseconds plus an optional ``t_offset``;
    - the layout of events_contrast_maximization's ``rosbag_to_h5.py`` (event_cnn_minimal's
      input; with the camera's frames as ``images/image<nnnnnnnnn>``, see
      :mod:`hybridneus.recordings.frames`): ``xs, ys, ts, ps``, ``ts`` in seconds when it
      holds floats, microseconds when integers; ``sensor_resolution`` (height, width).

    Blosc/Zstd filters come from hdf5plugin. Prophesee's own HDF5 (``CD/events``, ECF codec)
    is refused with a pointer to its RAW file.
    """

    def __init__(self, path: Path, time_unit: str | None = None) -> None:
        self.path = path
        h5py = need("h5py", path, "HDF5 files")
        need("hdf5plugin", path, "compressed HDF5 files")
        try:
            self._file = h5py.File(path, "r")
        except OSError as exc:
            raise RecordingError(f"{path}: cannot open as HDF5 ({first_line(exc)})") from None
        try:
            self._layout(h5py, path, time_unit)
        except RecordingError:
            raise
        except H5_FAULTS as exc:
            raise RecordingError(f"{path}: damaged HDF5 file ({first_line(exc)})") from None

    def _layout(self, h5py, path: Path, time_unit: str | None) -> None:
        f = self._file
        if "CD" in f and "events" in f["CD"]:
            raise RecordingError(
                f"{path}: a Prophesee HDF5 file (CD/events, ECF codec), which hdf5plugin "
                "cannot decode; convert the camera's RAW file instead"
            )
        group = f["events"] if "events" in f and isinstance(f["events"], h5py.Group) else f
        names, layout = next(((n, name) for n, name in H5_LAYOUTS if n[0] in group),
                             H5_LAYOUTS[0])
        missing = [k for k in names if k not in group]
        if missing:
            raise RecordingError(
                f"{path}: no event arrays {'/'.join(missing)} (expected events/x, events/y, "
                "events/t, events/p as in DSEC and TUM-VIE, or events/xs, ys, ts, ps)"
            )
        self._cols = [group[k] for k in names]
        n = {c.shape[0] for c in self._cols}
        if len(n) != 1:
            raise RecordingError(f"{path}: event arrays differ in length ({sorted(n)})")
        self.n_events = n.pop()
        floats = self._cols[0].dtype.kind == "f"
        self.time_unit = time_unit or ("s" if floats and names[0] == "ts" else "us")
        offset = f.get("t_offset")
        self._offset = int(offset[()]) if offset is not None else 0
        self.format = f"hdf5 ({layout})"
        if "width" in f.attrs and "height" in f.attrs:
            self.size = (int(f.attrs["width"]), int(f.attrs["height"]))
        elif "sensor_resolution" in f.attrs:
            h, w = (int(v) for v in np.asarray(f.attrs["sensor_resolution"])[:2])
            self.size = (w, h)
        self.note = (f"{self.format}, {self.n_events:,} events, t in {self.time_unit}"
                     + (f" + t_offset {self._offset}" if self._offset else ""))

    def chunks(self) -> Iterator[EventChunk]:
        t_col, x_col, y_col, p_col = self._cols
        for s in range(0, self.n_events, CHUNK):
            e = min(s + CHUNK, self.n_events)
            try:
                t = t_col[s:e].astype(np.int64) + self._offset if t_col.dtype.kind in "iu" \
                    else t_col[s:e].astype(np.float64) + self._offset
                x, y, p = x_col[s:e], y_col[s:e], p_col[s:e]
            except H5_FAULTS as exc:
                raise RecordingError(
                    f"{self.path}: cannot decode events {s}..{e} ({first_line(exc)}; a "
                    "compression filter hdf5plugin lacks?)") from None
            yield EventChunk(_seconds(t, self.time_unit), x.astype(np.int32),
                             y.astype(np.int32), polarity_on(np.asarray(p), self.path))


class TextSource(EventSource):
    """Whitespace, comma, semicolon or tab separated columns; ``columns`` names their order
    (default ``t x y p``, the RPG event-camera dataset's), a header line is skipped, and
    ``#`` comments are ignored. Timestamps with a decimal point are read as seconds, integers
    as microseconds, unless ``time_unit`` says otherwise.
    """

    def __init__(self, path: Path, columns: str = "txyp", time_unit: str | None = None) -> None:
        self.path = path
        columns = columns.replace(",", "").replace(" ", "").lower()
        if sorted(columns) != sorted("txyp"):
            raise RecordingError(
                f"{path}: --columns must name t, x, y and p once each, got {columns!r}")
        self._order = {c: i for i, c in enumerate(columns)}
        self.format = "text"
        try:
            with open(path, "rb") as f:
                head = [line for line in (f.readline() for _ in range(50)) if line]
        except OSError as exc:
            raise RecordingError(f"{path}: cannot read ({exc.strerror})") from None
        rows = [r for r in (_split(line) for line in head) if r]
        numeric = [r for r in rows if _numbers(r) is not None]
        if not numeric:
            raise RecordingError(f"{path}: no rows of numbers in the first 50 lines")
        if len(numeric[0]) < 4:
            raise RecordingError(
                f"{path}: rows have {len(numeric[0])} columns, expected at least 4 (t x y p)")
        self._ncols = len(numeric[0])
        self._header = len(rows) > 0 and _numbers(rows[0]) is None
        t_text = numeric[0][self._order["t"]]
        self.time_unit = time_unit or ("s" if b"." in t_text or b"e" in t_text.lower() else "us")
        assumed = "" if time_unit else " (assumed from the first row; set --time-unit)"
        self.note = f"text, columns {' '.join(columns)}, t in {self.time_unit}{assumed}"

    def chunks(self) -> Iterator[EventChunk]:
        with open(self.path, "rb") as f:
            lineno = 0
            while True:
                lines = f.readlines(1 << 24)
                if not lines:
                    break
                start = lineno
                lineno += len(lines)
                if start == 0 and self._header:
                    lines = lines[1:]
                body = b"".join(line for line in lines if not line.lstrip().startswith(b"#"))
                for sep in (b",", b";", b"\t"):
                    body = body.replace(sep, b" ")
                try:
                    values = np.array(body.split(), dtype=np.float64) if body.strip() else \
                        np.zeros(0)
                except ValueError:
                    raise RecordingError(f"{self.path}: lines {start + 1}..{lineno} hold a "
                                         "value that is not a number") from None
                if values.size % self._ncols:
                    raise RecordingError(
                        f"{self.path}: lines {start + 1}..{lineno} do not all have "
                        f"{self._ncols} columns")
                rows = values.reshape(-1, self._ncols)
                if not np.isfinite(rows).all():
                    raise RecordingError(f"{self.path}: a value in lines {start + 1}..{lineno} "
                                         "is not a finite number")
                o = self._order
                yield EventChunk(rows[:, o["t"]] * TIME_UNITS[self.time_unit],
                                 rows[:, o["x"]].astype(np.int32),
                                 rows[:, o["y"]].astype(np.int32),
                                 polarity_on(rows[:, o["p"]], self.path))


class NumpySource(EventSource):
    """An npz with arrays ``x y t p`` (EventNeRF's own), or an npy holding a structured
    array with fields ``t x y`` and ``p`` or ``on`` (faery's and Prophesee's dtype).
    Floating-point timestamps are read as seconds, integers as microseconds, unless
    ``time_unit`` says otherwise.
    """

    def __init__(self, path: Path, time_unit: str | None = None) -> None:
        self.path = path
        self.format = path.suffix.lstrip(".")
        try:
            if path.suffix == ".npy":
                arr = np.load(path, mmap_mode="r", allow_pickle=False)
                names = arr.dtype.names or ()
                if not {"t", "x", "y"} <= set(names) or not ({"p", "on"} & set(names)):
                    raise RecordingError(
                        f"{path}: expected a structured array with fields t, x, y and p (or "
                        f"on), found {list(names) or f'a plain {arr.dtype} array'}")
                self._cols = {k: arr[k] for k in ("t", "x", "y")}
                self._cols["p"] = arr["p" if "p" in names else "on"]
            else:
                with zipfile.ZipFile(path) as zf:
                    keys = {n[:-4] for n in zf.namelist() if n.endswith(".npy")}
                missing = [k for k in ("x", "y", "t", "p") if k not in keys]
                if missing:
                    raise RecordingError(f"{path}: missing array(s) {', '.join(missing)} "
                                         f"(found {sorted(keys)})")
                data = np.load(path, allow_pickle=False)
                self._cols = {k: data[k].reshape(-1) for k in ("t", "x", "y", "p")}
        except RecordingError:
            raise
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
            raise RecordingError(f"{path}: cannot read ({first_line(exc)})") from None
        lengths = {v.shape[0] for v in self._cols.values()}
        if len(lengths) != 1:
            raise RecordingError(f"{path}: arrays differ in length ({sorted(lengths)})")
        self.n_events = lengths.pop()
        t_float = self._cols["t"].dtype.kind == "f"
        self.time_unit = time_unit or ("s" if t_float else "us")
        assumed = "" if time_unit else " (from the dtype; set --time-unit)"
        self.note = f"{self.format}, {self.n_events:,} events, t in {self.time_unit}{assumed}"

    def chunks(self) -> Iterator[EventChunk]:
        c = self._cols
        for s in range(0, self.n_events, CHUNK):
            e = min(s + CHUNK, self.n_events)
            yield EventChunk(_seconds(np.asarray(c["t"][s:e]), self.time_unit),
                             np.asarray(c["x"][s:e]).astype(np.int32),
                             np.asarray(c["y"][s:e]).astype(np.int32),
                             polarity_on(np.asarray(c["p"][s:e]), self.path))


def _split(line: bytes) -> list[bytes]:
    line = line.strip()
    if not line or line.startswith(b"#"):
        return []
    for sep in (b",", b";", b"\t"):
        line = line.replace(sep, b" ")
    return line.split()


def _numbers(row: list[bytes]) -> list[float] | None:
    try:
        return [float(v) for v in row]
    except ValueError:
        return None


def open_events(
    path: str | Path,
    *,
    time_unit: str | None = None,
    columns: str = "txyp",
    topic: str | None = None,
    track: int | None = None,
) -> EventSource:
    """Open a recording's events by its suffix.

    Args:
        path: the recording.
        time_unit: the unit of the file's timestamps (``s``, ``ms``, ``us``, ``ns``) where
            the format does not fix it; None: the format's convention, or a guess (printed).
        columns: order of the columns of a text file, e.g. ``"txyp"`` or ``"xytp"``.
        topic: the event topic of a ROS bag that holds several.
        track: the events track (stream id) of an AEDAT4 file that holds several; None:
            the first.

    Raises:
        RecordingError: an unknown suffix, a missing reader, or a file the reader refuses.
    """
    path = Path(path)
    if time_unit is not None and time_unit not in TIME_UNITS:
        raise RecordingError(f"--time-unit: expected one of {', '.join(TIME_UNITS)}, "
                             f"got {time_unit!r}")
    if not path.exists():
        raise RecordingError(f"{path}: no such file or folder")
    suffix = path.suffix.lower()
    if path.is_dir():
        if (path / "metadata.yaml").is_file():
            return BagSource(path, topic=topic)
        raise RecordingError(f"{path}: a folder without a ROS 2 bag's metadata.yaml, "
                             "expected an event file")
    if path.stat().st_size == 0:  # some readers take nothing for a default header
        raise RecordingError(f"{path}: empty file (0 bytes)")
    if suffix in BAG_SUFFIXES:
        return BagSource(path, topic=topic)
    if track is not None and suffix != ".aedat4":
        raise RecordingError(f"--track: applies to AEDAT4 files, not {path.name}")
    if suffix in FAERY_SUFFIXES:
        return FaerySource(path, track=track)
    if suffix in HDF5_SUFFIXES:
        return HDF5Source(path, time_unit=time_unit)
    if suffix in TEXT_SUFFIXES:
        return TextSource(path, columns=columns, time_unit=time_unit)
    if suffix in NUMPY_SUFFIXES:
        return NumpySource(path, time_unit=time_unit)
    known = FAERY_SUFFIXES + HDF5_SUFFIXES + TEXT_SUFFIXES + NUMPY_SUFFIXES + BAG_SUFFIXES
    raise RecordingError(f"{path}: unknown event file type {suffix or '(no suffix)'!r} "
                         f"(known: {' '.join(known)})")


__all__ = ["EventChunk", "EventSource", "open_events", "polarity_on", "TIME_UNITS"]
