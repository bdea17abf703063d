"""Silent lines: runs of pixels along a window's image motion where no event fired.

A pixel stays silent in a window when its brightness does not change as the image moves
across it, so a run of silent pixels along the direction of motion, ended on both sides by
pixels that fired, sees one stretch of constant brightness. On an object lit from a fixed
light, a curved surface of one colour is shaded unevenly and fires; a long silent run lies on
a flat face of one colour (or on the background). :func:`silent_lines` draws such runs and
returns, for each, its two ends and one pixel between them; ``priors.silent_lines``
(:mod:`hybridneus.training.priors.silent_lines`) asks their depths to follow one plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage


@dataclass
class Lines:
    """Pixel triples on silent runs (all (k, 2) int64, column first).

    Attributes:
        start: the pixel just inside one end of the run.
        middle: a pixel between the ends.
        end: the pixel just inside the other end.
        t: (k,) float32 where ``middle`` lies from ``start`` (0) to ``end`` (1) along the run.
    """

    start: np.ndarray
    middle: np.ndarray
    end: np.ndarray
    t: np.ndarray

    def __len__(self) -> int:
        return int(self.t.shape[0])


def changed_mask(counts: np.ndarray) -> np.ndarray:
    """(h, w) bool: pixels whose brightness changed over the window (as many events of one
    polarity as of the other means it came back), from (h, w, 2) [negative, positive]
    counts, grown by one pixel so that a low-contrast edge that changed every other pixel
    (a Bayer mosaic's other colours) still closes a run."""
    changed = counts[..., 1] != counts[..., 0]
    return ndimage.binary_dilation(changed, structure=np.ones((3, 3), dtype=bool))


def image_motion(K: np.ndarray, c2w0: np.ndarray, c2w1: np.ndarray,
                 point: np.ndarray | None = None) -> np.ndarray:
    """(2,) unit direction in which ``point`` (default: the world origin, where the object
    is) moves in the image from camera ``c2w0`` to ``c2w1``, both (4, 4) OpenCV camera-to-world
    with pinhole ``K`` (3, 3); ``(1, 0)`` when it does not move."""
    x = np.zeros(3) if point is None else np.asarray(point, dtype=np.float64)
    uv = []
    for c2w in (c2w0, c2w1):
        cam = c2w[:3, :3].T @ (x - c2w[:3, 3])
        p = K @ cam
        uv.append(p[:2] / max(p[2], 1e-9))
    flow = uv[1] - uv[0]
    norm = float(np.linalg.norm(flow))
    if not np.isfinite(norm) or norm < 1e-6:
        return np.array([1.0, 0.0])
    return flow / norm


def _first_fired(fired: np.ndarray, xy: np.ndarray, step: np.ndarray, max_length: int
                 ) -> np.ndarray:
    """(n,) steps from each pixel ``xy`` along ``step`` (2,) to the first fired pixel, or 0
    when the run leaves the image or reaches no fired pixel within ``max_length``."""
    h, w = fired.shape
    s = np.arange(1, max_length + 1)
    pos = np.rint(xy[:, None, :] + s[None, :, None] * step).astype(np.int64)
    inside = (pos[..., 0] >= 0) & (pos[..., 0] < w) & (pos[..., 1] >= 0) & (pos[..., 1] < h)
    hit = np.zeros(inside.shape, dtype=bool)
    hit[inside] = fired[pos[..., 1][inside], pos[..., 0][inside]]
    stop = hit | ~inside
    first = np.argmax(stop, axis=1)
    found = stop[np.arange(len(xy)), first] & hit[np.arange(len(xy)), first]
    return np.where(found, s[first], 0)


def silent_lines(fired: np.ndarray, direction: np.ndarray, n: int, rng: np.random.Generator,
                 min_length: int = 8, max_length: int = 128, margin: int = 1) -> Lines:
    """Up to ``n`` triples on silent runs along ``direction``.

    Candidates are silent pixels drawn uniformly within the box around the fired pixels; a
    candidate is kept when, walking both ways along ``direction``, a fired pixel ends the run
    within ``max_length`` pixels on each side (a run into the image border is background or
    unknown) and the run, less ``margin`` pixels at each end, is at least ``min_length`` long.

    Args:
        fired: (h, w) bool, :func:`changed_mask` of the window.
        direction: (2,) the image motion (column, row), :func:`image_motion`.
        n: most triples to return.
        rng: random generator.
        min_length: shortest run kept, pixels between its two ends.
        max_length: farthest a fired pixel may lie from a candidate, pixels.
        margin: pixels left between a run's end and the fired pixel that closes it.

    Returns:
        :class:`Lines` with at most ``n`` rows (none when the window fired nowhere).
    """
    empty = np.zeros((0, 2), dtype=np.int64)
    rows, cols = np.nonzero(fired)
    if n <= 0 or rows.size == 0:
        return Lines(empty, empty, empty, np.zeros(0, dtype=np.float32))
    step = np.asarray(direction, dtype=np.float64)
    step = step / np.abs(step).max()  # one pixel along the major axis per step
    y0, y1, x0, x1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    m = 4 * n
    cand = np.stack([rng.integers(x0, x1, size=m), rng.integers(y0, y1, size=m)], axis=1)
    cand = cand[~fired[cand[:, 1], cand[:, 0]]]
    ahead = _first_fired(fired, cand, step, max_length)
    back = _first_fired(fired, cand, -step, max_length)
    a, b = back - 1 - margin, ahead - 1 - margin  # steps from the candidate to each end
    keep = (ahead > 0) & (back > 0) & (a >= 1) & (b >= 1) & (a + b >= min_length)
    cand, a, b = cand[keep][:n], a[keep][:n], b[keep][:n]
    start = np.rint(cand - a[:, None] * step).astype(np.int64)
    end = np.rint(cand + b[:, None] * step).astype(np.int64)
    t = (a / (a + b)).astype(np.float32)
    return Lines(start, cand.astype(np.int64), end, t)
