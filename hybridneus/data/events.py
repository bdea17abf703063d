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
        t_end: the capture's last timestamp when it is not the last event's (a filtered
            stream keeps its views where the file put them); ``None``: ``t[-1]``.
    """

    x: np.ndarray
    y: np.ndarray
    t: np.ndarray
    p: np.ndarray
    path: Path | None = None
    polarity_note: str = "-1/+1"
    t_end: float | None = None
    _pixel_code: np.ndarray | None = field(default=None, repr=False)
    _code_width: int = field(default=0, repr=False)
    # Derived structures built on first use (e.g. the window counter of data.windows).
    cache: dict = field(default_factory=dict, repr=False)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def t_max(self) -> float:
        """Largest timestamp: view i of N sits at ``i / (N - 1) * t_max``."""
        if self.t_end is not None:
            return float(self.t_end)
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


class _PixelCheck:
    """Per-chunk checks of ``x`` or ``y`` before the cast to int16."""

    def __init__(self, key: str, path: Path) -> None:
        self.key, self.path, self.max = key, path, -1

    def __call__(self, chunk: np.ndarray) -> np.ndarray:
        key, path = self.key, self.path
        if chunk.dtype == np.bool_ or not (
            np.issubdtype(chunk.dtype, np.integer) or np.issubdtype(chunk.dtype, np.floating)
        ):
            raise DatasetError(f"{path}: key '{key}' has dtype {chunk.dtype}, expected integers")
        if np.issubdtype(chunk.dtype, np.floating):
            if not np.all(np.isfinite(chunk)):
                raise DatasetError(f"{path}: key '{key}' holds NaN or inf")
            if not np.all(chunk == np.floor(chunk)):
                raise DatasetError(f"{path}: key '{key}' holds non-integer pixel coordinates")
        lo, hi = chunk.min(), chunk.max()
        if lo < 0:
            raise DatasetError(
                f"{path}: pixels outside the image: {key} has negative values (min {int(lo)})"
            )
        if hi > np.iinfo(np.int16).max:
            raise DatasetError(
                f"{path}: pixels outside the image: {key} max {int(hi)} is too large"
            )
        self.max = max(self.max, int(hi))
        return chunk.astype(np.int16)


class _PolarityCheck:
    """Per-chunk checks of ``p``: only -1/+1 or only 0/1 (or booleans)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.n_zero = self.n_minus = 0
        self.boolean = False

    def __call__(self, chunk: np.ndarray) -> np.ndarray:
        if chunk.dtype == np.bool_:
            self.boolean = True
            self.n_zero += int(np.count_nonzero(~chunk))
            return chunk.astype(np.int8)
        if not (np.issubdtype(chunk.dtype, np.integer) or np.issubdtype(chunk.dtype, np.floating)):
            raise DatasetError(f"{self.path}: key 'p' has dtype {chunk.dtype}, expected numbers")
        nz = int(np.count_nonzero(chunk == 0))
        nm = int(np.count_nonzero(chunk == -1))
        npl = int(np.count_nonzero(chunk == 1))
        if nz + nm + npl != chunk.shape[0]:
            bad = np.unique(chunk[(chunk != 0) & (chunk != 1) & (chunk != -1)])[:5]
            raise DatasetError(
                f"{self.path}: polarity values {bad.tolist()} are neither -1/+1 nor 0/1"
            )
        self.n_zero += nz
        self.n_minus += nm
        if self.n_zero and self.n_minus:
            raise DatasetError(
                f"{self.path}: polarity holds -1, 0 and +1 values; expected either -1/+1 or 0/1"
            )
        return chunk.astype(np.int8)


