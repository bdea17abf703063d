"""Reading and checking one events npz: ``x`` (column), ``y`` (row), ``t``, ``p``.

Real recordings hold tens of millions of events, so everything here is vectorised and each
array is converted to its final dtype exactly once (``x``/``y`` int16, ``t`` float64, ``p``
int8 in {-1, +1}); checks that need temporaries run over chunks so that peak memory stays
near the size of the loaded arrays.
"""

from __future__ import annotations

import logging
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hybridneus.errors import DatasetError

log = logging.getLogger(__name__)

EVENT_KEYS = ("x", "y", "t", "p")
_CHUNK = 1 << 22


@dataclass
class EventStream:
    """Events of one split, sorted by time.

    Attributes:
        x: (n_events,) int16, pixel column.
        y: (n_events,) int16, pixel row.
        t: (n_events,) float64, timestamps as stored (only ``t / t.max()`` matters).
        p: (n_events,) int8, polarity in {-1, +1} (0/1 files are converted on load).
        path: the npz file.
        polarity_note: how polarity was stored, e.g. ``"0/1 (converted to -1/+1)"``.
    """

    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    p: np.ndarray
    path: Path | None = None
    polarity_note: str = "-1/+1"
    _pixel_code: np.ndarray | None = field(default=None, repr=False)
    _code_width: int = field(default=0, repr=False)
    # Derived structures built on first use (e.g. the window counter of data.windows).
    cache: dict = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def t_max(self) -> float:
        """Largest timestamp: view i of N sits at ``i / (N - 1) * t_max``."""
        return float(self.t[-1]) if len(self) else 0.0

    @property
    def n_positive(self) -> int:
        """Number of +1 events."""
        return int(np.count_nonzero(self.p > 0))

    def pixel_code(self, width: int) -> np.ndarray:
        """(n_events,) int32 ``2 * (y * width + x) + (p > 0)``, computed once and cached.

        One unweighted ``bincount`` of a slice of this array gives the negative and positive
        counts of every pixel, from which any polarity offset can be applied afterwards.
        """
        if self._pixel_code is None or self._code_width != width:
            code = np.empty(len(self), dtype=np.int32)
            for s in range(0, len(self), _CHUNK):
                e = min(s + _CHUNK, len(self))
                c = self.y[s:e].astype(np.int32)
                c *= width
                c += self.x[s:e]
                c *= 2
                c += self.p[s:e] > 0
                code[s:e] = c
            self._pixel_code, self._code_width = code, width
        return self._pixel_code


def _as_int16_pixels(arr: np.ndarray, key: str, path: Path) -> np.ndarray:
    """Convert a pixel coordinate array to int16 once, refusing non-integral values."""
    if arr.dtype == np.bool_ or not (
        np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)
    ):
        raise DatasetError(f"{path}: key '{key}' has dtype {arr.dtype}, expected integers")
    if np.issubdtype(arr.dtype, np.floating):
        for s in range(0, arr.shape[0], _CHUNK):
            chunk = arr[s : s + _CHUNK]
            if not np.all(np.isfinite(chunk)):
                raise DatasetError(f"{path}: key '{key}' holds NaN or inf")
            if not np.all(chunk == np.floor(chunk)):
                raise DatasetError(f"{path}: key '{key}' holds non-integer pixel coordinates")
    if arr.shape[0]:
        lo, hi = arr.min(), arr.max()
        if lo < 0:
            raise DatasetError(
                f"{path}: pixels outside the image: {key} has negative values (min {lo})"
            )
        if hi > np.iinfo(np.int16).max:
            raise DatasetError(f"{path}: pixels outside the image: {key} max {hi} is too large")
    return arr.astype(np.int16, copy=False)


def _as_polarity(arr: np.ndarray, path: Path) -> tuple[np.ndarray, str]:
    """Convert polarity to int8 -1/+1, accepting -1/+1, 0/1 or booleans."""
    if arr.dtype == np.bool_:
        out = arr.astype(np.int8)
        out *= 2
        out -= 1
        return out, "boolean 0/1 (converted to -1/+1)"
    if not (np.issubdtype(arr.dtype, np.integer) or np.issubdtype(arr.dtype, np.floating)):
        raise DatasetError(f"{path}: key 'p' has dtype {arr.dtype}, expected numbers")
    n_zero = n_minus = n_plus = 0
    for s in range(0, arr.shape[0], _CHUNK):
        chunk = arr[s : s + _CHUNK]
        nz = int(np.count_nonzero(chunk == 0))
        nm = int(np.count_nonzero(chunk == -1))
        npl = int(np.count_nonzero(chunk == 1))
        if nz + nm + npl != chunk.shape[0]:
            bad = np.unique(chunk[(chunk != 0) & (chunk != 1) & (chunk != -1)])[:5]
            raise DatasetError(
                f"{path}: polarity values {bad.tolist()} are neither -1/+1 nor 0/1"
            )
        n_zero, n_minus, n_plus = n_zero + nz, n_minus + nm, n_plus + npl
    if n_zero and n_minus:
        raise DatasetError(
            f"{path}: polarity holds -1, 0 and +1 values; expected either -1/+1 or 0/1"
        )
    out = arr.astype(np.int8, copy=False)
    if n_zero:
        # ``arr`` was read from the archive into memory we own, so in-place is safe.
        out *= 2
        out -= 1
        return out, "0/1 (converted to -1/+1)"
    return out, "-1/+1"


