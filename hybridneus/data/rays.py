"""Camera rays in the EventNeRF convention, unit-sphere bounds and pose interpolation.

Conventions (as the EventNeRF reference code):

- A pixel ``(x, y)`` = (column, row) is sampled at its centre ``(x + 0.5, y + 0.5)``.
- Camera coordinates ``(xn, yn, 1)`` with ``xn = (x + 0.5 - cx) / fx``,
  ``yn = (y + 0.5 - cy) / fy`` (skew, if K has one, is removed through K^-1), then the
  approximate radial undistortion ``xn, yn /= 1 + k1 r^2 + k2 r^4`` with ``r^2 = xn^2 + yn^2``.
- OpenCV camera axes (x right, y down, z forward); the direction is rotated by the
  camera-to-world rotation and normalised; the origin is the camera centre.
- A split with a :class:`~hybridneus.data.lens.Lens` (OpenCV's radtan or fisheye models)
  takes ``(xn, yn)`` from the lens's per-pixel table instead of ``K`` and ``k1 k2``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

if TYPE_CHECKING:
    from hybridneus.data.lens import Lens

ArrayLike = np.ndarray | torch.Tensor


def _as_f64(a: ArrayLike) -> np.ndarray:
    if isinstance(a, torch.Tensor):
        return a.detach().cpu().numpy().astype(np.float64, copy=False)
    return np.asarray(a, dtype=np.float64)


def camera_rays(
    K: ArrayLike,
    distortion: ArrayLike | None,
    c2w: ArrayLike,
    xy: ArrayLike,
    device: str | torch.device | None = None,
    lens: Lens | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Rays through pixel centres.

    Args:
        K: (3, 3) or (n_rays, 3, 3) pinhole matrix.
        distortion: (2,) or (n_rays, 2) radial coefficients (k1, k2), or None for none.
        c2w: (4, 4), (3, 4), (n_rays, 4, 4) or (n_rays, 3, 4) camera-to-world (OpenCV axes).
        xy: (n_rays, 2) integer pixel coordinates, column first (x = column, y = row).
        device: output device; default: that of ``xy`` if it is a tensor, else CPU.
        lens: the split's distorted lens (its table replaces ``K`` and ``distortion``), or
            None.

    Returns:
        - origins: (n_rays, 3) float32 camera centres.
        - dirs: (n_rays, 3) float32 unit directions in world coordinates.

    Note:
        Computed in float64 numpy and cast at the end; not differentiable (poses are fixed
        inputs).
    """
    if device is None:
        device = xy.device if isinstance(xy, torch.Tensor) else torch.device("cpu")
    if lens is not None:
        ij = (xy.detach().cpu().numpy() if isinstance(xy, torch.Tensor)
              else np.asarray(xy)).reshape(-1, 2).astype(np.int64)
        cam = np.ones((ij.shape[0], 3))
        cam[:, :2] = lens.table[ij[:, 1], ij[:, 0]]
        return _world_rays(cam, c2w, device)
    pix = _as_f64(xy).reshape(-1, 2) + 0.5
    Kinv = np.linalg.inv(_as_f64(K))
    uv1 = np.concatenate([pix, np.ones_like(pix[:, :1])], axis=-1)
    if Kinv.ndim == 2:
        cam = uv1 @ Kinv.T
    else:
        cam = np.einsum("nij,nj->ni", Kinv, uv1)
    cam /= cam[:, 2:3]
    if distortion is not None:
        d = _as_f64(distortion).reshape(-1, 2)
        r2 = cam[:, 0] ** 2 + cam[:, 1] ** 2
        factor = 1.0 + d[:, 0] * r2 + d[:, 1] * r2 * r2
        cam[:, :2] /= factor[:, None]
    return _world_rays(cam, c2w, device)


def _world_rays(cam: np.ndarray, c2w: ArrayLike, device) -> tuple[torch.Tensor, torch.Tensor]:
    pose = _as_f64(c2w)
    rot = pose[..., :3, :3]
    if rot.ndim == 2:
        dirs = cam @ rot.T
        origins = np.broadcast_to(pose[:3, 3], (cam.shape[0], 3))
    else:
        dirs = np.einsum("nij,nj->ni", rot, cam)
        origins = pose[:, :3, 3]
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    return (
        torch.as_tensor(np.ascontiguousarray(origins, dtype=np.float32), device=device),
        torch.as_tensor(np.ascontiguousarray(dirs, dtype=np.float32), device=device),
    )


def near_far_unit_sphere(
    origins: torch.Tensor, dirs: torch.Tensor, radius: float = 1.0, near_eps: float = 1e-2
) -> tuple[torch.Tensor, torch.Tensor]:
    """Ray distances where the rays are inside the sphere ``|p| <= radius``.

    Cameras of EventNeRF datasets lie inside the unit sphere (NeRF++ normalisation), so
    ``near`` is a small epsilon and ``far`` is where the ray leaves the sphere. A ray that
    starts outside gets the entry point as ``near``; one that misses gets ``near = far``.

    Args:
        origins: (n_rays, 3) ray origins.
        dirs: (n_rays, 3) unit directions.
        radius: sphere radius. Default: 1.0.
        near_eps: smallest ``near``. Default: 1e-2.

    Returns:
        - near: (n_rays,)
        - far: (n_rays,)

    Note:
        Differentiable in ``origins`` and ``dirs`` (not needed in training).
    """
    b = (origins * dirs).sum(-1)
    c = (origins * origins).sum(-1) - radius * radius
    disc = b * b - c
    root = torch.sqrt(torch.clamp(disc, min=0.0))
    far = torch.clamp(-b + root, min=near_eps)
    near = torch.where(c < 0, torch.full_like(b, near_eps), torch.clamp(-b - root, min=near_eps))
    near = torch.where(disc < 0, far, torch.minimum(near, far))
    return near, far


