"""Twice-differentiable gather, scatter and 8-corner interpolation on 1-D feature tables.

These autograd Functions are the only non-standard operations of the grid encodings. Each
one's backward is built from the others (gather <-> scatter are adjoint linear maps), so
autograd can differentiate a backward pass again: the Eikonal loss needs d(d sdf/dx)/d table
and d(d sdf/dx)/dx.

Tables with an even number of features F are viewed as ``F // 2`` complex numbers per row, so
the common F = 2 case gathers and scatters one 8-byte element per corner with the point
dimension innermost; on CPU this is several times faster than a trailing size-2 dimension.
"""

from __future__ import annotations

import torch

__all__ = ["gather_rows", "scatter_rows", "gather_levels", "interpolate_corners", "trilinear"]


class _Gather(torch.autograd.Function):
    """rows = table[idx]; table (size, *feat), idx (n,) -> (n, *feat)."""

    @staticmethod
    def forward(ctx, table: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
        ctx.save_for_backward(idx)
        ctx.size = table.shape[0]
        return table.index_select(0, idx)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        (idx,) = ctx.saved_tensors
        return _Scatter.apply(grad, idx, ctx.size), None


class _Scatter(torch.autograd.Function):
    """out = zeros(size, *feat); out[idx] += src (duplicates accumulate)."""

    @staticmethod
    def forward(ctx, src: torch.Tensor, idx: torch.Tensor, size: int) -> torch.Tensor:
        ctx.save_for_backward(idx)
        return _scatter_impl(src, idx, size)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        (idx,) = ctx.saved_tensors
        return _Gather.apply(grad, idx), None, None


def gather_rows(table: torch.Tensor, idx: torch.Tensor) -> torch.Tensor:
    """Twice-differentiable ``table[idx]``.

    Args:
        table: (size, *feat) any float or complex dtype.
        idx: (n,) int32 or int64 row indices in [0, size).

    Returns:
        rows: (n, *feat).

    Note:
        Differentiable w.r.t. ``table`` to any order (the backward is :func:`scatter_rows`,
        whose backward is this gather). Not differentiable w.r.t. ``idx``.
    """
    return _Gather.apply(table, idx)


def scatter_rows(src: torch.Tensor, idx: torch.Tensor, size: int) -> torch.Tensor:
    """Twice-differentiable scatter-add of ``src`` rows into a zero table of ``size`` rows.

    Args:
        src: (n, *feat).
        idx: (n,) int32 or int64 row indices in [0, size).
        size: number of rows of the result.

    Returns:
        table: (size, *feat) with ``table[idx[i]] += src[i]``.

    Note:
        Differentiable w.r.t. ``src`` to any order (the backward is :func:`gather_rows`).
    """
    return _Scatter.apply(src, idx, size)


def _to_rows(flat: torch.Tensor, n_features: int) -> torch.Tensor:
    """Real (..., n * F) -> the gathered-row layout: complex pairs for even F, else real.

    On CPU: (rows,) for F in (1, 2); (rows, F // 2) complex for even F > 2; (rows, F) for
    odd F > 1. On CUDA always real: (rows,) for F = 1, else (rows, F).
    """
    if n_features % 2 == 0 and not flat.is_cuda:
        # CUDA atomics on real rows beat complex ones; the CPU kernels prefer one 8-byte item.
        c = torch.view_as_complex(flat.reshape(-1, n_features // 2, 2))
        return c.squeeze(-1) if n_features == 2 else c
    return flat.reshape(-1) if n_features == 1 else flat.reshape(-1, n_features)


def _table_rows(table: torch.Tensor) -> torch.Tensor:
    """Table (size, F) -> its row view (see :func:`_to_rows`); shares memory."""
    return _to_rows(table, table.shape[-1])


def _to_flat(rows: torch.Tensor, lead: int) -> torch.Tensor:
    """Gathered rows (lead * n, *k) -> real (lead, n * F)."""
    if rows.is_complex():
        rows = torch.view_as_real(rows)
    return rows.reshape(lead, -1)


def _scatter_impl(src: torch.Tensor, idx: torch.Tensor, size: int) -> torch.Tensor:
    out = src.new_zeros((size, *src.shape[1:]))
    if src.dim() == 1 and idx.dtype == torch.int64:
        # 1-D scatter_add_ is the fastest accumulate on CPU (anchors: ~5x embedding backward).
        return out.scatter_add_(0, idx, src)
    return out.index_add_(0, idx, src)


class _GatherLevels(torch.autograd.Function):
    """Corner values of every level: 8 outputs, corner c is (n_levels, n * F) real.

    Each level keeps its own small table, so gathers and scatters stay in cache and the
    per-level gradient buffers are small enough for the allocator to reuse. Returning the
    corners as separate outputs lets the interpolation run on (n_levels, n * F) tensors
    without autograd materialising (n_levels, 8, n * F) gradients per corner.
    """

    @staticmethod
    def forward(ctx, idx: torch.Tensor, *tables: torch.Tensor) -> tuple[torch.Tensor, ...]:
        n_lev, _, n = idx.shape
        n_features = tables[0].shape[-1]
        out = tables[0].new_empty(n_lev, 8, n * n_features)
        for lvl, table in enumerate(tables):
            dst = _to_rows(out[lvl], n_features)
            torch.index_select(_table_rows(table), 0, idx[lvl].reshape(-1), out=dst)
        ctx.save_for_backward(idx)
        ctx.sizes = [t.shape[0] for t in tables]
        return out.unbind(1)

    @staticmethod
    def backward(ctx, *grads: torch.Tensor):
        # Differentiable ops only (_ScatterCorners), so this pass can be differentiated.
        (idx,) = ctx.saved_tensors
        n_features = grads[0].shape[-1] // idx.shape[-1]
        out = []
        for lvl, size in enumerate(ctx.sizes):
            if not ctx.needs_input_grad[lvl + 1]:
                out.append(None)
                continue
            srcs = [g[lvl] for g in grads]
            rows = _ScatterCorners.apply(idx[lvl], size, n_features, *srcs)
            out.append(_to_flat(rows, size))
        return None, *out


class _ScatterCorners(torch.autograd.Function):
    """rows = zeros(size); rows[idx[c]] += src_c for the 8 corners of one level.

    Scattering corner by corner avoids stacking the 8 gradients into one buffer.
    """

    @staticmethod
    def forward(ctx, idx: torch.Tensor, size: int, n_features: int, *srcs: torch.Tensor):
        first = _to_rows(srcs[0].contiguous(), n_features)
        out = first.new_zeros((size, *first.shape[1:]))
        if first.dim() == 1 and not first.is_cuda:
            # 1-D scatter_add_ with int64 indices ran ~1.7x faster than index_add_ with int32
            # on CPU, conversion included (benchmarks/bench_grids.py).
            idx64 = idx.long()
            for c, src in enumerate(srcs):
                out.scatter_add_(0, idx64[c], _to_rows(src.contiguous(), n_features))
        else:
            for c, src in enumerate(srcs):
                out.index_add_(0, idx[c], _to_rows(src.contiguous(), n_features))
        ctx.save_for_backward(idx)
        ctx.n_features = n_features
        return out

    @staticmethod
    def backward(ctx, grad: torch.Tensor):
        (idx,) = ctx.saved_tensors
        gathered = [_to_flat(_Gather.apply(grad, idx[c]), 1).view(-1) for c in range(8)]
        return None, None, None, *gathered


class _GatherLevelsJoined(torch.autograd.Function):
    """:class:`_GatherLevels` from the levels' tables joined into one: a fixed handful of
    kernels whatever the number of levels, where the per-level path launches one gather per
    level and 8 scatters per level in the backward."""

    @staticmethod
    def forward(ctx, idx: torch.Tensor, *tables: torch.Tensor) -> tuple[torch.Tensor, ...]:
        n_lev, _, n = idx.shape
        n_features = tables[0].shape[-1]
        sizes = [t.shape[0] for t in tables]
        rows = (idx + _row_offsets(sizes, idx.dtype, idx.device).view(n_lev, 1, 1)).reshape(-1)
        out = torch.cat(tables).index_select(0, rows)
        ctx.save_for_backward(rows)
        ctx.sizes, ctx.n_features = sizes, n_features
        return out.view(n_lev, 8, n * n_features).unbind(1)

    @staticmethod
    def backward(ctx, *grads: torch.Tensor):
        (rows,) = ctx.saved_tensors
        n_features = ctx.n_features
        # stack, scatter and split are differentiable, so this pass can be differentiated
        src = torch.stack(grads, dim=1).reshape(-1, n_features)
        joined = _Scatter.apply(src, rows, sum(ctx.sizes))
        parts = joined.split(ctx.sizes)
        return None, *(part if ctx.needs_input_grad[i + 1] else None
                       for i, part in enumerate(parts))


_OFFSETS: dict[tuple, torch.Tensor] = {}


def _row_offsets(sizes: list[int], dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """First row of each table in the joined table, made once per layout and device (a
    fresh host-to-GPU copy per call would make the gather wait for the device)."""
    key = (tuple(sizes), dtype, device)
    if key not in _OFFSETS:
        starts = [sum(sizes[:i]) for i in range(len(sizes))]
        _OFFSETS[key] = torch.tensor(starts, dtype=dtype).to(device)
    return _OFFSETS[key]


def gather_levels(
    tables: list[torch.Tensor], idx: torch.Tensor, joined: bool | None = None
) -> tuple[torch.Tensor, ...]:
    """The 8 corner values of every level, twice differentiable w.r.t. the tables.

    Args:
        tables: n_levels tables, each (table_size_l, F), contiguous, same dtype.
        idx: (n_levels, 8, n_points) int64 (or int32) rows of each level's table.
        joined: gather from the tables joined into one (a copy per call; one gather, and one
            scatter in the backward) rather than level by level (one gather per level, 8
            scatters per level). ``None``: joined on CUDA, where every kernel launch costs
            about as much as the work of a training batch; level by level on the CPU, where
            small per-level tables stay in cache (benchmarks/bench_grids.py). The results
            are the same.

    Returns:
        corners: 8 tensors (corner c = 4 * dz + 2 * dy + dx), each (n_levels, n_points * F),
        i.e. (n_levels, n_points, F) flattened.

    Note:
        Differentiable w.r.t. the tables to any order; not w.r.t. ``idx``.
    """
    if joined is None:
        joined = idx.is_cuda
    if joined:
        if sum(t.shape[0] for t in tables) >= 2**31:
            idx = idx.long()  # joined row numbers outgrow int32
        return _GatherLevelsJoined.apply(idx, *tables)
    return _GatherLevels.apply(idx, *tables)


def trilinear(corners: tuple[torch.Tensor, ...], frac: torch.Tensor) -> torch.Tensor:
    """Trilinear interpolation as 7 lerps.

    Args:
        corners: 8 tensors (*, m), corner c = 4 * dz + 2 * dy + dx.
        frac: (*, 3, m) position inside the cell along x, y, z in [0, 1).

    Returns:
        values: (*, m).

    Note:
        ``torch.lerp`` is differentiable to any order in all arguments.
    """
    fx, fy, fz = frac.unbind(-2)
    v = corners
    c00 = torch.lerp(v[0], v[1], fx)
    c10 = torch.lerp(v[2], v[3], fx)
    c01 = torch.lerp(v[4], v[5], fx)
    c11 = torch.lerp(v[6], v[7], fx)
    return torch.lerp(torch.lerp(c00, c10, fy), torch.lerp(c01, c11, fy), fz)


def interpolate_corners(table: torch.Tensor, idx: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Weighted sum of 8 gathered table rows per point (one level of a feature grid).

    Args:
        table: (table_size, n_features) float32 or float64, contiguous.
        idx: (8, n_points) int32 or int64 corner rows in [0, table_size).
        w: (8, n_points) interpolation weights, same dtype as ``table``.

    Returns:
        features: (n_points, n_features) with ``sum_c w[c] * table[idx[c]]``.

    Note:
        Differentiable w.r.t. ``table`` and ``w`` to any order; the backward pass uses
        :func:`scatter_rows` / :func:`gather_rows` so it can itself be differentiated.
        Not differentiable w.r.t. ``idx``.
    """
    n_features = table.shape[-1]
    if n_features > 1:
        w = w.unsqueeze(-1).expand(*w.shape, n_features).reshape(8, -1)
    corners = gather_levels([table], idx.unsqueeze(0))
    out = corners[0] * w[0]
    for c in range(1, 8):
        out = out + corners[c] * w[c]
    return out.view(-1, n_features)