def _check_sorted(t: np.ndarray, path: Path) -> None:
    """Raise unless ``t`` is finite and non-decreasing (checked in chunks)."""
    n = t.shape[0]
    for s in range(0, n, _CHUNK):
        e = min(s + _CHUNK + 1, n)
        chunk = t[s:e]
        if not np.all(np.isfinite(chunk)):
            raise DatasetError(f"{path}: timestamps 't' hold NaN or inf")
        d = np.diff(chunk)
        if not np.all(d >= 0):
            i = s + int(np.argmax(d < 0))
            raise DatasetError(
                f"{path}: timestamps are not sorted ascending (t[{i}]={t[i]!r} > "
                f"t[{i + 1}]={t[i + 1]!r})"
            )


def load_events(path: str | Path, width: int, height: int) -> EventStream:
    """Load and check one events npz.

    Args:
        path: the ``.npz`` file with keys ``x`` (column), ``y`` (row), ``t``, ``p``.
        width: image width; every ``x`` must be < width.
        height: image height; every ``y`` must be < height.

    Returns:
        The :class:`EventStream`; arrays are converted once to int16/int16/float64/int8.

    Raises:
        DatasetError: unreadable file, missing or extra keys, arrays of different lengths or
            not 1-D, no events, unsorted or non-finite timestamps, pixels outside the image,
            polarity values other than -1/+1 or 0/1. The message names the file.
    """
    path = Path(path)
    try:
        npz = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise DatasetError(f"{path}: cannot read events npz ({exc})") from None
    if not isinstance(npz, np.lib.npyio.NpzFile):
        raise DatasetError(f"{path}: not an npz archive (expected keys x, y, t, p)")
    with npz:
        keys = set(npz.files)
        missing = [k for k in EVENT_KEYS if k not in keys]
        extra = sorted(keys - set(EVENT_KEYS))
        if missing:
            raise DatasetError(
                f"{path}: missing key(s) {', '.join(missing)} (found {sorted(keys)}; "
                "expected x, y, t, p)"
            )
        if extra:
            log.info("%s: ignoring extra keys %s", path, extra)

        def read(key: str) -> np.ndarray:
            try:
                arr = npz[key]
            except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
                raise DatasetError(f"{path}: cannot read key '{key}' ({exc})") from None
            if arr.ndim != 1:
                arr = arr.reshape(-1) if arr.ndim == 2 and 1 in arr.shape else arr
            if arr.ndim != 1:
                raise DatasetError(f"{path}: key '{key}' has shape {arr.shape}, expected 1-D")
            return arr

        # One key at a time, so the raw and converted copies of only one array coexist.
        t = read("t")
        n = t.shape[0]
        if n == 0:
            raise DatasetError(f"{path}: no events (empty arrays)")
        if not np.issubdtype(t.dtype, np.number) or t.dtype == np.bool_:
            raise DatasetError(f"{path}: key 't' has dtype {t.dtype}, expected numbers")
        t = t.astype(np.float64, copy=False)
        _check_sorted(t, path)
        if t[-1] <= 0:
            raise DatasetError(f"{path}: largest timestamp is {t[-1]!r}; expected > 0")
        arrays = {}
        for key in ("x", "y", "p"):
            arr = read(key)
            if arr.shape[0] != n:
                raise DatasetError(
                    f"{path}: key '{key}' has {arr.shape[0]} entries but 't' has {n}"
                )
            if key == "p":
                arrays["p"], note = _as_polarity(arr, path)
            else:
                arrays[key] = _as_int16_pixels(arr, key, path)
            del arr
    x, y, p = arrays["x"], arrays["y"], arrays["p"]
    if int(x.max()) >= width or int(y.max()) >= height:
        raise DatasetError(
            f"{path}: pixels outside the image: max x={int(x.max())}, max y={int(y.max())} "
            f"for a {width}x{height} image (x is the column, y the row; set the size with "
            "overrides width=..., height=...)"
        )
    if note != "-1/+1":
        log.warning("%s: polarity stored as %s", path, note)
    return EventStream(x=x, y=y, t=t, p=p, path=path, polarity_note=note)
