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

__all__ = ["gather_rows", "scatter_rows", "interpolate_corners"]


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
        out = src.new_zeros((size, *src.shape[1:]))
        return out.index_add_(0, idx, src)

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


def _pairs(t: torch.Tensor) -> torch.Tensor:
    """(..., F) real with F even -> (...,) complex if F == 2, else (..., F // 2) complex."""
    c = torch.view_as_complex(t.unflatten(-1, (-1, 2)))
    return c.squeeze(-1) if c.shape[-1] == 1 else c


def _unpairs(c: torch.Tensor, n_features: int) -> torch.Tensor:
    """Inverse of :func:`_pairs`: (...,) or (..., F // 2) complex -> (..., F) real."""
    if n_features == 2:
        c = c.unsqueeze(-1)
    return torch.view_as_real(c).flatten(-2)


def _as_rows(table: torch.Tensor) -> torch.Tensor:
    """Table (size, F) -> the 1-D (F == 2), paired or real row view that is gathered."""
    f = table.shape[-1]
    if f % 2 == 0:
        return _pairs(table)
    return table.squeeze(-1) if f == 1 else table


def _from_rows(rows: torch.Tensor, n_features: int) -> torch.Tensor:
    """Inverse of :func:`_as_rows` on gathered or scattered rows."""
    if n_features % 2 == 0:
        return _unpairs(rows, n_features)
    return rows.unsqueeze(-1) if n_features == 1 else rows


def _weighted_corner_sum(vals: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """sum_c w[c] * vals[c]; vals (8, n, *k), w (8, n) -> (n, *k)."""
    if vals.dim() == 3:
        w = w.unsqueeze(-1)
    return (vals * w).sum(0)


def _corner_weight_grad(vals: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
    """d out / d w[c] contracted with g: Re(sum_k vals[c, n, k] * conj(g[n, k])) -> (8, n)."""
    prod = vals * (g.conj() if g.is_complex() else g)
    if prod.is_complex():
        prod = prod.real
    return prod.sum(-1) if prod.dim() == 3 else prod


class _InterpolateCorners(torch.autograd.Function):
    """out[n] = sum_c w[c, n] * table[idx[c, n]] for one grid level."""

    @staticmethod
    def forward(ctx, table: torch.Tensor, idx: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
        rows = _as_rows(table)
        n = idx.shape[1]
        vals = rows.index_select(0, idx.reshape(-1)).unflatten(0, (8, n))
        ctx.save_for_backward(table, idx, w)
        return _from_rows(_weighted_corner_sum(vals, w), table.shape[-1])

    @staticmethod
    def backward(ctx, grad_out: torch.Tensor):
        # Written with differentiable ops only: under create_graph=True autograd records this
        # pass, which gives the double backward the Eikonal loss needs.
        table, idx, w = ctx.saved_tensors
        n_features = table.shape[-1]
        g = _as_rows(grad_out.contiguous())
        grad_table = grad_w = None
        if ctx.needs_input_grad[0]:
            wk = w.unsqueeze(-1) if g.dim() == 2 else w
            contrib = (wk * g.unsqueeze(0)).flatten(0, 1)
            grad_table = _from_rows(_Scatter.apply(contrib, idx.reshape(-1), table.shape[0]),
                                    n_features)
        if ctx.needs_input_grad[2]:
            vals = _Gather.apply(_as_rows(table), idx.reshape(-1)).unflatten(0, (8, idx.shape[1]))
            grad_w = _corner_weight_grad(vals, g.unsqueeze(0))
        return grad_table, None, grad_w


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
    return _InterpolateCorners.apply(table, idx, w)
