"""Where the object can be, from the events alone: a visual hull of per-view event silhouettes.

Against a constant background, only the object fires events. For a view ``i``, the pixels that
fired within ``window`` views of it outline the object's image (its silhouette edges move as
the camera does); with sensor noise removed (:func:`hybridneus.data.firing.without_noise`),
their filled convex hull, grown by ``dilate`` pixels, contains the object's image. A point
that projects inside the image but outside that hull in enough views is free space. The hull
is conservative (convex per view, dilated, voted) and cannot see into concavities. It
tightens the scene's crop cylinder (:func:`event_hull_crop`) and, during training, tells the
field where there is no matter (:class:`FreeSpace`); it never cuts a mesh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from hybridneus.data.dataset import SplitData
from hybridneus.data.firing import fired_near


@dataclass
class EventHull:
    """Occupancy of a regular grid: ``occupied[i, j, k]`` at ``origin + voxel * (i, j, k)``."""

    occupied: np.ndarray
    origin: np.ndarray
    voxel: float
    n_views: int


#: Why there is no hull, for the crop's and the ``hull`` term's log lines.
NOTHING_OUTLINED = "the events outline nothing (no view fired, or all were too noisy)"

#: Views whose viewing directions lie within this many degrees of a view pool their firing
#: pixels into its outline (:func:`event_silhouettes`).
ARC_DEG = 2.0
#: ... but no more than this many views on either side.
MAX_ARC_VIEWS = 8


def event_silhouettes(
    split: SplitData,
    window: int = 1,
    dilate: int = 2,
    step: int = 6,
    denoise: bool = True,
    arc_deg: float = ARC_DEG,
) -> tuple[list[int], list[np.ndarray]]:
    """(view indices, boolean (height, width) masks) for every ``step``-th view: the filled
    convex hull of the pixels that fired within ``window`` views of it, less sensor noise
    (:func:`~hybridneus.data.firing.without_noise`; ``denoise=False`` takes every pixel),
    pooled with those of the neighbouring views whose viewing directions are within
    ``arc_deg`` degrees of its own (at most ``MAX_ARC_VIEWS`` on either side; each window is
    denoised on its own), grown by ``dilate`` pixels. Views with fewer than three firing
    pixels (nothing to outline) or too much noise to tell the outline are skipped. Kept in
    ``split.events.cache``: the crop and the ``hull`` term outline the same views (the masks
    are read-only).

    Pooling is for slow cameras: where a view moves a fraction of a degree (a turntable
    capture of 999 views turns 0.36 degrees per view), one window fires only a sparse
    stroke of the outline, mostly its edges across the motion, and the noise filter can
    drop the rest; the convex hull of what is left misses the object's top and bottom
    (17% of a small bunny's surface was called empty). Over 2 degrees the outline barely
    moves, so pooling adds the strokes without growing the hull by much."""
    key = ("silhouettes", split.width, split.height, split.n_views, window, dilate, max(step, 1),
           denoise, float(arc_deg))
    cached = split.events.cache.get(key)
    if cached is None:
        cached = _silhouettes(split, window, dilate, max(step, 1), denoise, arc_deg)
        for mask in cached[1]:
            mask.flags.writeable = False  # shared by every caller
        split.events.cache[key] = cached
    return list(cached[0]), list(cached[1])


def _silhouettes(
    split: SplitData, window: int, dilate: int, step: int, denoise: bool, arc_deg: float
) -> tuple[list[int], list[np.ndarray]]:
    import cv2

    w, h = split.width, split.height
    views, masks = [], []
    kernel = np.ones((2 * dilate + 1,) * 2, np.uint8) if dilate > 0 else None
    forward = split.c2w[:, :3, 2] / np.linalg.norm(split.c2w[:, :3, 2], axis=1, keepdims=True)
    cos_arc = np.cos(np.deg2rad(arc_deg))
    first, last = window, split.n_views - window - 1
    near: dict[int, np.ndarray | None] = {}  # each window is outlined once, however pooled
    for i in range(first, last + 1, step):
        for j in [j for j in near if j < i - MAX_ARC_VIEWS]:
            del near[j]  # behind every later view's arc
        if i not in near:
            near[i] = fired_near(split, i, window, denoise)
        if near[i] is None:
            continue  # the view itself is too noisy to outline
        fired = near[i].copy()
        for side in (-1, 1):
            for k in range(1, MAX_ARC_VIEWS + 1):
                j = i + side * k
                if not first <= j <= last or forward[i] @ forward[j] < cos_arc:
                    break
                if j not in near:
                    near[j] = fired_near(split, j, window, denoise)
                if near[j] is not None:
                    fired |= near[j]
        ys, xs = np.nonzero(fired)
        if xs.size < 3:
            continue
        mask = np.zeros((h, w), np.uint8)
        cv2.fillConvexPoly(mask, cv2.convexHull(np.stack([xs, ys], 1).astype(np.int32)), 1)
        if kernel is not None:
            mask = cv2.dilate(mask, kernel)
        views.append(i)
        masks.append(mask.astype(bool))
    return views, masks


def project_to_pixels(
    split: SplitData, view: int, points: torch.Tensor | np.ndarray
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Pixel (column, row) indices (long) of world ``points`` (n, 3) in ``view``, and whether
    each is in front of the camera (bool), computed in ``points``' dtype on its device; the
    inverse of :func:`hybridneus.data.rays.camera_rays` (its radial model is inverted by
    fixed-point iteration)."""
    points = torch.as_tensor(points)
    c2w = torch.as_tensor(split.c2w[view], dtype=points.dtype, device=points.device)
    cam = (points - c2w[:3, 3]) @ c2w[:3, :3]
    z = cam[:, 2]
    xn = cam[:, :2] / torch.where(z.abs() < 1e-9, 1e-9, z)[:, None]
    if split.lens is not None:  # OpenCV's forward model, on the CPU
        uv = split.lens.project(xn.detach().cpu().numpy())
        uv = torch.as_tensor(uv, dtype=points.dtype, device=points.device) - 0.5
        return torch.floor(uv[:, 0] + 0.5).long(), torch.floor(uv[:, 1] + 0.5).long(), z > 0
    k1, k2 = (float(v) for v in split.distortion[view])
    if k1 or k2:  # rays divide distorted coordinates by 1 + k1 r^2 + k2 r^4
        xd = xn.clone()
        for _ in range(8):
            r2 = (xd * xd).sum(dim=1, keepdim=True)
            xd = xn * (1.0 + k1 * r2 + k2 * r2 * r2)
        xn = xd
    fx, s, cx = (float(k) for k in split.intrinsics[view][0, :3])
    fy, cy = float(split.intrinsics[view][1, 1]), float(split.intrinsics[view][1, 2])
    u = fx * xn[:, 0] + s * xn[:, 1] + cx - 0.5
    v = fy * xn[:, 1] + cy - 0.5
    return torch.floor(u + 0.5).long(), torch.floor(v + 0.5).long(), z > 0


def event_hull(
    split: SplitData,
    lo: np.ndarray,
    hi: np.ndarray,
    resolution: int = 64,
    window: int = 1,
    dilate: int = 2,
    step: int = 6,
    min_seen: float = 0.1,
    min_votes: float = 0.05,
    denoise: bool = True,
    silhouettes: tuple[list[int], list[np.ndarray]] | None = None,
    device: torch.device | str = "cpu",
) -> EventHull:
    """The visual hull of the event silhouettes on a grid over the box [lo, hi] with
    ``resolution`` points along its longest side. A point is free when at least ``min_votes``
    of the views that see it (in front, inside the image) see it outside their silhouette,
    when fewer than ``min_seen`` of the views see it at all (the object is in most views'
    images), or when it is farther from the origin than the nearest camera (the object is
    inside the ring). ``denoise``: see :func:`event_silhouettes`. ``silhouettes``: (view
    indices, masks) to use instead of :func:`event_silhouettes`'s (``window``, ``dilate``,
    ``step`` and ``denoise`` are then unused). ``device``: where the votes are counted (in
    float32: the silhouettes' dilation is far wider than its rounding)."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    voxel = float((hi - lo).max()) / (resolution - 1)
    shape = tuple(int(np.ceil((hi - lo)[k] / voxel - 1e-9)) + 1 for k in range(3))
    axes = [lo[k] + voxel * np.arange(shape[k]) for k in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    if silhouettes is None:
        silhouettes = event_silhouettes(split, window, dilate, step, denoise)
    views, masks = silhouettes
    # torch, not numpy: a 96^3 grid against 160 views is 10 s of single-threaded numpy at
    # the start of every fit, a fraction of that on two threads in float32, and nothing on a GPU
    grid = torch.as_tensor(points, dtype=torch.float32, device=device)
    n_out = torch.zeros(grid.shape[0], dtype=torch.int32, device=device)
    n_seen = torch.zeros_like(n_out)
    w, h = split.width, split.height
    for view, mask in zip(views, masks, strict=True):
        u, v, front = project_to_pixels(split, view, grid)
        seen = front & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        inside = torch.tensor(mask, device=device)[v.clamp(0, h - 1), u.clamp(0, w - 1)]
        n_seen += seen
        n_out += seen & ~inside
    n_out, n_seen = n_out.cpu().numpy(), n_seen.cpu().numpy()
    # one view whose outline is incomplete (a pause, a low-contrast edge) must not carve the
    # object: free space needs the votes of a share of the views that see the point
    free = n_out >= np.maximum(1, min_votes * n_seen)
    # a point that (almost) no view sees is not evidence of anything: count it as free
    free |= n_seen < max(1, int(min_seen * len(views)))
    # the object sits inside the ring of cameras; beyond the nearest camera centre a point is
    # only ever seen from the far side, behind the object, and would never be carved
    nearest = float(np.linalg.norm(split.c2w[:, :3, 3], axis=1).min())
    free |= np.linalg.norm(points, axis=1) >= nearest
    return EventHull(~free.reshape(shape), lo, voxel, len(views))


def hull_view_step(split: SplitData) -> int:
    """The view step that uses about 160 views: enough to outline the object, and quick."""
    return max(1, split.n_views // 160)


def event_hull_crop(
    split: SplitData,
    crop: tuple[float, float, float],
    margin: float = 0.05,
    resolution: int = 64,
    step: int | None = None,
    **silhouette: int,
) -> tuple[float, float, float] | None:
    """The crop cylinder ``(r, y_min, y_max)`` shrunk to the event hull plus ``margin``.

    The result never exceeds ``crop``. ``None`` when the events outline nothing inside the
    crop (no view had firing pixels, or the hull is empty), so the caller keeps ``crop``.
    ``step``: use every step-th view; default about 160 views in all. ``silhouette`` takes
    :func:`event_silhouettes`'s ``window`` and ``dilate``.
    """
    r, y0, y1 = (float(c) for c in crop)
    step = hull_view_step(split) if step is None else step
    hull = event_hull(split, (-r, y0, -r), (r, y1, r), resolution, step=step, **silhouette)
    if hull.n_views == 0:
        return None
    idx = np.argwhere(hull.occupied)
    pts = hull.origin + hull.voxel * idx
    inside = pts[:, 0] ** 2 + pts[:, 2] ** 2 <= r * r
    if not inside.any():
        return None
    pts = pts[inside]
    pad = margin + hull.voxel  # a voxel: the grid only samples the hull
    radius = min(r, float(np.sqrt(pts[:, 0] ** 2 + pts[:, 2] ** 2).max()) + pad)
    return radius, max(y0, float(pts[:, 1].min()) - pad), min(y1, float(pts[:, 1].max()) + pad)


#: A view whose outline covers this share of the image or more sees events all over it ...
CLUTTER_COVER = 0.8
#: ... and a split is cluttered when at least this share of its outlined views do.
CLUTTER_VIEWS = 0.5


def background_fires(split: SplitData) -> str | None:
    """Why the split's background seems to fire events, or ``None`` when it does not.

    Against a constant background a view's events outline the object, a part of the image.
    A desk, a lab or a moving background behind it fires wherever the camera's motion sweeps
    an edge: the outline (the one the crop and the hull prior use, about 160 views) then
    covers nearly the whole image, or the events are so dense everywhere that the noise
    filter cannot tell an outline at all and the view is skipped. The hull's free space and
    the crop from it assume the former; when at least :data:`CLUTTER_VIEWS` of the views
    are filled so (an outline over :data:`CLUTTER_COVER` of the image, or none), they would
    carve nothing or cut the object, so both are left out and the caller says so."""
    step = hull_view_step(split)
    _, masks = event_silhouettes(split, step=step)
    candidates = len(range(1, split.n_views - 1, step))
    if candidates == 0:
        return None
    filled = candidates - len(masks) + sum(float(m.mean()) >= CLUTTER_COVER for m in masks)
    share = filled / candidates
    if share < CLUTTER_VIEWS:
        return None
    return (f"the events fill the image in {share:.0%} of {candidates} views (an outline over "
            f"{CLUTTER_COVER:.0%} of it, or too dense to outline): the background fires events "
            "(clutter behind the object, a moving background, or noise too dense to filter)")


class FreeSpace:
    """Where an :class:`EventHull` says there is no matter, as a lookup on torch points.

    ``free(points)`` is True where the point's nearest hull voxel, and every voxel within
    ``grow`` voxels of it (a cube), is outside the hull; False elsewhere, including outside
    the hull's grid, where the hull knows nothing. Growing keeps the nearest-voxel lookup
    from calling free a point up to a voxel's half-diagonal outside a thin part, but it also
    spares the matter a fit grows within ``grow`` voxels of the hull. The silhouettes'
    own dilation is a margin already: on the five benchmark assets at 96 points (no growth)
    at most 0.03% of the true surface is called free.

    Args:
        hull: the hull.
        grow: voxels added around the hull's occupied voxels.
        device: where lookups run.
    """

    def __init__(self, hull: EventHull, grow: int = 0, device: torch.device | str = "cpu") -> None:
        occupied = torch.from_numpy(np.ascontiguousarray(hull.occupied)).float()
        if grow > 0:
            k = 2 * grow + 1
            occupied = torch.nn.functional.max_pool3d(occupied[None, None], k, 1, grow)[0, 0]
        self.free_grid = (occupied < 0.5).to(device)
        self.origin = torch.as_tensor(hull.origin, dtype=torch.float32, device=device)
        self.voxel = float(hull.voxel)
        self.shape = torch.tensor(hull.occupied.shape, device=device)

    @property
    def free_fraction(self) -> float:
        """The share of the grid that is free."""
        return float(self.free_grid.float().mean())

    def free(self, points: torch.Tensor) -> torch.Tensor:
        """(n,) bool for world ``points`` (n, 3): True where the hull says empty."""
        idx = torch.round((points.detach() - self.origin) / self.voxel).long()
        inside = ((idx >= 0) & (idx < self.shape)).all(dim=-1)
        idx = torch.minimum(idx.clamp(min=0), self.shape - 1)
        return inside & self.free_grid[idx[:, 0], idx[:, 1], idx[:, 2]]


def event_free_space(
    split: SplitData,
    lo: np.ndarray,
    hi: np.ndarray,
    resolution: int = 96,
    grow: int = 0,
    step: int | None = None,
    device: torch.device | str = "cpu",
) -> FreeSpace | None:
    """The free space of the event hull (:func:`event_hull`, about 160 views, the crop's
    votes) over the box [lo, hi]; ``None`` when no view outlines anything."""
    step = hull_view_step(split) if step is None else step
    hull = event_hull(split, lo, hi, resolution, step=step, device=device)
    if hull.n_views == 0 or not hull.occupied.any():
        return None
    return FreeSpace(hull, grow, device)
