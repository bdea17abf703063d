"""Hot pixels: sensor pixels that fire on their own, far more often than their neighbours.

A real event sensor has a few pixels whose reset or comparator leaks, so that they fire tens
to hundreds of times a second whatever the light does. Over a recording in which the camera
or the object moves, an edge crosses many pixels and the event count per pixel varies slowly
across the image; a hot pixel stands alone, far above every pixel around it. A pixel is hot
when its count is at least :data:`MIN_RATIO` times the largest count of its neighbours
(each plus one) and at least :data:`MIN_EVENTS`. The largest neighbour, not a typical one,
keeps a thin line that the camera crossed again and again (a wire, a printed stroke) out:
the line's own pixels neighbour each other. The neighbours are the eight around the pixel
and the eight of its own colour under a 2x2 Bayer mosaic (two pixels away): behind a colour
filter an edge of one colour fires only every other pixel along its line, and each of those
stands far above its differently filtered neighbours.

Its events would ask the fit for a brightness change that no surface makes, so
``hybridneus convert`` leaves them out of the dataset it writes (``--keep-hot-pixels`` keeps
them) and says which pixels they were, and a fit leaves out those of any dataset it is
given (``estimate.hot_pixels``; the pixels go into the run's ``scene.yaml``, so that a
resumed fit leaves out the same). ``hybridneus info`` reports any it finds.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

#: Least count over the largest neighbour's for a hot pixel (each plus one) ...
MIN_RATIO = 5.0
#: ... and least events over the recording.
MIN_EVENTS = 50


@dataclass(frozen=True)
class HotPixels:
    """The hot pixels of a recording.

    Attributes:
        mask: (height, width) bool, True at a hot pixel.
        counts: (height, width) the events per pixel they were found from.
        ratio: (height, width) each pixel's count over its largest neighbour's (each plus 1;
            the neighbours as in the module docstring).
    """

    mask: np.ndarray
    counts: np.ndarray
    ratio: np.ndarray

    @property
    def n(self) -> int:
        return int(self.mask.sum())

    @property
    def events(self) -> int:
        """Events the hot pixels fired."""
        return int(self.counts[self.mask].sum())

    def pixels(self) -> list[tuple[int, int]]:
        """The hot pixels as ``(x, y)``, the loudest first."""
        ys, xs = np.nonzero(self.mask)
        order = np.argsort(-self.counts[ys, xs], kind="stable")
        return [(int(xs[k]), int(ys[k])) for k in order]

    def line(self) -> str:
        """One line for a report."""
        if not self.n:
            return "hot pixels: none"
        total = max(int(self.counts.sum()), 1)
        shown = ", ".join(f"({x}, {y}) x{self.ratio[y, x]:.0f}" for x, y in self.pixels()[:5])
        more = f" and {self.n - 5} more" if self.n > 5 else ""
        return (f"hot pixels: {self.n} fire far more than their neighbours ({shown}{more}); "
                f"{self.events:,} events, {self.events / total:.1%} of all")


def pixel_counts(x: np.ndarray, y: np.ndarray, width: int, height: int) -> np.ndarray:
    """(height, width) int64 events per pixel."""
    flat = np.asarray(y, np.int64) * width + np.asarray(x, np.int64)
    return np.bincount(flat, minlength=width * height).reshape(height, width)


def find_hot_pixels(counts: np.ndarray) -> HotPixels:
    """The hot pixels of an image of event counts (module docstring)."""
    from scipy.ndimage import maximum_filter

    counts = np.asarray(counts)
    ring = np.zeros((5, 5), bool)
    ring[1:4, 1:4] = True  # the eight around it
    ring[::2, ::2] = True  # the eight of its colour in a Bayer mosaic
    ring[2, 2] = False
    # Outside the image there are no neighbours (a mirror would make a pixel its own).
    around = maximum_filter(counts, footprint=ring, mode="constant", cval=0)
    ratio = (counts + 1.0) / (around + 1.0)
    mask = (ratio >= MIN_RATIO) & (counts >= MIN_EVENTS)
    return HotPixels(mask, counts, ratio)


def split_hot_pixels(split) -> HotPixels:
    """The hot pixels of a :class:`~hybridneus.data.dataset.SplitData`'s events."""
    ev = split.events
    return find_hot_pixels(pixel_counts(ev.x, ev.y, split.width, split.height))


def without_pixels(split, pixels: list) -> Any:
    """``split`` with the events of ``pixels`` (``(x, y)`` pairs) left out.

    The views stay where they were: the stream keeps the capture's last timestamp even when
    the last event was a hot pixel's. ``split`` is not changed.
    """
    import dataclasses

    from hybridneus.data.denoise import kept_events

    if not len(pixels):
        return split
    ev = split.events
    mask = np.zeros((split.height, split.width), bool)
    xy = np.asarray(pixels, np.int64).reshape(-1, 2)
    mask[xy[:, 1], xy[:, 0]] = True
    return dataclasses.replace(split, events=kept_events(ev, ~mask[ev.y, ev.x]))


__all__ = ["HotPixels", "MIN_EVENTS", "MIN_RATIO", "find_hot_pixels", "pixel_counts",
           "split_hot_pixels", "without_pixels"]
