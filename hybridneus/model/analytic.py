"""Analytic signed distance fields with known colour patterns, for tests, demos and benchmarks.

Each class satisfies :class:`hybridneus.model.protocol.Field` in world coordinates: negative
SDF inside, gradients from autograd (so they match what a trained field returns), and a colour
that depends only on position, so that a coloured mesh can be checked against the pattern.

Colour patterns (``pattern=``):
    ``"position"``: RGB = clamp((p + 1) / 2, 0, 1), i.e. x, y, z mapped from [-1, 1] to [0, 1].
    ``"stripes"``: red where floor(x / stripe_width) is even, blue where it is odd.
    a fixed RGB tuple: that colour everywhere.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

ColorPattern = str | Sequence[float]


def position_color(points: torch.Tensor) -> torch.Tensor:
    """The ``"position"`` pattern: (n_points, 3) world points -> (n_points, 3) RGB in [0, 1]."""
    return ((points + 1.0) * 0.5).clamp(0.0, 1.0)


def stripe_color(points: torch.Tensor, width: float = 0.1) -> torch.Tensor:
    """The ``"stripes"`` pattern along x: red on even stripes, blue on odd ones."""
    odd = (torch.floor(points[:, 0] / width).remainder(2.0) > 0.5).to(points.dtype)
    rgb = torch.zeros_like(points)
    rgb[:, 0] = 1.0 - odd
    rgb[:, 2] = odd
    return rgb


class _AnalyticField:
    """Shared plumbing: device handling, autograd gradient, colour patterns."""

    def __init__(
        self,
        pattern: ColorPattern = "position",
        stripe_width: float = 0.1,
        device: str | torch.device = "cpu",
    ) -> None:
        self.device = torch.device(device)
        self.pattern = pattern
        self.stripe_width = float(stripe_width)
        if isinstance(pattern, str) and pattern not in ("position", "stripes"):
            raise ValueError(f"pattern {pattern!r}: expected 'position', 'stripes' or an RGB")

    def _sdf(self, points: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        """Signed distance at ``points`` (n_points, 3) -> (n_points,)."""
        return self._sdf(points.to(self.device, torch.float32))

    def sdf_and_gradient(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Signed distance (n_points,) and its gradient (n_points, 3), via autograd.

        Note:
            The returned tensors are detached; the gradient is exact where the SDF is smooth.
        """
        with torch.enable_grad():
            p = points.detach().to(self.device, torch.float32).requires_grad_(True)
            d = self._sdf(p)
            (g,) = torch.autograd.grad(d.sum(), p)
        return d.detach(), g.detach()

    def color(self, points: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
        """RGB (n_points, 3) in [0, 1]; the patterns ignore the view directions (n_points, 3)."""
        p = points.to(self.device, torch.float32)
        if isinstance(self.pattern, str):
            if self.pattern == "position":
                return position_color(p)
            return stripe_color(p, self.stripe_width)
        rgb = torch.tensor(list(self.pattern), dtype=torch.float32, device=self.device)
        return rgb.expand(p.shape[0], 3).clone()


class SphereField(_AnalyticField):
    """Exact SDF of a sphere: |p - centre| - radius."""

    def __init__(
        self,
        radius: float = 0.5,
        center: Sequence[float] = (0.0, 0.0, 0.0),
        pattern: ColorPattern = "position",
        stripe_width: float = 0.1,
        device: str | torch.device = "cpu",
    ) -> None:
        super().__init__(pattern, stripe_width, device)
        self.radius = float(radius)
        self.center = torch.tensor(list(center), dtype=torch.float32, device=self.device)

    def _sdf(self, points: torch.Tensor) -> torch.Tensor:
        return torch.linalg.vector_norm(points - self.center, dim=-1) - self.radius


class TorusField(_AnalyticField):
    """Exact SDF of a torus around the world y axis (major radius R, tube radius r)."""

    def __init__(
        self,
        major_radius: float = 0.5,
        minor_radius: float = 0.2,
        center: Sequence[float] = (0.0, 0.0, 0.0),
        pattern: ColorPattern = "position",
        stripe_width: float = 0.1,
        device: str | torch.device = "cpu",
    ) -> None:
        super().__init__(pattern, stripe_width, device)
        self.major_radius = float(major_radius)
        self.minor_radius = float(minor_radius)
        self.center = torch.tensor(list(center), dtype=torch.float32, device=self.device)

    def _sdf(self, points: torch.Tensor) -> torch.Tensor:
        q = points - self.center
        ring = torch.sqrt(q[:, 0] ** 2 + q[:, 2] ** 2) - self.major_radius
        return torch.sqrt(ring**2 + q[:, 1] ** 2) - self.minor_radius


class BoxField(_AnalyticField):
    """Exact SDF of an axis-aligned box with half extents ``half_size`` (optionally rounded)."""

    def __init__(
        self,
        half_size: Sequence[float] = (0.4, 0.3, 0.5),
        center: Sequence[float] = (0.0, 0.0, 0.0),
        rounding: float = 0.0,
        pattern: ColorPattern = "position",
        stripe_width: float = 0.1,
        device: str | torch.device = "cpu",
    ) -> None:
        super().__init__(pattern, stripe_width, device)
        self.half_size = torch.tensor(list(half_size), dtype=torch.float32, device=self.device)
        self.center = torch.tensor(list(center), dtype=torch.float32, device=self.device)
        self.rounding = float(rounding)

    def _sdf(self, points: torch.Tensor) -> torch.Tensor:
        q = (points - self.center).abs() - (self.half_size - self.rounding)
        outside = torch.linalg.vector_norm(q.clamp(min=0.0), dim=-1)
        inside = q.max(dim=-1).values.clamp(max=0.0)
        return outside + inside - self.rounding


class UnionField(_AnalyticField):
    """Union (pointwise minimum) of several analytic fields; colour from the first one.

    The minimum of exact SDFs is exact outside and a lower bound inside, which is enough for
    meshing tests with several disconnected parts (a body plus a small floater).
    """

    def __init__(self, *fields: _AnalyticField) -> None:
        if not fields:
            raise ValueError("UnionField needs at least one field")
        super().__init__(fields[0].pattern, fields[0].stripe_width, fields[0].device)
        self.fields = fields

    def _sdf(self, points: torch.Tensor) -> torch.Tensor:
        return torch.stack([f._sdf(points) for f in self.fields], dim=0).min(dim=0).values
