"""The polarity offset that the events' own balance implies.

Real DAVIS sensors fire positive and negative events at different thresholds; the EventNeRF
reference code corrects this by adding a per-scene ``polarity_offset`` ``o`` to every
polarity, so that a positive event stands for a change of ``C (1 + o)`` and a negative one for
``-C (1 - o)`` (``o`` near -0.4 on the published real scenes). A dataset's path names that
value for the published scenes; for any other data the reader can only guess (0, or the
``real`` group's -0.404 for an unpublished scene under ``real/``), and a wrong offset adds a
drift of ``C o`` per event to every target.

The data say what ``o`` is. Over a capture that comes back to where it started (a turntable,
a closed orbit) each pixel sees the same brightness at the end as at the start, so its events
sum to no change: ``n+ (1 + o) = n- (1 - o)``, that is ``o = (n- - n+) / (n+ + n-)``. Along an
open path they need not: a spiral from the pole to the equator that sees a shaded surface
turn away from its light fires mostly OFF events at every pixel of it (a simulated bowl with
balanced polarities reads as -0.9), so a fit uses the estimate only where
:func:`closed_path` says the cameras come back to their start, or over the longest stretch
of views whose cameras end where they began (:func:`closed_span`: a hand-held capture that
comes down from above and then circles the object closes after its first views). The
estimate is
the median of that ratio over the pixels with at least ``MIN_EVENTS`` events, taken after the
background-activity filter (:mod:`hybridneus.data.denoise`): balanced noise events would pull
each pixel's ratio towards 0, and a hot pixel (one polarity, many events) is one pixel of
thousands in a median. A count-weighted mean would lean towards the pixels whose thresholds
happen to be smallest, which fire the most.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hybridneus.data.dataset import SplitData
from hybridneus.data.denoise import DenoiseReport, denoised_split, kept_events
from hybridneus.data.events import EventStream

#: Events per bincount call (bounds its int64 copy).
_CHUNK = 1 << 22
#: Events a pixel needs before its balance counts.
MIN_EVENTS = 8
#: Pixels the median needs before it is an estimate.
MIN_PIXELS = 50
#: Estimates closer to 0 than this are read as balanced polarities (offset 0).
BALANCED = 0.05
#: A stated offset this far from the estimate gets a warning (the published real scenes'
#: offsets span 0.1).
DISAGREE = 0.15
#: A path is closed when its last camera centre is within this many of its typical steps
#: between views from the first (a loop of N views ends one step from its start).
CLOSED_STEPS = 3.0
#: A closed stretch of a path (:func:`closed_span`) spans at least this share of its views.
MIN_SPAN = 0.25


@dataclass(frozen=True)
class PolarityBalance:
    """The offset the events imply (see the module docstring).

    Attributes:
        offset: the median of ``(n- - n+) / (n+ + n-)`` over the pixels counted; ``None``
            when fewer than ``MIN_PIXELS`` pixels have ``MIN_EVENTS`` events.
        pixels: pixels counted.
        events: events those pixels hold.
        dense_noise: the noise filter found the noise too dense to tell from the object and
            kept every event; balanced noise then pulls the estimate towards 0.
    """

    offset: float | None
    pixels: int
    events: int
    dense_noise: bool = False

    @property
    def balanced(self) -> bool:
        """The polarities balance (the estimate is within ``BALANCED`` of 0)."""
        return self.offset is not None and abs(self.offset) < BALANCED

    def suggested(self) -> float | None:
        """The offset to use: 0 for balanced polarities, else the estimate rounded to three
        decimals; ``None`` without an estimate."""
        if self.offset is None:
            return None
        return 0.0 if self.balanced else round(self.offset, 3)

    def disagrees(self, stated: float) -> bool:
        """The events contradict the ``stated`` offset (by more than ``DISAGREE``)."""
        offset = self.suggested()
        return offset is not None and abs(offset - stated) > DISAGREE

    def line(self) -> str:
        """One log line."""
        if self.offset is None:
            return (f"polarity: too few pixels with {MIN_EVENTS} or more events ({self.pixels})"
                    " to estimate the offset from the events")
        where = f"median over {self.pixels} pixels with {MIN_EVENTS} or more events"
        where += (", noise too dense to filter: it pulls the estimate towards 0"
                  if self.dense_noise else ", after the noise filter")
        if self.balanced:
            return f"polarity: the events are balanced (offset {self.offset:+.3f}; {where})"
        return f"polarity: the events imply an offset of {self.offset:+.3f} ({where})"


def closed_path(c2w: np.ndarray) -> tuple[bool, float]:
    """Whether a capture's cameras come back to where they started.

    Args:
        c2w: (n_views, 4, 4) camera-to-world poses in capture order.

    Returns:
        ``(closed, gap)``: closed when the gap between the first and the last camera centre
        is at most :data:`CLOSED_STEPS` median steps between consecutive views; ``gap`` in
        such steps (0 where the cameras never move).
    """
    centres = np.asarray(c2w, np.float64)[:, :3, 3]
    gap = float(np.linalg.norm(centres[-1] - centres[0]))
    steps = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    step = float(np.median(steps)) if steps.size else 0.0
    if step <= 0.0:
        return gap <= 0.0, 0.0 if gap <= 0.0 else math.inf
    return gap <= CLOSED_STEPS * step, gap / step


def closed_span(c2w: np.ndarray) -> tuple[int, int] | None:
    """The longest stretch of views ``first .. last`` whose cameras end where they began.

    The last camera must be within :data:`CLOSED_STEPS` median steps between views of the
    first and look the same way (its viewing direction within as many median turns between
    views): each pixel then sees the same brightness at both ends. Stretches shorter than
    :data:`MIN_SPAN` of the views count for nothing.

    Args:
        c2w: (n_views, 4, 4) camera-to-world poses in capture order.

    Returns:
        ``(first, last)``, or ``None`` where no stretch closes.
    """
    from scipy.spatial import cKDTree

    c2w = np.asarray(c2w, np.float64)
    n = c2w.shape[0]
    centres, forward = c2w[:, :3, 3], c2w[:, :3, 2]
    forward = forward / np.linalg.norm(forward, axis=1, keepdims=True)
    step = float(np.median(np.linalg.norm(np.diff(centres, axis=0), axis=1))) if n > 1 else 0.0
    if step <= 0.0:
        return None
    turn = float(np.median(np.arccos(np.clip((forward[1:] * forward[:-1]).sum(1), -1, 1))))
    cos_turn = math.cos(CLOSED_STEPS * turn + 1e-9)
    shortest = max(2, math.ceil(MIN_SPAN * n))
    best = None
    near = cKDTree(centres).query_ball_point(centres, CLOSED_STEPS * step)
    for i, js in enumerate(near):
        js = np.asarray(js)
        js = js[(js - i >= shortest) & (forward[js] @ forward[i] >= cos_turn)]
        if js.size and (best is None or js.max() - i > best[1] - best[0]):
            best = (i, int(js.max()))
    return best


def between_views(split: SplitData, first: int, last: int) -> SplitData:
    """``split`` with only the events from view ``first`` to view ``last`` (its views stay)."""
    ev = split.events
    times = split.view_times
    a = int(np.searchsorted(ev.t, times[first], side="left"))
    b = int(np.searchsorted(ev.t, times[last], side="right"))
    return replace(split, events=kept_events(ev, slice(a, b)))


def _counts(events: EventStream, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """(height * width,) int64 OFF and ON event counts of each pixel."""
    code = events.pixel_code(width)  # cached: the window sampler counts with it too
    counts = np.zeros(2 * width * height, np.int64)
    for start in range(0, code.size, _CHUNK):  # bincount makes an int64 copy of its input
        counts += np.bincount(code[start:start + _CHUNK], minlength=counts.size)
    neg, pos = counts.reshape(-1, 2).T
    return neg, pos


def balance_offset(events: EventStream, width: int, height: int) -> PolarityBalance:
    """The polarity offset implied by ``events``, taken as they are (no noise filter).

    Args:
        events: the stream (polarities -1/+1).
        width: image width.
        height: image height.

    Returns:
        The :class:`PolarityBalance`.
    """
    neg, pos = _counts(events, width, height)
    n = neg + pos
    counted = n >= MIN_EVENTS
    pixels = int(np.count_nonzero(counted))
    held = int(n[counted].sum())
    if pixels < MIN_PIXELS:
        return PolarityBalance(None, pixels, held)
    ratio = (neg[counted] - pos[counted]) / n[counted]
    return PolarityBalance(float(np.median(ratio)), pixels, held)


def pixel_offsets(events: EventStream, width: int, height: int, offset: float) -> np.ndarray:
    """Each pixel's own polarity offset, shrunk towards the scene's ``offset``.

    A sensor's ON and OFF thresholds differ from pixel to pixel (their mismatch), so one
    offset leaves each pixel a drift of its own; over a closed path a pixel's balance says
    its offset, ``(n- - n+) / n``, with a sampling variance of about ``(1 - o^2) / n``. The
    estimate weighs it against ``offset`` by those two variances (``k / (n + k)`` on the
    scene's, ``k`` the sampling variance over the spread the pixels' balances show beyond
    it): a pixel with few events keeps about the scene's offset.

    Args:
        events: the stream (polarities -1/+1), as :func:`balance_offset` takes it.
        width: image width.
        height: image height.
        offset: the scene's offset (:func:`balance_offset`'s estimate).

    Returns:
        (height * width,) float32 offsets, in the order of ``row * width + column``.
    """
    neg, pos = (c.astype(np.float64) for c in _counts(events, width, height))
    n = neg + pos
    counted = n >= MIN_EVENTS
    own = np.where(n > 0, (neg - pos) / np.maximum(n, 1.0), offset)
    sampling = (1.0 - offset ** 2) / np.maximum(n, 1.0)
    spread = float(np.mean((own[counted] - offset) ** 2) - np.mean(sampling[counted])) \
        if counted.any() else 0.0
    if spread <= 0.0:
        return np.full(n.shape, offset, np.float32)
    trust = spread / (spread + sampling)
    return (offset + trust * (own - offset)).clip(-0.95, 0.95).astype(np.float32)


def polarity_balance(
    split: SplitData,
    slab_views: float = 2.0,
    denoised: tuple[SplitData, DenoiseReport] | None = None,
) -> PolarityBalance:
    """The polarity offset implied by a split's events, after the noise filter.

    Args:
        split: the split (a closed capture gives the most exact estimate).
        slab_views: the noise filter's slab length, in views
            (:func:`hybridneus.data.denoise.denoised_split`).
        denoised: what ``denoised_split(split, slab_views)`` returned, if the caller has it.

    Returns:
        The :class:`PolarityBalance`.
    """
    kept, report = denoised if denoised is not None else denoised_split(split, slab_views)
    found = balance_offset(kept.events, split.width, split.height)
    return replace(found, dense_noise=report.too_dense)
