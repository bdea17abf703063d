"""What every event reader yields: chunks of events, a source's header, and the helpers
they share (optional imports, polarity conventions)."""

from __future__ import annotations

import importlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hybridneus.errors import RecordingError

#: Events per chunk a reader yields (about 50 MB of temporaries per chunk).
CHUNK = 1 << 22

#: Seconds per tick of each clock a file may use.
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}

#: Extra to install, by the module a reader imports.
EXTRAS = {"faery": "faery", "h5py": "hdf5", "hdf5plugin": "hdf5", "rosbags": "rosbags",
          "pycolmap": "colmap", "dv_processing": "recordings"}


@dataclass
class EventChunk:
    """A run of consecutive events.

    Attributes:
        t: (n,) float64 seconds on the recording's clock.
        x: (n,) int32 pixel column.
        y: (n,) int32 pixel row.
        on: (n,) bool polarity (True: brightness went up).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    on: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])

    def select(self, keep: np.ndarray) -> EventChunk:
        """The events where ``keep`` (bool mask or index array) says so."""
        return EventChunk(self.t[keep], self.x[keep], self.y[keep], self.on[keep])

    @classmethod
    def concatenate(cls, chunks: list[EventChunk]) -> EventChunk:
        """One chunk of ``chunks`` (non-empty list) in order."""
        columns = ("t", "x", "y", "on")
        return cls(*(np.concatenate([getattr(c, k) for c in chunks]) for k in columns))


def need(module: str, path: Path, what: str):
    """Import an optional reader, or fail with the extra that installs it."""
    try:
        return importlib.import_module(module)
    except ImportError:
        extra = EXTRAS.get(module, module)
        raise RecordingError(
            f"{path}: reading {what} needs the {module} package: "
            f"pip install -e \".[{extra}]\" in the hybridneus folder"
        ) from None


def polarity_on(p: np.ndarray, path: Path) -> np.ndarray:
    """Polarity in any common convention (bool, 0/1, -1/+1) as bool ``on``."""
    if p.dtype == np.bool_:
        return p
    if p.size == 0:
        return np.zeros(0, bool)
    lo, hi = p.min(), p.max()
    if lo < -1 or hi > 1 or (lo == -1 and np.any(p == 0)):
        raise RecordingError(
            f"{path}: polarity values outside 0/1 and -1/+1 (min {lo}, max {hi})"
        )
    return p > 0


class EventSource:
    """A recording's events: ``size`` from the file's header where it has one, and chunks.

    Attributes:
        path: the file or folder.
        format: short name of the format, e.g. ``"aedat4"``, ``"hdf5 (DSEC layout)"``.
        size: (width, height) from the header, or None.
        time_unit: the unit the file's timestamps were read in (``s``, ``ms``, ``us``, ``ns``).
        note: how the reader interpreted the file, for the user.
    """

    path: Path
    format: str = ""
    size: tuple[int, int] | None = None
    time_unit: str = "us"
    note: str = ""

    def chunks(self) -> Iterator[EventChunk]:  # pragma: no cover - every reader overrides
        raise NotImplementedError


def first_line(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return text.splitlines()[0]
