"""Which pixels fired around a view, less sensor noise: the strokes the events' visual hull
(:mod:`hybridneus.data.hull`) outlines the object from.

Background activity and hot pixels fire at random places, alone; an object's outline fires in
connected strokes. :func:`without_noise` tells the two apart in one window's event counts.
"""

from __future__ import annotations

import numpy as np

from hybridneus.data.dataset import SplitData

#: Half the side, in RGGB cells (2x2 pixels), of the square in which :func:`without_noise`
#: counts firing cells: 5x5 cells, 10x10 pixels.
NOISE_RADIUS = 2
#: The longest step, in cells, by which :func:`without_noise` joins firing cells to an outline.
MAX_LINK = 8
#: The most events a cell may need before it counts as firing (:func:`without_noise`).
MAX_LEVEL = 4


def without_noise(
    counts: np.ndarray, radius: int = NOISE_RADIUS, max_share: float = 0.35
) -> np.ndarray | None:
    """The firing pixels of one window that are not sensor noise, or ``None`` when there is
    too much noise to tell.

    The test runs on RGGB cells (2x2 pixels), so that an edge seen by one colour channel only
    is as connected as one seen by all. A cell fires when its pixels hold at least ``m``
    events: ``m`` is 1 where the noise allows, else the least level up to
    :data:`MAX_LEVEL` at which it does. A sensor's background activity over a slow camera's
    window (a DAVIS346 at 0.1 Hz a pixel over two views of 60 ms: one cell in 20) leaves
    too many cells with one event to measure, but a passing edge fires a cell many times
    and a noise cell rarely twice. Only noise up to twice the density one level can measure
    (the quietest quarter of the image's blocks, below) is thinned so: beyond it, a window
    is cluttered (a background that fires everywhere, :func:`hybridneus.data.hull.
    background_fires`) or too noisy to tell, and the view is skipped.

    At one level, the density ``p`` of randomly firing cells is estimated from the isolated
    ones (no other firing cell in the ``2 radius + 1`` square of cells), whose share is
    ``p (1 - p)^n`` for ``n`` other cells in the square. A cell is kept when at least ``k``
    others of its square fired, ``k`` the smallest count that fewer than half a noise cell
    in the whole image is expected to reach (a Poisson tail), and so is every firing cell
    joined to a kept one by steps short enough that noise rarely chains (the sparse
    stretches of an outline seen almost end-on). A pixel stays when it fired and its cell
    stays. Without isolated cells nothing is removed. A level cannot tell the outline from
    the noise when ``p`` is beyond what the isolated cells can measure (``1 / (n + 1)``; the
    quietest quarter of an 8x8 grid of image blocks fires that densely, or more cells are
    isolated than any ``p`` gives), or when ``k`` exceeds ``max_share`` of ``n``; when no
    level can, the caller should skip the view.

    Args:
        counts: (height, width) the events of each pixel in the window (a bool array counts
            each firing pixel once).
        radius: half the side of the square, in cells.
        max_share: the largest ``k`` accepted, as a share of ``n``.
    """
    counts = np.asarray(counts)
    fired = counts > 0
    h, w = fired.shape
    per_cell = np.zeros(((h + 1) // 2, (w + 1) // 2), np.int64)
    for dy in (0, 1):
        for dx in (0, 1):
            sub = counts[dy::2, dx::2]
            per_cell[: sub.shape[0], : sub.shape[1]] += sub
    n = (2 * radius + 1) ** 2 - 1
    for level in range(1, MAX_LEVEL + 1):
        cells = per_cell >= level
        if level == 2 and _quietest_quarter(per_cell >= 1) > 2.0 / (n + 1):
            return None  # denser than a sensor's noise: clutter, or noise beyond telling
        kept = _outline_cells(cells, radius, max_share)
        if kept is not None:
            return fired & np.repeat(np.repeat(kept, 2, axis=0), 2, axis=1)[:h, :w]
    return None


def _quietest_quarter(cells: np.ndarray) -> float:
    """The share of firing cells in the quietest quarter of an 8x8 grid of image blocks."""
    import cv2

    blocks = cv2.resize(cells.astype(np.float32), (8, 8), interpolation=cv2.INTER_AREA)
    return float(np.percentile(blocks, 25))


def _outline_cells(cells: np.ndarray, radius: int, max_share: float) -> np.ndarray | None:
    """The firing cells that are not noise at one level (:func:`without_noise`)."""
    import cv2

    side = 2 * radius + 1
    n = side * side - 1
    others = cv2.boxFilter(cells.astype(np.float32), -1, (side, side), normalize=False,
                           borderType=cv2.BORDER_CONSTANT) - cells
    # p (1 - p)^n peaks at p = 1 / (n + 1): dense noise leaves few isolated cells, or none,
    # too. Noise fires everywhere alike, an object in a part of the image: the quietest
    # quarter of an 8x8 grid of blocks tells the two apart
    if _quietest_quarter(cells) > 1.0 / (n + 1):
        return None
    isolated = float(np.count_nonzero(cells & (others < 0.5))) / cells.size
    if isolated == 0.0:
        return cells
    if isolated > (n / (n + 1)) ** n / (n + 1):
        return None
    p = isolated
    for _ in range(50):  # the fixed point of p = isolated / (1 - p)^n below that maximum
        p = isolated / (1.0 - p) ** n
    lam, expected = p * n, p * cells.size
    term, tail, k = np.exp(-lam), 1.0, 0  # tail = P(X >= k), X ~ Poisson(lam)
    while expected * tail >= 0.5:
        tail -= term
        k += 1
        term *= lam / k
        if k > max_share * n:
            return None
    core = cells & (others >= k - 0.5)
    # 0.25 expected noise cells within a step: chains of noise die out quickly
    link = int(np.clip((np.sqrt(0.25 / p) - 1.0) / 2.0, 1, MAX_LINK))
    joined = cv2.dilate(cells.astype(np.uint8), np.ones((link, link), np.uint8))
    _, labels = cv2.connectedComponents(joined, connectivity=8)
    return cells & np.isin(labels, np.unique(labels[core]))


def fired_near(
    split: SplitData, view: int, window: int = 1, denoise: bool = True
) -> np.ndarray | None:
    """(height, width) bool: the pixels that fired within ``window`` views of ``view``, less
    sensor noise (:func:`without_noise`; ``denoise=False`` keeps every pixel). ``None`` when
    the window is too noisy to tell the outline."""
    from hybridneus.data.windows import event_counter

    t, times = split.events.t, split.view_times
    a = int(np.searchsorted(t, times[view - window], side="left"))
    b = int(np.searchsorted(t, times[view + window], side="right"))
    # the counter is shared with training's event frames
    counts = event_counter(split).counts(a, b).sum(axis=1).reshape(split.height, split.width)
    return without_noise(counts) if denoise else counts > 0


__all__ = ["MAX_LEVEL", "NOISE_RADIUS", "fired_near", "without_noise"]
