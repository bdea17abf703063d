"""Whether the events sit where the cameras look: a file's x and y columns exchanged.

An object-centred capture images the scene's centre (the origin, which the cameras look at)
near the middle of its events. Events whose x and y were exchanged on the way into the file
still fit the sensor when the object's image does, so no range check notices them; but their
centre then sits at the transpose of where the cameras look. This module only reports: the
caller decides how loudly.
"""

from __future__ import annotations

import numpy as np
import torch

from hybridneus.data.dataset import SplitData
from hybridneus.data.hull import project_to_pixels

#: At most this many events (a regular subsample) and views go into the centres.
MAX_EVENTS = 1_000_000
MAX_VIEWS = 32
#: The events' centre must miss the cameras' aim by this share of the image's short side, and
#: the transposed centre must be at least this many times closer, before anything is said.
MIN_MISS = 0.1
MIN_GAIN = 4.0


def looked_at_pixel(split: SplitData) -> tuple[float, float] | None:
    """The median pixel (column, row) at which the views see the world origin, or ``None``
    when it is behind every sampled camera."""
    step = max(1, split.n_views // MAX_VIEWS)
    origin = torch.zeros(1, 3, dtype=torch.float64)
    seen = []
    for view in range(0, split.n_views, step):
        u, v, front = (a[0].item() for a in project_to_pixels(split, view, origin))
        if front:
            seen.append((u, v))
    if not seen:
        return None
    u, v = np.median(np.asarray(seen, dtype=np.float64), axis=0)
    return float(u), float(v)


def transposed_events(split: SplitData) -> str | None:
    """A one-line warning when the split's events look transposed (x and y exchanged), else
    ``None``. Says nothing on few events, square-ish aims (the centre on the image diagonal)
    or events that fit neither way."""
    ev = split.events
    if len(ev) < 1000:
        return None
    aim = looked_at_pixel(split)
    if aim is None:
        return None
    stride = max(1, len(ev) // MAX_EVENTS)
    mx = float(ev.x[::stride].mean(dtype=np.float64)) + 0.5
    my = float(ev.y[::stride].mean(dtype=np.float64)) + 0.5
    u0, v0 = aim
    direct = float(np.hypot(mx - u0, my - v0))
    swapped = float(np.hypot(my - u0, mx - v0))
    if direct < MIN_MISS * min(split.width, split.height) or swapped * MIN_GAIN > direct:
        return None
    where = f" ({ev.path})" if ev.path is not None else ""
    return (f"the events{where} are centred on pixel ({mx:.0f}, {my:.0f}) but the cameras look "
            f"at ({u0:.0f}, {v0:.0f}); with x and y exchanged they would match: are the file's "
            "x and y columns swapped?")
