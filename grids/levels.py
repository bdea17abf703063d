"""Geometry of a multiresolution grid: per-level scale, resolution, table size, dense or hashed."""

from __future__ import annotations

import math
from dataclasses import dataclass

from hybridneus.errors import ConfigError

__all__ = ["GridLevel", "PRIMES", "make_levels", "per_level_scale"]

#: Per-axis hash primes (x, y, z) of tiny-cuda-nn / Instant-NGP.
PRIMES = (1, 2654435761, 805459861)


@dataclass(frozen=True)
class GridLevel:
    """One level of a multiresolution grid.

    Attributes:
        index: level number l, 0 = coarsest.
        scale: ``base_resolution * b**l - 1``; a point x in [0, 1] maps to ``x * scale + 0.5``.
        resolution: ``ceil(scale) + 1``, tiny-cuda-nn's vertex count per axis (reported).
        side: vertices per axis reachable from [0, 1]^3, ``floor(scale + 0.5) + 2``; dense
            levels index ``x + y * side + z * side**2`` over this many vertices.
        hashed: True when ``side**3`` exceeds the table-size cap T.
        table_size: rows of this level's table: ``side**3`` if dense, else T.
    """

    index: int
    scale: float
    resolution: int
    side: int
    hashed: bool
    table_size: int


def per_level_scale(n_levels: int, base_resolution: float, finest_resolution: float) -> float:
    """Growth factor b = exp(ln(finest / base) / (n_levels - 1)) (1.0 for a single level)."""
    if n_levels == 1:
        return 1.0
    return math.exp(math.log(finest_resolution / base_resolution) / (n_levels - 1))


def make_levels(
    n_levels: int,
    base_resolution: float,
    finest_resolution: float,
    max_table_size: int | None,
    owner: str = "HashGrid",
) -> list[GridLevel]:
    """Level geometry for a grid; ``max_table_size=None`` makes every level dense.

    Raises:
        ConfigError: on non-positive sizes or a table size that is not a power of two.
    """
    if n_levels < 1:
        raise ConfigError(f"{owner}: n_levels must be >= 1, got {n_levels}")
    if base_resolution < 1 or finest_resolution < base_resolution:
        raise ConfigError(
            f"{owner}: need 1 <= base_resolution <= finest_resolution, got "
            f"{base_resolution} and {finest_resolution}"
        )
    if max_table_size is not None and (max_table_size < 8 or max_table_size & (max_table_size - 1)):
        raise ConfigError(f"{owner}: table size must be a power of two >= 8, got {max_table_size}")
    b = per_level_scale(n_levels, base_resolution, finest_resolution)
    levels = []
    for lvl in range(n_levels):
        scale = base_resolution * b**lvl - 1.0
        if abs(scale - round(scale)) < 1e-9 * max(scale, 1.0):
            # Rounding noise of b**l: the finest level lands exactly on finest_resolution - 1.
            scale = float(round(scale))
        resolution = math.ceil(scale) + 1
        side = math.floor(scale + 0.5) + 2
        hashed = max_table_size is not None and side**3 > max_table_size
        table_size = max_table_size if hashed else side**3
        levels.append(GridLevel(lvl, scale, resolution, side, hashed, table_size))
    return levels
