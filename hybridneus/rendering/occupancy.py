"""An occupancy grid over the sampling box, refreshed from the SDF, for empty-space skipping.

A cell is occupied when the surface may pass through it: ``|sdf(centre)|`` is below half the
cell diagonal plus a band of ``band / inv_s`` (the width where NeuS's density is non-zero), or
the SDF changes sign among its 26 neighbours; the result is dilated by one cell. Samples
are then placed only in occupied cells.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F


class OccupancyGrid(torch.nn.Module):
    """Boolean grid of ``resolution**3`` cells spanning ``aabb``; state lives in buffers.

    Args:
        aabb: box (6,) as (x_min, y_min, z_min, x_max, y_max, z_max).
        resolution: cells per axis.

    Example:
        >>> grid = OccupancyGrid(torch.tensor([-1., -1, -1, 1, 1, 1]), 64)  # doctest: +SKIP
        >>> grid.update(field.sdf, inv_s=40.0)  # doctest: +SKIP
        >>> mask = grid.query(points)  # doctest: +SKIP
    """

    def __init__(self, aabb: torch.Tensor, resolution: int = 64) -> None:
        super().__init__()
        self.resolution = int(resolution)
        self.register_buffer("aabb", aabb.detach().clone().float())
        self.register_buffer(
            "occupied", torch.ones((resolution,) * 3, dtype=torch.bool), persistent=True
        )

    def cell_centres(self) -> torch.Tensor:
        """Centres of all cells, (resolution**3, 3), in x-major order matching ``occupied``."""
        r = self.resolution
        lo, hi = self.aabb[:3], self.aabb[3:]
        axis = (torch.arange(r, device=lo.device, dtype=torch.float32) + 0.5) / r
        grid = torch.stack(torch.meshgrid(axis, axis, axis, indexing="ij"), dim=-1)
        return lo + grid.reshape(-1, 3) * (hi - lo)

    @torch.no_grad()
    def update(
        self,
        sdf_fn: Callable[[torch.Tensor], torch.Tensor],
        inv_s: float,
        band: float = 3.0,
        chunk: int = 65536,
    ) -> float:
        """Re-evaluate every cell from ``sdf_fn`` (no grad); return the occupied fraction.

        Args:
            sdf_fn: points (n, 3) -> sdf (n,).
            inv_s: current NeuS sharpness.
            band: multiples of ``1 / inv_s`` added to the half cell diagonal.
            chunk: points per call.

        Note:
            Not differentiable; runs under ``torch.no_grad``.
        """
        centres = self.cell_centres()
        sdf = torch.cat([sdf_fn(p) for p in centres.split(chunk)])
        cell = (self.aabb[3:] - self.aabb[:3]) / self.resolution
        threshold = 0.5 * float(cell.norm()) + band / max(float(inv_s), 1e-3)
        grid = sdf.reshape((1, 1) + (self.resolution,) * 3)
        near = grid.abs() <= threshold
        # A sign change among neighbours also marks the surface: with |grad sdf| > 1 (early
        # training) the band test alone can miss it, and a lost surface stops all learning.
        hi = F.max_pool3d(grid, kernel_size=3, stride=1, padding=1)
        lo = -F.max_pool3d(-grid, kernel_size=3, stride=1, padding=1)
        occ = (near | ((hi >= 0) & (lo <= 0))).float()
        occ = F.max_pool3d(occ, kernel_size=3, stride=1, padding=1)[0, 0] > 0
        # A grid that lost the surface entirely would stop all learning: keep everything.
        if not bool(occ.any()):
            occ = torch.ones_like(occ)
        self.occupied.copy_(occ)
        return float(occ.float().mean())

    def query(self, points: torch.Tensor) -> torch.Tensor:
        """Whether each point lies in an occupied cell, (n_points,) bool; outside the box: False.

        Note:
            Not differentiable.
        """
        lo, hi = self.aabb[:3].to(points), self.aabb[3:].to(points)
        rel = (points - lo) / (hi - lo)
        inside = ((rel >= 0) & (rel < 1)).all(dim=-1)
        idx = (rel * self.resolution).long().clamp(0, self.resolution - 1)
        occ = self.occupied.to(points.device)[idx[:, 0], idx[:, 1], idx[:, 2]]
        return occ & inside
