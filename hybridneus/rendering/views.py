"""Whole images of a trained field: colour, normal and depth at a camera, and event sheets.

These read a trained :class:`~hybridneus.model.field.HybridField` and never change it. The
sampler used here is the training sampler (coarse samples over an occupancy grid, then NeuS
up-sampling), with the grid refreshed once from the field so that samples land near its
surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from hybridneus.rendering.occupancy import OccupancyGrid
from hybridneus.rendering.renderer import render_rays_chunked
from hybridneus.rendering.sampling import NeuSSampler


@dataclass
class ViewImages:
    """One rendered camera view; arrays are (height, width, ...) numpy.

    Attributes:
        color: composited RGB over the background in [0, 1], (height, width, 3) float32.
        normal: world-space unit normal blended by the NeuS weights, (height, width, 3).
        depth: expected distance along the ray, (height, width) float32.
        opacity: sum of weights (1 on the object, 0 on the background), (height, width).
    """

    color: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    opacity: np.ndarray


def inference_sampler(
    field,
    n_coarse: int = 32,
    n_importance: int = 32,
    up_rounds: int = 2,
    occupancy_resolution: int = 64,
) -> NeuSSampler:
    """A :class:`NeuSSampler` for rendering ``field``, its occupancy grid fitted to the field.

    Somewhat more samples than a training step uses, for fewer banding artefacts; the
    occupancy grid keeps them near the surface so that a 346x260 view stays affordable on a
    CPU.
    """
    from hybridneus.data.crop import crop_aabb

    aabb = crop_aabb(field.crop.detach().cpu()).to(field.device)
    grid = OccupancyGrid(aabb, occupancy_resolution).to(field.device)
    with torch.no_grad():
        grid.update(field.raw_sdf, inv_s=float(field.inv_s()))
    return NeuSSampler(
        aabb,
        n_coarse=n_coarse,
        n_importance=n_importance,
        up_rounds=up_rounds,
        occupancy=grid,
    )


def pixel_grid(width: int, height: int, stride: int = 1) -> np.ndarray:
    """Integer pixel coordinates (n_pixels, 2) as (x column, y row), row-major order."""
    gx, gy = np.meshgrid(np.arange(0, width, stride), np.arange(0, height, stride))
    return np.stack([gx.ravel(), gy.ravel()], axis=1).astype(np.int64)


@torch.no_grad()
def render_view(
    field,
    intrinsics: np.ndarray,
    distortion: np.ndarray,
    c2w: np.ndarray,
    width: int,
    height: int,
    sampler: NeuSSampler | None = None,
    stride: int = 1,
    chunk_rays: int = 4096,
    lens=None,
) -> ViewImages:
    """Render a camera of the dataset (or any pinhole camera) from ``field``.

    Args:
        field: a trained :class:`~hybridneus.model.field.HybridField`.
        intrinsics: K (3, 3). distortion: (k1, k2). c2w: camera-to-world (4, 4), OpenCV axes.
        width, height: image size in pixels; ``stride`` > 1 renders every stride-th pixel
            (a smaller image of (ceil(height / stride), ceil(width / stride))).
        sampler: from :func:`inference_sampler`; built on the fly when ``None``.
        chunk_rays: rays per forward pass (bounds memory).
        lens: the split's :class:`~hybridneus.data.lens.Lens`, if it has one.

    Returns:
        :class:`ViewImages`.

    Note:
        Not differentiable (runs under ``torch.no_grad``).
    """
    from hybridneus.data import camera_rays

    sampler = sampler if sampler is not None else inference_sampler(field)
    xy = pixel_grid(width, height, stride)
    h, w = len(range(0, height, stride)), len(range(0, width, stride))
    origins, dirs = camera_rays(intrinsics, distortion, c2w, xy, device=field.device,
                                lens=lens)
    out = render_rays_chunked(field, origins, dirs, sampler, chunk_rays=chunk_rays)
    return ViewImages(
        color=out.color.clamp(0, 1).cpu().numpy().reshape(h, w, 3).astype(np.float32),
        normal=out.normal.cpu().numpy().reshape(h, w, 3).astype(np.float32),
        depth=out.depth.cpu().numpy().reshape(h, w).astype(np.float32),
        opacity=out.opacity.cpu().numpy().reshape(h, w).astype(np.float32),
    )


@torch.no_grad()
def predicted_event_frame(
    field,
    split,
    preset,
    t0: float,
    t1: float,
    sampler: NeuSSampler | None = None,
    stride: int = 1,
) -> tuple[np.ndarray, np.ndarray]:
    """The field's log-brightness change over [t0, t1) next to the recorded one.

    Returns:
        ``(predicted, recorded)``, each (height', width') float32 in log units: predicted is
        the Bayer-masked ``log(c1^2.2 + eps) - log(c0^2.2 + eps)`` of the renders at the
        window's two cameras, recorded is ``C * E`` with the polarity offset (the training
        target), both on every ``stride``-th pixel.
    """
    from hybridneus.data import EventWindowSampler, bayer_mask, camera_rays

    windows = EventWindowSampler(split, preset, seed=0, device=field.device)
    sampler = sampler if sampler is not None else inference_sampler(field)
    xy = pixel_grid(split.width, split.height, stride)
    h, w = len(range(0, split.height, stride)), len(range(0, split.width, stride))
    (c2w0, k0), (c2w1, k1) = windows.pose_at(t0), windows.pose_at(t1)
    dev = field.device
    o0, d0 = camera_rays(split.intrinsics[k0], split.distortion[k0], c2w0, xy, device=dev,
                         lens=split.lens)
    o1, d1 = camera_rays(split.intrinsics[k1], split.distortion[k1], c2w1, xy, device=dev,
                         lens=split.lens)
    out = render_rays_chunked(field, torch.cat([o0, o1]), torch.cat([d0, d1]), sampler)
    m = xy.shape[0]
    c0, c1 = out.color[:m].clamp_min(0), out.color[m:].clamp_min(0)
    eps = float(preset.tonemap_eps)
    diff = torch.log(c1**2.2 + eps) - torch.log(c0**2.2 + eps)
    bayer = torch.as_tensor(bayer_mask(xy, preset.mosaic), device=dev, dtype=diff.dtype)
    predicted = (diff * bayer).sum(-1).cpu().numpy().reshape(h, w)
    recorded = windows.frame(t0, t1)[:: stride, :: stride] * float(preset.threshold)
    return predicted.astype(np.float32), recorded.astype(np.float32)
