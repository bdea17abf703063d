"""Multiresolution hash and dense feature grids (tiny-cuda-nn semantics) in pure PyTorch."""

from __future__ import annotations

import torch
from torch import nn

from hybridneus.errors import ConfigError

from .gather import interpolate_corners
from .levels import PRIMES, GridLevel, make_levels

__all__ = ["HashGrid", "DenseGrid", "level_corners"]

_INIT_RANGE = 1e-4


def level_corners(
    xt: torch.Tensor, level: GridLevel, index_dtype: torch.dtype = torch.int64
) -> tuple[torch.Tensor, torch.Tensor]:
    """Table rows and trilinear weights of the 8 cell corners around each point on one level.

    Args:
        xt: (3, n_points) positions in [0, 1]^3, point dimension innermost.
        level: the level's geometry (scale, dense side or hashed table size).
        index_dtype: torch.int64 or torch.int32 for the returned rows.

    Returns:
        idx: (8, n_points) rows in [0, level.table_size); corner c = 4 * dz + 2 * dy + dx.
        w: (8, n_points) trilinear weights (sum to 1 per point), dtype of ``xt``.

    Note:
        ``w`` is differentiable w.r.t. ``xt`` to any order (it is a product of
        ``frac(x * scale + 0.5)`` terms); ``idx`` is piecewise constant and carries no
        gradient.
    """
    n = xt.shape[1]
    pos = xt * level.scale + 0.5
    cell = pos.detach().floor()
    frac = pos - cell
    ic = cell.to(torch.int64)
    # (3, 2, n): weight of the low and high corner along each axis.
    wa = torch.stack((1.0 - frac, frac), dim=1)
    w = (wa[2].view(2, 1, 1, n) * wa[1].view(1, 2, 1, n) * wa[0].view(1, 1, 2, n)).view(8, n)
    if level.hashed:
        ix, iy, iz = ic[0], ic[1] * PRIMES[1], ic[2] * PRIMES[2]
        hx = torch.stack((ix, ix + 1))
        hy = torch.stack((iy, iy + PRIMES[1]))
        hz = torch.stack((iz, iz + PRIMES[2]))
        idx = hz.view(2, 1, 1, n) ^ hy.view(1, 2, 1, n) ^ hx.view(1, 1, 2, n)
        idx = (idx & (level.table_size - 1)).view(8, n)
    else:
        s = level.side
        # Points outside [0, 1]^3 are clamped to the border cell so rows stay in range.
        ic = ic.clamp_(0, s - 2)
        base = ic[0] + ic[1] * s + ic[2] * (s * s)
        offsets = torch.tensor(
            [dz * s * s + dy * s + dx for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)],
            dtype=torch.int64,
            device=xt.device,
        )
        idx = base.unsqueeze(0) + offsets.unsqueeze(1)
    return idx.to(index_dtype), w


