"""Which colour each pixel of an event sensor sees: a Bayer layout or none (monochrome).

A colour sensor (the DAVIS346C) puts a 2x2 Bayer pattern over its pixels and each pixel
fires for its own channel only; a monochrome one (most Prophesee sensors, the DVXplorer, the
DAVIS346 mono) fires for brightness. Layouts are named by the colours of the pattern's
pixels in the order (row 0, col 0), (row 0, col 1), (row 1, col 0), (row 1, col 1).
"""

from __future__ import annotations

import numpy as np

from hybridneus.errors import ConfigError

#: The Bayer layouts, and ``mono`` for a sensor without colour filters.
MOSAICS = ("RGGB", "BGGR", "GRBG", "GBRG", "mono")
_CHANNEL = {"R": 0, "G": 1, "B": 2}


def check_mosaic(name: str) -> str:
    """The canonical spelling of a mosaic name (``rggb`` -> ``RGGB``, ``Mono`` -> ``mono``).

    Raises:
        ConfigError: not a known layout.
    """
    text = str(name).strip()
    canon = "mono" if text.lower() in ("mono", "monochrome", "grey", "gray") else text.upper()
    if canon not in MOSAICS:
        raise ConfigError(f"mosaic: unknown sensor mosaic {name!r} (known: "
                          f"{', '.join(MOSAICS)})")
    return canon


def channel_table(mosaic: str) -> np.ndarray:
    """(2, 2) int64 channel (0 R, 1 G, 2 B) of each pattern position of a Bayer layout."""
    mosaic = check_mosaic(mosaic)
    if mosaic == "mono":
        raise ConfigError("mosaic: a monochrome sensor has no colour channels")
    return np.array([_CHANNEL[c] for c in mosaic], dtype=np.int64).reshape(2, 2)


def channel_image(height: int, width: int, mosaic: str = "RGGB") -> np.ndarray:
    """(height, width) int64 channel of every pixel of a Bayer layout."""
    table = channel_table(mosaic)
    return table[np.arange(height)[:, None] % 2, np.arange(width)[None, :] % 2]


def mosaic_weights(xy: np.ndarray, mosaic: str = "RGGB") -> np.ndarray:
    """(n, 3) float32 weights of the colour channels each pixel ``xy`` (n, 2) = (column, row)
    measures: one-hot for a Bayer layout, a third each for ``mono`` (whose field renders
    grey, so every channel carries the same brightness)."""
    xy = np.asarray(xy)
    if check_mosaic(mosaic) == "mono":
        return np.full((xy.shape[0], 3), 1.0 / 3.0, dtype=np.float32)
    channel = channel_table(mosaic)[xy[:, 1] % 2, xy[:, 0] % 2]
    return np.eye(3, dtype=np.float32)[channel]
