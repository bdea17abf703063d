"""What a pose track's rows hold as a tracker writes them: occluded rows, repeated stamps, gaps.

Motion-capture systems write a row of NaN (or empty cells, or zeros) for a frame where the
markers were hidden; loggers write a stamp twice when two messages arrive in one tick; and a
tracker that loses the body leaves a stretch with no rows at all. The first two are dropped
here and counted; a gap longer than :data:`DROPOUT_INTERVALS` of the track's usual sample
interval is a *dropout*, kept in the report with its span so that a conversion can refuse to
place a view inside it unless the user allows interpolation across it (``--max-gap``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: A gap between two samples longer than this many median sample intervals is a dropout.
DROPOUT_INTERVALS = 4.0


@dataclass(frozen=True)
class Dropout:
    """A stretch of the pose clock with no sample.

    Attributes:
        start: seconds of the last sample before it.
        end: seconds of the first sample after it.
        missing: samples the track's median rate would have put inside it.
    """

    start: float
    end: float
    missing: int

    @property
    def length(self) -> float:
        return self.end - self.start

    def describe(self) -> str:
        return (f"no pose for {self.length:.3f} s ({self.start:.6f}..{self.end:.6f} s, about "
                f"{self.missing} samples missing)")


@dataclass
class RowReport:
    """What cleaning a track's rows found.

    Attributes:
        occluded: rows dropped for a non-finite value (NaN, an empty cell) or a zero
            quaternion, which is how motion capture marks a lost body.
        repeated: rows dropped because their stamp repeats the previous row's.
        dropouts: gaps longer than :data:`DROPOUT_INTERVALS` sample intervals.
    """

    occluded: int = 0
    repeated: int = 0
    dropouts: list[Dropout] = field(default_factory=list)

    def warnings(self, source: str) -> list[str]:
        """One line per finding, each naming ``source``."""
        lines = []
        if self.occluded:
            lines.append(f"{source}: {self.occluded} occluded row(s) (NaN, empty or zero "
                         "quaternion) dropped")
        if self.repeated:
            lines.append(f"{source}: {self.repeated} row(s) with a repeated timestamp dropped "
                         "(the first of each kept)")
        lines += [f"{source}: {d.describe()}" for d in self.dropouts]
        return lines

    def to_json(self) -> dict:
        return {"occluded_rows": self.occluded, "repeated_stamps": self.repeated,
                "dropouts_s": [[d.start, d.end] for d in self.dropouts]}


def clean_rows(t: np.ndarray, quat: np.ndarray, position: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, RowReport]:
    """Drop occluded rows and repeated stamps.

    Args:
        t: (n,) stamps.
        quat: (n, 4) quaternions.
        position: (n, 3) positions.

    Returns:
        ``(t, quat, position, report)`` of the rows kept (the report's ``dropouts`` empty:
        :func:`find_dropouts` fills it once the stamps are in seconds and checked).
        Stamps that go backwards are kept, for the track's own check to name them.
    """
    t = np.asarray(t, dtype=np.float64)
    quat = np.asarray(quat, dtype=np.float64)
    position = np.asarray(position, dtype=np.float64)
    finite = np.isfinite(t) & np.isfinite(quat).all(axis=1) & np.isfinite(position).all(axis=1)
    occluded = ~finite | (np.linalg.norm(np.nan_to_num(quat), axis=1) < 1e-6)
    keep = ~occluded
    kept = np.flatnonzero(keep)
    repeated = np.zeros_like(keep)
    repeated[kept[1:][np.diff(t[kept]) == 0]] = True
    keep &= ~repeated
    report = RowReport(occluded=int(occluded.sum()), repeated=int(repeated.sum()))
    return t[keep], quat[keep], position[keep], report


def find_dropouts(t: np.ndarray) -> list[Dropout]:
    """Gaps of strictly increasing stamps ``t`` (seconds) longer than
    :data:`DROPOUT_INTERVALS` median sample intervals."""
    if t.shape[0] < 3:
        return []
    step = np.diff(t)
    usual = float(np.median(step))
    long = np.flatnonzero(step > DROPOUT_INTERVALS * usual)
    return [Dropout(float(t[k]), float(t[k + 1]), int(round(step[k] / usual)) - 1)
            for k in long]


__all__ = ["DROPOUT_INTERVALS", "Dropout", "RowReport", "clean_rows", "find_dropouts"]
