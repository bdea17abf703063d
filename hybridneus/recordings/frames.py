"""The camera's own frames in a recording: a DAVIS's APS frames beside its events.

A DAVIS346 records intensity frames (its active pixel sensor) into the same AEDAT4 file as
its events, on the same clock. ``convert --views frames`` places one view at each frame (the
middle of its exposure) and writes the frames as the split's ``rgb/`` files, so that the
contrast threshold can be taken from them (``estimate.threshold``) and ``--check`` pictures
can be compared with them. faery reads the frame track; DV stores colour frames already
demosaiced.

HDF5 files in the layout events_contrast_maximization's ``rosbag_to_h5.py`` writes hold the
frames beside the events: ``images/image000000000``, ... (uint8 or uint16, greyscale
or ``color_bgr`` as their ``type`` attribute says), each stamped by its ``timestamp``
attribute on the events' clock and in their unit. A greyscale frame of a colour sensor (its
raw Bayer values) serves as it is: each pixel keeps its own colour's value. These files carry
no exposure time.

An APS pixel's value is linear in the light it gathered, while the layout's ``rgb/`` files are
sRGB-encoded (the reader and the threshold estimate take ``c ** 2.2`` for the light), so the
frames are written as ``255 v ** (1 / 2.2)`` for ``v`` the value over its format's full scale
(8 or 16 bits). Frames of 8 bits hold the dark end coarsely (a step of one in 20 is a log
change of 0.05, a third of a DAVIS threshold); the threshold estimate reads low from them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hybridneus.errors import RecordingError
from hybridneus.recordings.stream import TIME_UNITS, first_line, need

#: The gamma the layout's ``rgb/`` files are encoded with.
GAMMA = 2.2


@dataclass(frozen=True)
class ApsFrame:
    """One frame.

    Attributes:
        t: seconds on the event clock, the middle of the exposure.
        image: (height, width, 3) float32 in [0, 1], linear in the light (the sensor's value
            over its format's full scale).
        exposure: the exposure's length, seconds.
        bits: the bits per value the frame was stored with (8 or 16).
    """

    t: float
    image: np.ndarray
    exposure: float
    bits: int = 8


def read_frames(path: str | Path, size: tuple[int, int], time_unit: str | None = None,
                span: tuple[float, float] | None = None) -> list[ApsFrame]:
    """The camera's frames in a recording, in time order: the first frame track of an AEDAT4
    file, or the ``images`` group of an HDF5 file.

    Args:
        path: the recording.
        size: (width, height) of the sensor; a frame of another size (a region of interest)
            is refused.
        time_unit: the unit of an HDF5 file's stamps (its events'); None: seconds where the
            stamps are floats, else microseconds.
        span: (first, last) event-clock seconds: only the frames whose time lies within are
            kept (the others are not decoded into memory); None: all.

    Raises:
        RecordingError: the file holds no frames, or a frame does not cover the sensor.
    """
    frames, _ = _read(Path(path), size, time_unit, span)
    return frames


def frame_times(path: str | Path, size: tuple[int, int],
                time_unit: str | None = None) -> np.ndarray:
    """(n,) the event-clock seconds of every frame in a recording, sorted, without keeping
    their pixels (:func:`read_frames` for the arguments and errors)."""
    return _read(Path(path), size, time_unit, (np.inf, -np.inf))[1]


def holds_frames(path: str | Path) -> bool:
    """Whether a recording's format can hold frames and the file holds some."""
    path = Path(path)
    suffix = path.suffix.lower()
    try:
        if suffix == ".aedat4":
            import faery

            with faery.aedat.Decoder(path) as decoder:
                return any(t.data_type == "frame" for t in decoder.tracks())
        if suffix in (".h5", ".hdf5", ".hdf"):
            import h5py

            with h5py.File(path, "r") as f:
                group = f.get("images")
                return isinstance(group, h5py.Group) and len(group) > 0
    except Exception:  # unreadable here: the events' reader says why
        return False
    return False


def _read(path: Path, size: tuple[int, int], time_unit: str | None,
          span: tuple[float, float] | None) -> tuple[list[ApsFrame], np.ndarray]:
    suffix = path.suffix.lower()

    def keep(t: float) -> bool:
        return span is None or span[0] <= t <= span[1]

    if suffix in (".h5", ".hdf5", ".hdf"):
        frames, times = _hdf5_frames(path, size, time_unit, keep)
    elif suffix == ".aedat4":
        frames, times = _aedat4_frames(path, size, keep)
    else:
        raise RecordingError(f"{path}: --views frames needs the camera's frames, which only "
                             "AEDAT4 (iniVation DV) and HDF5 files hold here")
    frames.sort(key=lambda f: f.t)
    return frames, np.sort(np.asarray(times, dtype=np.float64))


