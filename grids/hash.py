"""Multiresolution hash and dense feature grids (tiny-cuda-nn semantics) in pure PyTorch."""

from __future__ import annotations

import torch
from torch import nn

from hybridneus.errors import ConfigError

from .gather import gather_levels, trilinear
from .levels import PRIMES, GridLevel, make_levels

__all__ = ["HashGrid", "DenseGrid"]

_INIT_RANGE = 1e-4


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
        #: Row-index dtype: int32 halves the index traffic (measured faster on CPU, see
        #: benchmarks/bench_grids.py); int64 gives identical rows.
        self.index_dtype = torch.int32
        #: Points per chunk, bounding the per-level (8, chunk * F) temporaries; None picks
        #: 2**18 on CPU and 2**20 on CUDA, as measured in benchmarks/bench_grids.py.
        self.chunk_size: int | None = None
        #: Largest (levels, 8, n * F) corner buffer, in bytes, encoded with all levels
        #: batched; larger batches go level by level (CPU only; CUDA always batches).
        self.batch_bytes = 32 << 20
        #: Gather from all levels' tables joined into one (see :func:`gather_levels`); None
        #: joins them on CUDA only.
        self.joined_gather: bool | None = None
        # Coarse levels are dense and fine ones hashed (side grows with the level).
        self.n_dense = sum(not lvl.hashed for lvl in levels)
        if any(lvl.hashed for lvl in levels[: self.n_dense]):
            raise ConfigError(f"{owner}: dense levels must precede hashed levels")
        sizes = [lvl.table_size for lvl in levels]
        self._sizes = sizes
        #: One (table_size, n_features_per_level) parameter per level.
        self.tables = nn.ParameterList(
            nn.Parameter(
                torch.empty(size, n_features_per_level, dtype=dtype).uniform_(
                    -_INIT_RANGE, _INIT_RANGE
                )
            )
            for size in sizes
        )
        sides = torch.tensor([lvl.side for lvl in levels], dtype=torch.int64)
        corner = torch.tensor(
            [[dz, dy, dx] for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)], dtype=torch.int64
        )
        dense_offsets = corner[:, 0] * sides[:, None] ** 2 + corner[:, 1] * sides[:, None]
        dense_offsets = dense_offsets + corner[:, 2]
        buffers = {
            "sides": sides,
            "masks": torch.tensor(sizes, dtype=torch.int64) - 1,
            "dense_offsets": dense_offsets,  # (n_levels, 8)
        }
        for name, value in buffers.items():
            self.register_buffer("_" + name, value, persistent=False)
        self._scale_cache: dict[tuple[torch.dtype, torch.device], torch.Tensor] = {}

    def set_active_levels(self, n: int) -> None:
        """Use only the ``n`` coarsest levels; finer levels are skipped and output zeros.

        Args:
            n: number of active levels, clamped to [1, n_levels].
        """
        self.active_levels = max(1, min(int(n), self.n_levels))

    def corners(self, xt: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Table rows of the 8 cell corners and the position inside the cell, active levels.

        Args:
            xt: (3, n_points) positions in [0, 1]^3, point dimension innermost, table dtype.

        Returns:
            idx: (n_active, 8, n_points) rows of each level's table, in [0, table_size);
                corner c = 4 * dz + 2 * dy + dx.
            frac: (n_active, 3, n_points) ``frac(x * scale + 0.5)``; the trilinear weight of
                corner (dx, dy, dz) is the product over axes of ``frac`` (bit 1) or
                ``1 - frac`` (bit 0).

        Note:
            ``frac`` is differentiable w.r.t. ``xt`` (d frac / d x = scale); ``idx`` is
            piecewise constant.
        """
        return self._corners(xt, 0, self.active_levels)

    def _scales(self, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
        """(n_levels,) level scales in ``dtype`` on ``device``, made once per pair.

        Built from the levels' Python floats, not kept as a buffer, so module.float()/.half()
        cannot round them; cached, because a fresh host-to-GPU copy on every call would make
        each encoding wait for the device.
        """
        key = (dtype, device)
        if key not in self._scale_cache:
            values = [lvl.scale for lvl in self.levels]
            self._scale_cache[key] = torch.tensor(values, dtype=dtype).to(device)
        return self._scale_cache[key]

    def _index_dtype(self) -> torch.dtype:
        # int32 rows only while every row number fits (huge dense levels need int64).
        return self.index_dtype if max(self._sizes) < 2**31 else torch.int64

    def _corners(self, xt: torch.Tensor, lo: int, hi: int) -> tuple[torch.Tensor, torch.Tensor]:
        """:meth:`corners` of levels ``lo .. hi - 1``: idx (hi - lo, 8, n), frac (hi - lo, 3, n)."""
        n_lev, n = hi - lo, xt.shape[1]
        scales = self._scales(xt.dtype, xt.device)[lo:hi]
        pos = xt.unsqueeze(0) * scales.view(n_lev, 1, 1) + 0.5
        cell = pos.detach().floor()
        frac = pos - cell  # (n_lev, 3, n)
        dtype = self._index_dtype()
        ic = cell.to(dtype)
        n_dense = max(0, min(self.n_dense, hi) - lo)  # dense levels come first
        idx = torch.empty(n_lev, 8, n, dtype=dtype, device=xt.device)
        if n_dense:
            sides = self._sides[lo : lo + n_dense].to(dtype).view(n_dense, 1)
            # Points outside [0, 1]^3 are clamped to the border cell so rows stay in range.
            icd = torch.minimum(ic[:n_dense].clamp_min(0), (sides - 2).unsqueeze(-1))
            base = icd[:, 0] + icd[:, 1] * sides + icd[:, 2] * (sides * sides)
            offsets = self._dense_offsets[lo : lo + n_dense].to(dtype).unsqueeze(-1)
            torch.add(base.unsqueeze(1), offsets, out=idx[:n_dense])
        n_hash = n_lev - n_dense
        if n_hash:
            ich = ic[n_dense:]
            masks = self._masks[lo + n_dense : hi].to(dtype).view(n_hash, 1, 1)
            # Masking each axis term first is exact for XOR; int32 products wrap modulo
            # 2**32 like tcnn's uint32 hash, so int32 and int64 give the same rows.
            p1, p2 = (_wrap(p, dtype) for p in PRIMES[1:])
            iy = ich[:, 1] * p1
            iz = ich[:, 2] * p2
            hx = torch.stack((ich[:, 0], ich[:, 0] + 1), dim=1) & masks
            hy = torch.stack((iy, iy + p1), dim=1) & masks
            hz = torch.stack((iz, iz + p2), dim=1) & masks
            h = (hz.view(n_hash, 2, 1, n) ^ hy.view(n_hash, 1, 2, n)).view(n_hash, 4, 1, n)
            torch.bitwise_xor(h, hx.view(n_hash, 1, 2, n), out=idx[n_dense:].view(n_hash, 4, 2, n))
        return idx, frac

    def _encode(self, xt: torch.Tensor) -> torch.Tensor:
        """(3, n) -> (n, out_dim): all levels at once for small batches, else level by level.

        Batching the levels costs fewer, larger ops, which wins while its
        (n_levels, 8, n * F) temporaries stay small. Above ``batch_bytes`` they no longer fit
        glibc's reusable heap: every call then maps and page-faults fresh memory, which cost
        more than the gathers themselves here, so larger chunks go level by level (<= 64
        bytes per point; benchmarks/bench_grids.py).
        """
        n, n_feat, n_act = xt.shape[1], self.n_features_per_level, self.active_levels
        size = n_act * 8 * n * n_feat * xt.element_size()
        if xt.is_cuda or size <= self.batch_bytes:
            feats = [self._encode_levels(xt, 0, n_act)]
        else:
            feats = [self._encode_levels(xt, lvl, lvl + 1) for lvl in range(n_act)]
        if n_act < self.n_levels:
            feats.append(xt.new_zeros(n, (self.n_levels - n_act) * n_feat))
        return feats[0] if len(feats) == 1 else torch.cat(feats, dim=1)

    def _encode_levels(self, xt: torch.Tensor, lo: int, hi: int) -> torch.Tensor:
        """(3, n) -> (n, (hi - lo) * F): levels ``lo .. hi - 1`` in one set of ops."""
        n, n_feat, n_lev = xt.shape[1], self.n_features_per_level, hi - lo
        idx, frac = self._corners(xt, lo, hi)
        if n_feat > 1:
            # Repeat per feature so every lerp runs on contiguous (n_lev, n * F) memory.
            frac = frac.unsqueeze(-1).expand(n_lev, 3, n, n_feat).reshape(n_lev, 3, n * n_feat)
        corners = gather_levels([self.tables[i] for i in range(lo, hi)], idx, self.joined_gather)
        feats = trilinear(corners, frac).view(n_lev, n, n_feat).transpose(0, 1)
        return feats.reshape(n, n_lev * n_feat)

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
            and their tables get no gradient (``.grad`` stays None). The output is continuous
            in ``x`` but its derivative jumps at cell faces (trilinear interpolation). Points
            outside [0, 1]^3 give defined but meaningless features (dense levels clamp to
            the border cell, hashed levels wrap).
        """
        if x.shape[-1] != 3:
            raise ValueError(
                f"{type(self).__name__}: expected x of shape (*, 3), got {tuple(x.shape)}"
            )
        batch = x.shape[:-1]
        xt = x.reshape(-1, 3).to(self.tables[0].dtype).t().contiguous()
        n = xt.shape[1]
        if n == 0:
            return xt.new_zeros(*batch, self.out_dim)
        chunk = self.chunk_size
        if chunk is None:
            chunk = 2**20 if xt.is_cuda else 2**18
        chunk = max(1, int(chunk))
        if n <= chunk:
            out = self._encode(xt)
        else:
            out = torch.cat([self._encode(xt[:, i : i + chunk]) for i in range(0, n, chunk)])
        return out.view(*batch, self.out_dim)

    def extra_repr(self) -> str:
        return (
            f"n_levels={self.n_levels}, n_features_per_level={self.n_features_per_level}, "
            f"dense_levels={self.n_dense}, active_levels={self.active_levels}, "
            f"resolution={self.levels[0].resolution}..{self.levels[-1].resolution}"
        )


def _wrap(prime: int, dtype: torch.dtype) -> int:
    """The prime as a value of ``dtype`` with the same low 32 bits (int32 wraps)."""
    if dtype == torch.int32 and prime >= 2**31:
        return prime - 2**32
    return prime


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
        tables: ``nn.ParameterList`` with one (table_size, F) parameter per level.
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
    of ``finest_resolution`` (3.7 M rows, 29 MB of float32 for the defaults). For small
    volumes.

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