class _TimeCheck:
    """Per-chunk checks of ``t``: numeric, finite, non-decreasing across chunk borders."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.last = -np.inf
        self.offset = 0

    def __call__(self, chunk: np.ndarray) -> np.ndarray:
        path = self.path
        if not np.issubdtype(chunk.dtype, np.number) or chunk.dtype == np.bool_:
            raise DatasetError(f"{path}: key 't' has dtype {chunk.dtype}, expected numbers")
        out = chunk.astype(np.float64)
        if not np.all(np.isfinite(out)):
            raise DatasetError(f"{path}: timestamps 't' hold NaN or inf")
        bad = np.diff(out) < 0
        if out.shape[0] and out[0] < self.last:
            i = self.offset - 1
            raise DatasetError(
                f"{path}: timestamps are not sorted ascending (t[{i}]={float(self.last)} > "
                f"t[{i + 1}]={float(out[0])})"
            )
        if np.any(bad):
            j = int(np.argmax(bad))
            i = self.offset + j
            raise DatasetError(
                f"{path}: timestamps are not sorted ascending (t[{i}]={float(out[j])} > "
                f"t[{i + 1}]={float(out[j + 1])})"
            )
        if out.shape[0]:
            self.last = out[-1]
        self.offset += out.shape[0]
        return out


def _read_member(
    zf: zipfile.ZipFile, key: str, path: Path, out_dtype: type, convert
) -> np.ndarray:
    """Stream one ``<key>.npy`` of the archive in chunks through ``convert`` into one array.

    Only one raw chunk exists at a time, so a 30M-event int64 column never sits in memory
    next to its int16 copy.
    """
    try:
        with zf.open(f"{key}.npy") as f:
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
            elif version == (2, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
            else:
                shape, dtype = None, None
            if shape is not None:
                if dtype.hasobject:
                    raise DatasetError(
                        f"{path}: key '{key}' holds Python objects (pickles are not loaded)"
                    )
                if len(shape) != 1 and not (len(shape) == 2 and 1 in shape):
                    raise DatasetError(
                        f"{path}: key '{key}' has shape {shape}, expected 1-D"
                    )
                n = int(np.prod(shape))
                info = zf.getinfo(f"{key}.npy")
                # before allocating what the header claims: no more than the member's size,
                # which itself cannot exceed deflate's ~1032:1 ratio over the stored bytes
                held = min(info.file_size, 1100 * info.compress_size + 4096)
                if n * dtype.itemsize > held:
                    raise DatasetError(
                        f"{path}: key '{key}' claims {n:,} entries but holds {held:,} bytes")
                out = np.empty(n, dtype=out_dtype)
                step = _CHUNK
                for s in range(0, n, step):
                    m = min(step, n - s)
                    buf = f.read(m * dtype.itemsize)
                    if len(buf) != m * dtype.itemsize:
                        raise DatasetError(f"{path}: key '{key}' is truncated")
                    out[s : s + m] = convert(np.frombuffer(buf, dtype=dtype))
                return out
    except DatasetError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, KeyError) as exc:
        raise DatasetError(f"{path}: cannot read key '{key}' ({exc})") from None
    # Rare .npy format versions: let numpy read the whole array, then convert in chunks.
    try:
        arr = np.load(path, allow_pickle=False)[key]
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise DatasetError(f"{path}: cannot read key '{key}' ({exc})") from None
    if arr.ndim != 1 and not (arr.ndim == 2 and 1 in arr.shape):
        raise DatasetError(f"{path}: key '{key}' has shape {arr.shape}, expected 1-D")
    arr = arr.reshape(-1)
    out = np.empty(arr.shape[0], dtype=out_dtype)
    for s in range(0, arr.shape[0], _CHUNK):
        out[s : s + _CHUNK] = convert(arr[s : s + _CHUNK])
    return out


def load_events(path: str | Path, width: int, height: int) -> EventStream:
    """Load and check one events npz.

    Each key is streamed from the archive in chunks of 4M values, checked and converted to
    its final dtype on the way, so peak memory stays near the size of the final arrays
    (int16 x/y, float64 t, int8 p: 13 bytes per event).

    Args:
        path: the ``.npz`` file with keys ``x`` (column), ``y`` (row), ``t``, ``p``, and
            optionally ``t_end``, the last view's time when the last event comes earlier
            (``hybridneus convert`` writes it).
        width: image width; every ``x`` must be < width.
        height: image height; every ``y`` must be < height.

    Returns:
        The :class:`EventStream`.

    Raises:
        DatasetError: unreadable file, missing keys, arrays of different lengths or not
            1-D, no events, unsorted or non-finite timestamps, pixels outside the image,
            polarity values other than -1/+1 or 0/1. The message names the file.
    """
    path = Path(path)
    try:
        zf = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile, EOFError, ValueError) as exc:
        raise DatasetError(f"{path}: cannot read events npz ({exc})") from None
    with zf:
        keys = {n[:-4] for n in zf.namelist() if n.endswith(".npy")}
        missing = [k for k in EVENT_KEYS if k not in keys]
        if missing:
            raise DatasetError(
                f"{path}: missing key(s) {', '.join(missing)} (found {sorted(keys)}; "
                "expected x, y, t, p)"
            )
        extra = sorted(keys - set(EVENT_KEYS) - {"t_end"})
        if extra:
            log.info("%s: ignoring extra keys %s", path, extra)
        x_check, y_check = _PixelCheck("x", path), _PixelCheck("y", path)
        p_check = _PolarityCheck(path)
        # The narrow columns first, t last: peak memory is the final arrays plus one chunk.
        x = _read_member(zf, "x", path, np.int16, x_check)
        n = x.shape[0]
        if n == 0:
            raise DatasetError(f"{path}: no events (empty arrays)")
        y = _read_member(zf, "y", path, np.int16, y_check)
        p = _read_member(zf, "p", path, np.int8, p_check)
        t = _read_member(zf, "t", path, np.float64, _TimeCheck(path))
        t_end = None
        if "t_end" in keys:
            end = _read_member(zf, "t_end", path, np.float64, lambda c: c)
            if end.shape != (1,) or not np.isfinite(end[0]) or end[0] < t[-1]:
                raise DatasetError(
                    f"{path}: key 't_end' must hold one finite time at or after the last "
                    f"event's ({float(t[-1])}), got {end.tolist()[:3]}")
            t_end = float(end[0])
    for key, arr in (("y", y), ("p", p), ("t", t)):
        if arr.shape[0] != n:
            raise DatasetError(f"{path}: key '{key}' has {arr.shape[0]} entries but 'x' has {n}")
    if t[-1] <= 0:
        raise DatasetError(f"{path}: largest timestamp is {float(t[-1])}; expected > 0")
    if t[0] < 0:
        raise DatasetError(f"{path}: timestamps start at {float(t[0])} < 0; view i of N sits "
                           "at i / (N - 1) * max(t), so t must count from 0")
    if x_check.max >= width or y_check.max >= height:
        raise DatasetError(
            f"{path}: pixels outside the image: max x={x_check.max}, max y={y_check.max} "
            f"for a {width}x{height} image (x is the column, y the row; set the size with "
            "overrides width=..., height=...)"
        )
    note = "-1/+1"
    if p_check.n_zero or p_check.boolean:
        p *= 2
        p -= 1
        note = ("boolean " if p_check.boolean else "") + "0/1 (converted to -1/+1)"
        log.warning("%s: polarity stored as %s", path, note)
    return EventStream(x=x, y=y, t=t, p=p, path=path, polarity_note=note, t_end=t_end)