def _quat_from_matrix(R: np.ndarray) -> np.ndarray:
    """(n, 3, 3) rotations -> (n, 4) unit quaternions (w, x, y, z), Shepperd's method."""
    m = R
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    diag = np.stack([tr, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    k = diag.argmax(axis=1)  # the largest of 4w^2-1, 4x^2-1, ... keeps the division stable
    q = np.empty((R.shape[0], 4))
    for case in range(4):
        sel = k == case
        if not np.any(sel):
            continue
        a = m[sel]
        if case == 0:
            s = np.sqrt(1.0 + a[:, 0, 0] + a[:, 1, 1] + a[:, 2, 2]) * 2
            q[sel] = np.stack([0.25 * s, (a[:, 2, 1] - a[:, 1, 2]) / s,
                               (a[:, 0, 2] - a[:, 2, 0]) / s, (a[:, 1, 0] - a[:, 0, 1]) / s], 1)
        elif case == 1:
            s = np.sqrt(1.0 + a[:, 0, 0] - a[:, 1, 1] - a[:, 2, 2]) * 2
            q[sel] = np.stack([(a[:, 2, 1] - a[:, 1, 2]) / s, 0.25 * s,
                               (a[:, 0, 1] + a[:, 1, 0]) / s, (a[:, 0, 2] + a[:, 2, 0]) / s], 1)
        elif case == 2:
            s = np.sqrt(1.0 + a[:, 1, 1] - a[:, 0, 0] - a[:, 2, 2]) * 2
            q[sel] = np.stack([(a[:, 0, 2] - a[:, 2, 0]) / s, (a[:, 0, 1] + a[:, 1, 0]) / s,
                               0.25 * s, (a[:, 1, 2] + a[:, 2, 1]) / s], 1)
        else:
            s = np.sqrt(1.0 + a[:, 2, 2] - a[:, 0, 0] - a[:, 1, 1]) * 2
            q[sel] = np.stack([(a[:, 1, 0] - a[:, 0, 1]) / s, (a[:, 0, 2] + a[:, 2, 0]) / s,
                               (a[:, 1, 2] + a[:, 2, 1]) / s, 0.25 * s], 1)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _matrix_from_quat(q: np.ndarray) -> np.ndarray:
    """(n, 4) unit quaternions (w, x, y, z) -> (n, 3, 3) rotations."""
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], 1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], 1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], 1),
    ], 1)


def interpolate_pose(c2w_a: np.ndarray, c2w_b: np.ndarray, w: float | np.ndarray) -> np.ndarray:
    """Camera-to-world pose between two poses: slerp of the rotation, lerp of the position.

    Args:
        c2w_a: (4, 4) or (n, 4, 4) pose at ``w = 0``.
        c2w_b: (4, 4) or (n, 4, 4) pose at ``w = 1``.
        w: scalar or (n,) weights in [0, 1].

    Returns:
        (4, 4) or (n, 4, 4) float64 pose; ``w = 0`` gives ``c2w_a`` and ``w = 1`` ``c2w_b``
        exactly. The rotation turns at constant speed along the shorter arc.
    """
    a = np.asarray(c2w_a, dtype=np.float64)
    b = np.asarray(c2w_b, dtype=np.float64)
    single = a.ndim == 2 and b.ndim == 2 and np.ndim(w) == 0
    a4 = a.reshape(-1, 4, 4)
    b4 = b.reshape(-1, 4, 4)
    wv = np.asarray(w, dtype=np.float64).reshape(-1)
    n = max(a4.shape[0], b4.shape[0], wv.shape[0])
    a4 = np.broadcast_to(a4, (n, 4, 4))
    b4 = np.broadcast_to(b4, (n, 4, 4))
    wv = np.broadcast_to(wv, (n,))
    qa = _quat_from_matrix(a4[:, :3, :3])
    qb = _quat_from_matrix(b4[:, :3, :3])
    dot = (qa * qb).sum(1)
    qb = np.where(dot[:, None] < 0, -qb, qb)  # q and -q are the same rotation: shorter arc
    dot = np.abs(dot).clip(max=1.0)
    theta = np.arccos(dot)
    sin = np.sin(theta)
    small = sin < 1e-9
    safe = np.where(small, 1.0, sin)
    ca = np.where(small, 1.0 - wv, np.sin((1.0 - wv) * theta) / safe)
    cb = np.where(small, wv, np.sin(wv * theta) / safe)
    q = ca[:, None] * qa + cb[:, None] * qb
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    out = np.zeros((n, 4, 4))
    out[:, :3, :3] = _matrix_from_quat(q)
    out[:, :3, 3] = (1.0 - wv)[:, None] * a4[:, :3, 3] + wv[:, None] * b4[:, :3, 3]
    out[:, 3, 3] = 1.0
    # Exact endpoints (no quaternion round-trip noise where callers compare poses).
    out[wv == 0.0] = a4[wv == 0.0]
    out[wv == 1.0] = b4[wv == 1.0]
    return out[0] if single else out
