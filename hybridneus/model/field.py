"""The hybrid NeuS field: a feature grid with small SDF and colour heads.

``HybridField`` implements :class:`hybridneus.model.protocol.Field`. World points are encoded
by a multiresolution grid spanning the volume [-1, 1]^3, or by annealed frequencies for the
``eventneus`` preset, and

- the SDF head maps ``[x, encoding]`` through Softplus(beta=100) layers to
  ``1 + feature_dim`` values (SDF first), geometrically initialised to a sphere;
- the colour head maps ``[SH(view dir), normal = grad SDF, features (, PE(x))]`` to RGB
  through a sigmoid;
- the NeuS sharpness is ``inv_s = exp(10 v)`` with a learned scalar ``v``;
- the background is the dataset's constant colour;
- the crop cylinder of the scene preset (``x^2 + z^2 <= r^2``, ``y_min <= y <= y_max``) is
  kept in buffers: rendering scales opacity by a soft indicator of it, and the public
  :meth:`HybridField.sdf` returns ``max(sdf, crop_sdf)`` so meshes never leave it.
"""

from __future__ import annotations

import math
from typing import Any

import torch
from torch import nn

from hybridneus.config import FieldConfig, GridConfig
from hybridneus.data.crop import crop_sdf
from hybridneus.errors import ConfigError
from hybridneus.model.eventneus import FlushedSoftplus, geometric_init_, make_mlp
from hybridneus.model.protocol import as_points


def _make_position_encoding(grid: GridConfig) -> tuple[nn.Module, bool]:
    """Return (encoder, expects_unit_cube_input)."""
    from hybridneus.grids import DenseGrid, FrequencyEncoding, HashGrid

    if grid.kind == "hash":
        enc = HashGrid(
            n_levels=grid.n_levels,
            n_features_per_level=grid.n_features,
            log2_hashmap_size=grid.log2_table_size,
            base_resolution=grid.base_resolution,
            finest_resolution=grid.max_resolution,
        )
        return enc, True
    if grid.kind == "dense":
        enc = DenseGrid(
            n_levels=grid.n_levels,
            n_features_per_level=grid.n_features,
            base_resolution=grid.base_resolution,
            finest_resolution=grid.max_resolution,
        )
        return enc, True
    if grid.kind == "frequency":
        enc = FrequencyEncoding(
            grid.n_frequencies, include_input=False, n_fmin=grid.frequency_start, n_anneal=1
        )
        return enc, False
    raise ConfigError(
        f"grid.kind: unknown encoding {grid.kind!r}; expected hash, dense or frequency"
    )