def _hdf5_frames(path: Path, size: tuple[int, int], time_unit: str | None,
                 keep) -> tuple[list[ApsFrame], list[float]]:
    from hybridneus.recordings.events import H5_FAULTS

    h5py = need("h5py", path, "HDF5 files")
    need("hdf5plugin", path, "compressed HDF5 files")
    frames, times = [], []
    try:
        with h5py.File(path, "r") as f:
            group = f.get("images")
            if not isinstance(group, h5py.Group) or not len(group):
                raise RecordingError(f"{path}: no frames (expected images/image000000000, ... "
                                     "with a timestamp attribute)")
            for name in sorted(group):
                dset = group[name]
                if "timestamp" not in dset.attrs:
                    raise RecordingError(f"{path}: images/{name} has no timestamp attribute")
                stamp = np.asarray(dset.attrs["timestamp"]).reshape(-1)[0]
                unit = time_unit or ("s" if stamp.dtype.kind == "f" else "us")
                t = float(stamp) * TIME_UNITS[unit]
                times.append(t)
                if not keep(t):
                    continue
                pixels = np.asarray(dset[()])
                kind = dset.attrs.get("type", "")
                if isinstance(kind, bytes):
                    kind = kind.decode()
                if pixels.ndim == 3 and kind == "color_bgr":
                    pixels = pixels[..., ::-1]
                frames.append(_as_frame(pixels, t, 0.0, size, path, (0, 0)))
    except RecordingError:
        raise
    except H5_FAULTS as exc:
        raise RecordingError(f"{path}: reading its frames failed ({first_line(exc)})") from None
    return frames, times


def _aedat4_frames(path: Path, size: tuple[int, int],
                   keep) -> tuple[list[ApsFrame], list[float]]:
    faery = need("faery", path, ".aedat4 files")
    frames: list[ApsFrame] = []
    times: list[float] = []
    try:
        with faery.aedat.Decoder(path) as decoder:
            tracks = [t for t in decoder.tracks() if t.data_type == "frame"]
            if not tracks:
                raise RecordingError(f"{path}: no frame track (tracks: "
                                     f"{', '.join(t.data_type for t in decoder.tracks())})")
            wanted = tracks[0].id
            for track, packet in decoder:
                if track.id != wanted:
                    continue
                start, end = packet.exposure_start_t, packet.exposure_end_t
                t = (0.5 * (start + end) if end > start else packet.t) * 1e-6
                times.append(t)
                if keep(t):
                    frames.append(_as_frame(np.asarray(packet.pixels), t,
                                            max(0.0, float(end - start) * 1e-6), size, path,
                                            (packet.offset_x, packet.offset_y)))
    except RecordingError:
        raise
    except Exception as exc:  # faery raises its own errors on a damaged file
        raise RecordingError(f"{path}: reading its frames failed ({first_line(exc)})") from None
    if not times:
        raise RecordingError(f"{path}: the frame track holds no frames")
    return frames, times


def _as_frame(pixels: np.ndarray, t: float, exposure: float, size: tuple[int, int],
              path: Path, offset: tuple[int, int]) -> ApsFrame:
    """A frame from its stored values: (h, w) or (h, w, channels) RGB, uint8 or uint16."""
    if pixels.dtype not in (np.uint8, np.uint16):
        raise RecordingError(f"{path}: a frame holds {pixels.dtype} values, expected 8 or "
                             "16-bit unsigned")
    bits = 16 if pixels.dtype == np.uint16 else 8
    if pixels.ndim == 2 or pixels.shape[-1] == 1:
        pixels = np.repeat(pixels.reshape(pixels.shape[:2] + (1,)), 3, axis=2)
    pixels = pixels[..., :3]
    h, w = pixels.shape[:2]
    if (w, h) != tuple(size) or any(offset):
        raise RecordingError(f"{path}: a frame covers {w}x{h} at ({offset[0]}, {offset[1]}), "
                             f"not the {size[0]}x{size[1]} sensor")
    image = (pixels.astype(np.float32) / float(2**bits - 1)).astype(np.float32)
    return ApsFrame(t=t, image=image, exposure=exposure, bits=bits)


def frames_for_views(frames: list[ApsFrame], track, start: float | None, end: float | None,
                     clock_offset: float, path: Path) -> list[ApsFrame]:
    """The frames a view can sit at: inside ``[start, end]`` (event clock; None: open) and
    inside the pose track (at event time plus ``clock_offset``), one per time.

    Raises:
        RecordingError: fewer than two are left.
    """
    t = np.array([f.t for f in frames])
    keep = track.covers(t + clock_offset) & np.r_[True, np.diff(t) > 0]
    if start is not None:
        keep &= t >= start
    if end is not None:
        keep &= t <= end
    kept = [f for f, k in zip(frames, keep, strict=True) if k]
    if len(kept) < 2:
        raise RecordingError(f"{path}: {len(kept)} of its {len(t)} frames lie inside the pose "
                             "track and --start/--end; --views frames needs at least 2")
    return kept


def write_frames(frames: list[ApsFrame], folder: Path, digits: int) -> None:
    """The frames as the split's ``rgb/r_<i>.png`` files, sRGB-encoded."""
    from PIL import Image

    folder.mkdir()
    for i, f in enumerate(frames):
        Image.fromarray(encode_srgb(f.image)).save(folder / f"r_{i:0{digits}d}.png")


def encode_srgb(image: np.ndarray) -> np.ndarray:
    """(h, w, 3) linear values in [0, 1] as the layout's sRGB-encoded uint8 ones."""
    return np.round(255.0 * np.clip(image, 0.0, 1.0) ** (1.0 / GAMMA)).astype(np.uint8)


__all__ = ["ApsFrame", "encode_srgb", "frame_times", "frames_for_views", "holds_frames",
           "read_frames", "write_frames"]