class _MultiresGrid(nn.Module):
    """Shared machinery of :class:`HashGrid` and :class:`DenseGrid`."""

    def __init__(
        self,
        levels: list[GridLevel],
        n_features_per_level: int,
        dtype: torch.dtype,
        owner: str,
    ) -> None:
        super().__init__()
        if n_features_per_level < 1:
            raise ConfigError(
                f"{owner}: n_features_per_level must be >= 1, got {n_features_per_level}"
            )
        if dtype not in (torch.float32, torch.float64):
            raise ConfigError(f"{owner}: dtype must be torch.float32 or torch.float64, got {dtype}")
        self.levels = levels
        self.n_levels = len(levels)
        self.n_features_per_level = n_features_per_level
        self.out_dim = self.n_levels * n_features_per_level
        self.active_levels = self.n_levels
        self.index_dtype = torch.int64
        self.tables = nn.ParameterList(
            nn.Parameter(
                torch.empty(lvl.table_size, n_features_per_level, dtype=dtype).uniform_(
                    -_INIT_RANGE, _INIT_RANGE
                )
            )
            for lvl in levels
        )

    def set_active_levels(self, n: int) -> None:
        """Use only the ``n`` coarsest levels; finer levels are skipped and output zeros.

        Args:
            n: number of active levels, clamped to [1, n_levels].
        """
        self.active_levels = max(1, min(int(n), self.n_levels))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Encode points.

        Args:
            x: (*, 3) positions in [0, 1]^3 (any float dtype; cast to the table dtype).

        Returns:
            features: (*, out_dim), level-major: ``[l0 f0, l0 f1, l1 f0, ...]``. Inactive
            levels are zero.

        Note:
            Differentiable w.r.t. the tables and ``x``, to any order (double backward works,
            so an Eikonal loss on d/dx can be optimised). Inactive levels are not computed
            and receive no gradient. The output is continuous in ``x`` but its derivative
            jumps at cell faces (trilinear interpolation).
        """
        if x.shape[-1] != 3:
            raise ValueError(f"{type(self).__name__}: expected x of shape (*, 3), got "
                             f"{tuple(x.shape)}")
        batch = x.shape[:-1]
        table0 = self.tables[0]
        xt = x.reshape(-1, 3).to(table0.dtype).t().contiguous()
        n = xt.shape[1]
        f = self.n_features_per_level
        outs = []
        for lvl, table in zip(self.levels, self.tables, strict=True):
            if lvl.index < self.active_levels:
                idx, w = level_corners(xt, lvl, self.index_dtype)
                outs.append(interpolate_corners(table, idx, w))
            else:
                outs.append(xt.new_zeros(n, f))
        return torch.cat(outs, dim=1).view(*batch, self.out_dim)

    def extra_repr(self) -> str:
        dense = sum(not lvl.hashed for lvl in self.levels)
        return (
            f"n_levels={self.n_levels}, n_features_per_level={self.n_features_per_level}, "
            f"dense_levels={dense}, active_levels={self.active_levels}, "
            f"resolution={self.levels[0].resolution}..{self.levels[-1].resolution}"
        )


class HashGrid(_MultiresGrid):
    """Multiresolution hash encoding (Instant-NGP) with tiny-cuda-nn's exact level rules.

    Level l has ``scale = base_resolution * b**l - 1`` with
    ``b = exp(ln(finest_resolution / base_resolution) / (n_levels - 1))``; a point x maps to
    ``x * scale + 0.5``. A level is dense (row ``x + y*side + z*side**2``, no collisions) while
    its ``side**3`` vertices fit in ``T = 2**log2_hashmap_size`` rows, with
    ``side = floor(scale + 0.5) + 2`` and a table of ``side**3`` rows; finer levels use ``T``
    rows indexed by ``(x * 1) ^ (y * 2654435761) ^ (z * 805459861) & (T - 1)``. Features
    are initialised U(-1e-4, 1e-4) and trilinearly interpolated. See docs/grids.md.

    Args:
        n_levels: number of levels L. Default: 16.
        n_features_per_level: features F per level. Default: 2.
        log2_hashmap_size: log2 of the maximum rows per level T. Default: 19.
        base_resolution: coarsest resolution. Default: 16.
        finest_resolution: finest resolution. Default: 2048.
        dtype: table dtype, torch.float32 or torch.float64. Default: torch.float32.

    Attributes:
        out_dim: ``n_levels * n_features_per_level``.
        levels: list of :class:`GridLevel` (scale, resolution, side, hashed, table_size).
        tables: one (table_size, F) parameter per level.
        active_levels: number of levels in use (see :meth:`set_active_levels`).

    Example:
        >>> from hybridneus.grids import HashGrid
        >>> enc = HashGrid(n_levels=4, log2_hashmap_size=12, finest_resolution=64)
        >>> enc(torch.rand(5, 7, 3)).shape
        torch.Size([5, 7, 8])
    """

    def __init__(
        self,
        n_levels: int = 16,
        n_features_per_level: int = 2,
        log2_hashmap_size: int = 19,
        base_resolution: float = 16,
        finest_resolution: float = 2048,
        dtype: torch.dtype = torch.float32,
    ) -> None:
        if not 3 <= log2_hashmap_size <= 30:
            raise ConfigError(
                f"HashGrid: log2_hashmap_size must be in [3, 30], got {log2_hashmap_size}"
            )
        levels = make_levels(n_levels, base_resolution, finest_resolution,
                             2**log2_hashmap_size, "HashGrid")
        super().__init__(levels, n_features_per_level, dtype, "HashGrid")
        self.log2_hashmap_size = log2_hashmap_size


class DenseGrid(_MultiresGrid):
    """Multiresolution dense grid: :class:`HashGrid` with every level dense (no hashing).

    Same scale, offset, init and output layout as :class:`HashGrid`; level l stores
    ``side**3`` rows with ``side = floor(scale + 0.5) + 2``, so memory grows with the cube
    of ``finest_resolution`` (~17 MB of float32 for the defaults). For small volumes.

    Args:
        n_levels: number of levels L. Default: 8.
        n_features_per_level: features F per level. Default: 2.
        base_resolution: coarsest resolution. Default: 16.
        finest_resolution: finest resolution. Default: 128.
        dtype: table dtype, torch.float32 or torch.float64. Default: torch.float32.
    """

    def __init__(
        self,
        n_levels: int = 8,
        n_features_per_level: int = 2,
        base_resolution: float = 16,
        finest_resolution: float = 128,
        dtype: torch.dtype = torch.float32,
    ) -> None:
        levels = make_levels(n_levels, base_resolution, finest_resolution, None, "DenseGrid")
        super().__init__(levels, n_features_per_level, dtype, "DenseGrid")