class HybridField(nn.Module):
    """Grid-encoded NeuS SDF with a view-dependent colour head (see the module docstring).

    Args:
        grid: encoding configuration.
        field: head configuration.
        background: RGB in [0, 1] composited behind the object (the scene preset's).
        crop: (radius, y_min, y_max) of the crop cylinder. Default: the whole volume.
        grey: render grey (the mean of the colour head's channels, and of the background):
            a monochrome sensor's events say nothing about colour.

    Attributes:
        device: where the parameters live.
        encoding: the position encoder (HashGrid, DenseGrid or FrequencyEncoding).
        variance: the learned scalar v (inv_s = exp(10 v)).

    Example:
        >>> f = HybridField(GridConfig(n_levels=4, max_resolution=32), FieldConfig())
        >>> f.sdf(np.zeros((1, 3), dtype=np.float32)).shape
        (1,)
    """

    def __init__(
        self,
        grid: GridConfig,
        field: FieldConfig,
        background: tuple[float, float, float] = (159 / 255,) * 3,
        crop: tuple[float, float, float] = (1.0, -1.0, 1.0),
        grey: bool = False,
    ) -> None:
        super().__init__()
        self.grey = bool(grey)
        from hybridneus.grids import FrequencyEncoding, SphericalHarmonics

        self.grid_config = grid
        self.field_config = field
        self.encoding, self._unit_cube = _make_position_encoding(grid)
        enc_dim = int(self.encoding.out_dim)
        self.sdf_net = make_mlp(
            3 + enc_dim,
            field.sdf_hidden,
            field.sdf_layers,
            1 + field.feature_dim,
            skips=field.sdf_skip,
            activation=FlushedSoftplus(field.softplus_beta),
        )
        radius = min(field.init_radius, 0.9 * float(crop[0]))
        geometric_init_(self.sdf_net, n_inputs_xyz=3, radius=radius, skips=field.sdf_skip)
        self.init_radius = radius
        self._center_sphere()
        self.sh = SphericalHarmonics(field.sh_degree)
        self.color_pe: nn.Module | None = None
        color_in = self.sh.out_dim + 3 + field.feature_dim
        if field.color_position_frequencies > 0:
            self.color_pe = FrequencyEncoding(field.color_position_frequencies, n_anneal=None)
            color_in += int(self.color_pe.out_dim)
        self.color_net = make_mlp(color_in, field.color_hidden, field.color_layers, 3, (),
                                  nn.ReLU())
        background_rgb = torch.tensor([float(c) for c in background])
        self.variance = nn.Parameter(torch.tensor(float(field.inv_s_init)))
        self.register_buffer("crop", torch.tensor([float(c) for c in crop]))
        bg = background_rgb.clamp(1e-3, 1 - 1e-3)
        self.register_buffer("background_const", bg)

    # ------------------------------------------------------------------ properties

    @property
    def device(self) -> torch.device:  # type: ignore[override]
        """Device of the parameters."""
        return self.variance.device

    def inv_s(self) -> torch.Tensor:
        """NeuS sharpness ``exp(10 v)``, a differentiable scalar clamped to [1e-6, 1e6]."""
        return torch.exp(self.variance * 10.0).clamp(1e-6, 1e6)

    def background(self) -> torch.Tensor:
        """Background RGB (3,) in [0, 1]."""
        bg = self.background_const
        return bg.mean().expand(3) if self.grey else bg

    # ------------------------------------------------------------------ schedules

    def update_step(self, step: float, total_steps: int) -> None:
        """Apply the coarse-to-fine schedule for ``step`` of ``total_steps`` (a fractional
        step: a re-planned schedule's position, :meth:`.Timeline.position`).

        Grid kinds open levels linearly from ``grid.start_levels`` to all at
        ``grid.opened_at * total_steps``; the frequency kind anneals its bands over as many
        steps.
        """
        g = self.grid_config
        if g.kind == "frequency":
            self.encoding.n_anneal = max(1, int(g.opened_at * total_steps))
            self.encoding.update_step(step)
            return
        full_at = max(1.0, g.opened_at * total_steps)
        extra = (g.n_levels - g.start_levels) * min(1.0, step / full_at)
        self.encoding.set_active_levels(int(g.start_levels + math.floor(extra)))

    def active_levels(self) -> int:
        """Active grid levels (or fully-on frequency bands)."""
        if self.grid_config.kind == "frequency":
            return self.encoding.full_bands()
        return int(self.encoding.active_levels)

    # ------------------------------------------------------------------ core (torch)

    def sdf_and_features(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Raw SDF (n_points,) and geometric features (n_points, feature_dim).

        Note:
            Differentiable to second order in ``points`` (for the Eikonal term).
        """
        enc_in = (points + 1.0) * 0.5 if self._unit_cube else points
        h = torch.cat([points, self.encoding(enc_in).to(points.dtype)], dim=-1)
        out = self.sdf_net(h)
        return out[:, 0], out[:, 1:]

    def sdf_gradient_features(
        self, points: torch.Tensor, create_graph: bool = True
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """SDF (n,), its gradient (n, 3) and features (n, F) with autograd.

        Args:
            points: (n_points, 3); need not require grad.
            create_graph: keep the graph of the gradient (training: Eikonal, normals).

        Note:
            With ``create_graph`` the gradient is differentiable (double backward through
            the grid), otherwise all outputs are detached.
        """
        with torch.enable_grad():
            x = points.detach().requires_grad_(True)
            sdf, feats = self.sdf_and_features(x)
            (grad,) = torch.autograd.grad(
                sdf, x, torch.ones_like(sdf), create_graph=create_graph, retain_graph=create_graph
            )
        if not create_graph:
            return sdf.detach(), grad.detach(), feats.detach()
        return sdf, grad, feats

    def radiance(
        self,
        points: torch.Tensor,  # (n, 3)
        dirs: torch.Tensor,  # (n, 3)
        normals: torch.Tensor,  # (n, 3)
        features: torch.Tensor,  # (n, F)
    ) -> torch.Tensor:
        """Colour head: RGB (n, 3) in [0, 1]. Differentiable in all inputs."""
        parts = [self.sh(dirs), normals, features]
        if self.color_pe is not None:
            parts.append(self.color_pe(points))
        rgb = torch.sigmoid(self.color_net(torch.cat(parts, dim=-1)))
        return rgb.mean(-1, keepdim=True).expand_as(rgb) if self.grey else rgb

    def crop_weight(self, points: torch.Tensor, softness: float) -> torch.Tensor:
        """Soft indicator (n,) of the crop cylinder: 1 inside, 0 beyond ``softness`` outside."""
        return torch.sigmoid(4.0 - crop_sdf(points, self.crop) * (8.0 / max(softness, 1e-6)))

    # ------------------------------------------------------------------ Field protocol

    @staticmethod
    def _check_points(points: torch.Tensor, name: str = "points") -> None:
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"{name}: expected shape (n_points, 3), got {tuple(points.shape)}")

    def sdf(self, points: Any, chunk: int = 65536) -> Any:
        """Signed distance at ``points`` (n_points, 3) -> (n_points,), cropped to the cylinder.

        numpy in gives numpy out; torch tensors stay torch (on ``self.device``).

        Note:
            Not differentiable (evaluated under ``torch.no_grad``); use
            :meth:`sdf_and_features` for training.
        """
        pts, was_numpy = as_points(points, self.device)
        self._check_points(pts)
        with torch.no_grad():
            parts = [torch.maximum(self.sdf_and_features(p)[0], crop_sdf(p, self.crop))
                     for p in pts.split(chunk)] if pts.shape[0] else [pts[:, 0]]
            out = torch.cat(parts)
        return out.cpu().numpy() if was_numpy else out

    def raw_sdf(self, points: torch.Tensor, chunk: int = 65536) -> torch.Tensor:
        """Uncropped SDF (n_points,) without gradients (what training samples see)."""
        with torch.no_grad():
            if points.shape[0] == 0:
                return points[:, 0]
            return torch.cat([self.sdf_and_features(p)[0] for p in points.split(chunk)])

    def sdf_and_gradient(self, points: Any, chunk: int = 65536) -> tuple[Any, Any]:
        """Cropped SDF (n_points,) and its gradient (n_points, 3); numpy in, numpy out.

        Note:
            Outputs are detached.
        """
        pts, was_numpy = as_points(points, self.device)
        self._check_points(pts)
        sdfs, grads = [], []
        for p in pts.split(chunk):
            with torch.enable_grad():
                x = p.detach().requires_grad_(True)
                s = torch.maximum(self.sdf_and_features(x)[0], crop_sdf(x, self.crop))
                (g,) = torch.autograd.grad(s, x, torch.ones_like(s))
            sdfs.append(s.detach())
            grads.append(g.detach())
        sdf = torch.cat(sdfs) if sdfs else pts[:, 0]
        grad = torch.cat(grads) if grads else pts
        if was_numpy:
            return sdf.cpu().numpy(), grad.cpu().numpy()
        return sdf, grad

    def color(self, points: Any, dirs: Any, chunk: int = 32768) -> Any:
        """RGB (n_points, 3) in [0, 1] seen along unit ``dirs`` (n_points, 3); numpy in/out.

        Note:
            Outputs are detached (the normal input needs an inner autograd pass).
        """
        pts, was_numpy = as_points(points, self.device)
        d, _ = as_points(dirs, self.device)
        self._check_points(pts)
        self._check_points(d, "dirs")
        if d.shape != pts.shape:
            raise ValueError(f"dirs: expected shape {tuple(pts.shape)}, got {tuple(d.shape)}")
        d = torch.nn.functional.normalize(d, dim=-1)
        outs = []
        for p, dd in zip(pts.split(chunk), d.split(chunk), strict=True):
            _, grad, feats = self.sdf_gradient_features(p, create_graph=False)
            with torch.no_grad():
                outs.append(self.radiance(p, dd, grad, feats).clamp(0.0, 1.0))
        out = torch.cat(outs) if outs else pts
        return out.cpu().numpy() if was_numpy else out

    def _load_from_state_dict(
        self, state_dict: dict[str, Any], prefix: str, *args: Any, **kwargs: Any
    ) -> None:
        # Checkpoints of hybridneus 0.2 hold the box the grid spanned; a run whose box was
        # not the volume is refused with its config (grid.domain, removed in 0.3).
        state_dict.pop(prefix + "grid_box", None)
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)

    # ------------------------------------------------------------------ init

    @torch.no_grad()
    def _center_sphere(self, n: int = 512) -> None:
        """Shift the SDF output so that its mean on the init sphere is 0.

        Geometric init gives ``|x| - r`` only up to an offset that grows with depth (the
        8-layer head misses a small crop sphere entirely without this).
        """
        gen = torch.Generator().manual_seed(0)
        dirs = torch.nn.functional.normalize(torch.randn(n, 3, generator=gen), dim=-1)
        if self.grid_config.kind == "frequency":
            self.encoding.update_step(0)
        offset = self.sdf_and_features(dirs * self.init_radius)[0].mean()
        self.sdf_net.layers[-1].bias[0] -= offset
