"""Which events are sensor noise: a background-activity filter over the whole stream.

Background activity and hot pixels fire alone: few other pixels near them fire at about the
same time. A moving edge fires along its length at once, so its events have company. The
stream is cut into time slabs ``dt`` long; an event's *company* is the number of events of
the other pixels within ``radius`` pixels (a ``2 radius + 1`` square, so that the same Bayer
colour two pixels away counts) in its slab and the slabs on either side. A hot pixel's own
repeats never count.

How much company noise gets by chance depends on how noisy the sensor is, so the bar is set
from the stream itself (:func:`company_bar`): background activity of ``rho`` events per
pixel and slab gives each event ``Poisson(mu)`` company, ``mu = n rho`` for the ``n``
pixel-slabs around it, and leaves about ``rho e^-mu`` pixel-slabs holding a lone event, from
which ``rho`` follows. The bar is the least company that leaves noise of at most
``SURVIVAL`` of all the events; a clean stream needs none (0: every event is kept). Noise so
dense that no event is alone cannot be measured that way; it shows as events everywhere,
even in the quietest quarter of the image, and then the stream is kept whole too.

The polarity-offset estimate (:mod:`hybridneus.data.balance`) counts only the kept events,
so that balanced noise does not pull it towards 0; ``hybridneus info`` prints the report.
A fit trains on the kept events too (``estimate.denoise``, :func:`hybridneus.data.estimate.
training_data`): its rays go to pixels that fired in a window, and on a noisy sensor nearly
every pixel has. Noise right beside the object's moving outline has company and stays.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from hybridneus.data.dataset import SplitData
from hybridneus.data.events import EventStream

#: Cells of the count volume that one chunk of :func:`event_company` holds at most.
_CHUNK_CELLS = 1 << 23
#: Neighbourhood half-side, in pixels.
RADIUS = 2
#: The noise the bar may leave, as a share of all the events.
SURVIVAL = 0.01
#: The largest bar, as a share of the pixel-slabs around an event: noise that needs more is
#: too dense to tell from the object, and the stream is kept whole.
MAX_BAR_SHARE = 0.35


def event_company(
    events: EventStream, width: int, height: int, dt: float, radius: int = RADIUS
) -> np.ndarray:
    """(n_events,) int32: events of other pixels within ``radius`` and one slab (module doc).

    Args:
        events: the stream, sorted by time.
        width: image width.
        height: image height.
        dt: slab length, in the stream's time unit (> 0).
        radius: neighbourhood half-side in pixels.

    Note:
        Memory stays near ``_CHUNK_CELLS`` float32 cells whatever the stream's length: slabs
        are counted a chunk at a time, each chunk with one slab of margin either side.
    """
    if len(events) == 0:
        return np.zeros(0, dtype=np.int32)
    return _company(events, width, height, _slabs(events, dt), radius)


def _slabs(events: EventStream, dt: float) -> np.ndarray:
    """(n_events,) int64 slab index of each event of a non-empty stream."""
    if not dt > 0:
        raise ValueError(f"event_company: dt must be > 0, got {dt}")
    return np.floor((events.t - events.t[0]) / dt).astype(np.int64)


def _company(
    events: EventStream, width: int, height: int, slab: np.ndarray, radius: int
) -> np.ndarray:
    """:func:`event_company` of a non-empty stream, given its events' slabs."""
    import cv2

    company = np.zeros(len(events), dtype=np.int32)
    pixels = width * height
    n_slabs = int(slab[-1]) + 1
    per_chunk = max(1, _CHUNK_CELLS // pixels - 2)
    side = 2 * radius + 1
    for s0 in range(0, n_slabs, per_chunk):
        s1 = min(s0 + per_chunk, n_slabs)
        lo, hi = np.searchsorted(slab, [s0 - 1, s1 + 1], side="left")
        rel = slab[lo:hi] - (s0 - 1)  # 0 is the margin slab before the chunk
        code = rel * pixels + events.y[lo:hi].astype(np.int64) * width + events.x[lo:hi]
        depth = s1 - s0 + 2
        counts = np.bincount(code, minlength=depth * pixels).astype(np.float32)
        counts = counts.reshape(depth, height, width)
        own = counts[1:-1] + counts[:-2] + counts[2:]  # per pixel, over three slabs
        near = np.empty_like(own)
        for k in range(own.shape[0]):
            near[k] = cv2.boxFilter(own[k], -1, (side, side), normalize=False,
                                    borderType=cv2.BORDER_CONSTANT)
        near -= own
        a, b = np.searchsorted(slab, [s0, s1], side="left")
        mine = slab[a:b] - s0
        company[a:b] = np.rint(near[mine, events.y[a:b], events.x[a:b]]).astype(np.int32)
    return company


@dataclass(frozen=True)
class CompanyBar:
    """What :func:`company_bar` found.

    Attributes:
        bar: least company an event needs to be kept (0: keep every event).
        noise_rate: noise events per pixel and slab, estimated (``nan``: beyond measuring).
        noise_share: estimated share of the stream's events that are background activity
            (hot pixels add their events once per slab, whatever their rate).
    """

    bar: int
    noise_rate: float
    noise_share: float


def _n_around(radius: int) -> int:
    """Pixel-slabs around an event: the square less its own pixel, times three slabs."""
    return ((2 * radius + 1) ** 2 - 1) * 3


def company_bar(
    alone: int, events: int, cells: int, radius: int = RADIUS, survival: float = SURVIVAL
) -> CompanyBar:
    """The company bar for a stream (see the module doc).

    Args:
        alone: pixel-slabs holding an event without company (a hot pixel counts once per
            slab, however often it fires, so that a few of them do not pass for dense noise).
        events: events in the stream.
        cells: pixels times slabs of the stream.
        radius: the neighbourhood half-side the company was counted with.
        survival: the noise the bar may leave, as a share of all the events.
    """
    n_around = _n_around(radius)
    if events == 0:
        return CompanyBar(0, 0.0, 0.0)
    alone = alone / cells
    if alone * n_around * math.e > 1.0:  # rho e^(-n rho) peaks at rho = 1 / n
        return CompanyBar(0, math.nan, math.nan)
    rho = alone
    for _ in range(100):  # the smaller root of rho = alone * e^(n rho)
        rho = alone * math.exp(n_around * rho)
    share = min(1.0, rho * cells / events)
    mu = n_around * rho
    term, tail, bar = math.exp(-mu), 1.0, 0  # tail = P(X >= bar), X ~ Poisson(mu)
    while share * tail > survival:
        tail -= term
        bar += 1
        term *= mu / bar
        if bar > MAX_BAR_SHARE * n_around:
            return CompanyBar(0, rho, share)
    return CompanyBar(bar, rho, share)


def signal_events(
    events: EventStream, width: int, height: int, dt: float
) -> tuple[np.ndarray, CompanyBar]:
    """(n_events,) bool, the events with at least the :func:`company_bar` of company, and
    the bar. ``dt``: slab length in the stream's time unit (> 0)."""
    import cv2

    if len(events) == 0:
        return np.ones(0, bool), CompanyBar(0, 0.0, 0.0)
    slab = _slabs(events, dt)
    company = _company(events, width, height, slab, RADIUS)
    pixels = width * height
    n_slabs = int(slab[-1]) + 1
    # Noise dense enough that no event is alone looks clean to the count of lone events.
    # Noise fires everywhere alike, an object in a part of the image: where the quietest
    # quarter of an 8x8 grid of blocks is that busy, nothing can be told apart.
    image = np.bincount(events.y.astype(np.int64) * width + events.x, minlength=pixels)
    blocks = cv2.resize(image.reshape(height, width).astype(np.float32), (8, 8),
                        interpolation=cv2.INTER_AREA)
    if np.percentile(blocks, 25) / n_slabs * _n_around(RADIUS) > 1.0:
        return np.ones(company.size, bool), CompanyBar(0, math.nan, math.nan)
    lone = company == 0
    alone = np.unique(slab[lone] * pixels + events.y[lone].astype(np.int64) * width
                      + events.x[lone]).size
    found = company_bar(alone, company.size, pixels * n_slabs)
    return company >= found.bar, found


@dataclass(frozen=True)
class DenoiseReport:
    """What :func:`denoised_split` did: the bar, its estimate and the events kept."""

    bar: int
    noise_rate: float
    noise_share: float
    kept: int
    total: int

    @property
    def too_dense(self) -> bool:
        """The noise was too dense to tell from the object, and every event was kept."""
        return self.bar == 0 and math.isnan(self.noise_rate)

    def line(self) -> str:
        """One log line."""
        if self.too_dense:
            return (f"events: the noise is too dense to tell from the object; the filter keeps "
                    f"all {self.total}")
        if self.bar == 0 and self.noise_share <= SURVIVAL:
            return (f"events: about {self.noise_share:.1%} look like sensor noise; the filter "
                    f"keeps all {self.total}")
        if self.bar == 0:
            return (f"events: about {self.noise_share:.0%} look like sensor noise, too dense to "
                    f"filter; the filter keeps all {self.total}")
        return (f"events: about {self.noise_share:.1%} look like sensor noise; the filter keeps "
                f"{self.kept} of {self.total} ({self.kept / self.total:.1%}), those with "
                f"{self.bar} or more events of other pixels close to them in space and time")


def denoised_split(split: SplitData, slab_views: float = 2.0) -> tuple[SplitData, DenoiseReport]:
    """A copy of ``split`` whose events are those :func:`company_bar` keeps.

    Args:
        split: the split.
        slab_views: slab length in view intervals (``t_max / (n_views - 1)``).

    Returns:
        ``(split, report)``; the split is ``split`` itself when every event is kept.
    """
    ev = split.events
    total = len(ev)
    if total == 0 or split.n_views < 2 or split.t_max <= 0:
        return split, DenoiseReport(0, 0.0, 0.0, total, total)
    dt = slab_views * split.t_max / (split.n_views - 1)
    keep, found = signal_events(ev, split.width, split.height, dt)
    kept = int(np.count_nonzero(keep))
    report = DenoiseReport(found.bar, found.noise_rate, found.noise_share, kept, total)
    if kept == total:
        return split, report
    return dataclasses.replace(split, events=kept_events(ev, keep)), report


def kept_events(events: EventStream, keep: np.ndarray | slice) -> EventStream:
    """The events ``keep`` selects (a boolean mask or a slice), as a stream whose views stay
    where the file put them (``t_end``)."""
    return EventStream(events.x[keep], events.y[keep], events.t[keep], events.p[keep],
                       path=events.path, polarity_note=events.polarity_note,
                       t_end=events.t_max)
