"""Event frames as pictures: red where brightness rose, blue where it fell."""

from __future__ import annotations

import numpy as np


def event_image(frame: np.ndarray, background: str = "white") -> np.ndarray:
    """(height, width, 3) uint8 RGB picture of a signed event frame.

    Intensity is scaled by the 99th percentile of the non-zero magnitudes (at least 1), so a
    few hot pixels do not wash out the rest.

    Args:
        frame: (height, width) signed event sums.
        background: ``white`` or ``black`` behind the events.
    """
    nonzero = np.abs(frame[frame != 0])
    scale = max(float(np.percentile(nonzero, 99)), 1.0) if nonzero.size else 1.0
    a = np.clip(np.abs(frame) / scale, 0.0, 1.0)[..., None]
    colour = np.where(frame[..., None] > 0, np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    base = np.ones(3) if background == "white" else np.zeros(3)
    return ((base * (1 - a) + colour * a) * 255).round().astype(np.uint8)
