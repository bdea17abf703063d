"""Inside/outside tests that work on meshes with holes, and signed distances built on them.

Two sign tests:
    ``winding``: the generalised winding number w(p) = sum over triangles of their solid angle
        seen from p, divided by 4 pi (Jacobson et al. 2013). w = 1 inside a closed mesh, 0
        outside, and it degrades gracefully across holes; inside is w >= 0.5. Exact, vectorised
        in torch, cost O(n_points x n_faces).
    ``rays``: majority vote of ray-parity over ``n_rays`` random directions (Open3D
        RaycastingScene). Fast, but a point whose rays leave through holes can be misjudged.
    ``auto`` (default): ``rays`` with 7 directions, and the exact winding number only for the
        points whose votes are not unanimous (on a closed mesh: almost none).
Distances are unsigned closest-point distances from Open3D (exact, BVH-accelerated).
"""

from __future__ import annotations

import math

import numpy as np
import torch
import trimesh

SIGN_METHODS = ("auto", "winding", "rays")


def _solid_angles(tris: torch.Tensor, points: torch.Tensor) -> torch.Tensor:
    """Signed solid angles (...,) of triangles (..., 3, 3) seen from points (..., 3).

    Van Oosterom & Strackee's formula: tan(omega / 2) = det[a b c] /
    (|a||b||c| + (a.b)|c| + (b.c)|a| + (c.a)|b|) with a, b, c the corners relative to the
    point; positive when the point sees the triangle's back (it is on the inner side).
    """
    # Component-wise arithmetic: torch reductions over a trailing dim of 3 are several times
    # slower than three multiplies and adds on this hot path.
    ax, ay, az = (tris[..., 0, k] - points[..., k] for k in range(3))
    bx, by, bz = (tris[..., 1, k] - points[..., k] for k in range(3))
    cx, cy, cz = (tris[..., 2, k] - points[..., k] for k in range(3))
    la = torch.sqrt(ax * ax + ay * ay + az * az)
    lb = torch.sqrt(bx * bx + by * by + bz * bz)
    lc = torch.sqrt(cx * cx + cy * cy + cz * cz)
    det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
    denom = (
        la * lb * lc
        + (ax * bx + ay * by + az * bz) * lc
        + (bx * cx + by * cy + bz * cz) * la
        + (cx * ax + cy * ay + cz * az) * lb
    )
    return 2.0 * torch.atan2(det, denom)


def winding_number_exact(
    mesh: trimesh.Trimesh, points: np.ndarray, pair_budget: int = 2**21
) -> np.ndarray:
    """Exact generalised winding number (n_points,) of ``points`` (n_points, 3).

    Cost O(n_points x n_faces): use it for checks and small meshes; :func:`winding_number`
    is the fast version.
    """
    tris = torch.tensor(np.asarray(mesh.triangles), dtype=torch.float64)
    pts = torch.tensor(np.asarray(points), dtype=torch.float64)
    out = torch.zeros(pts.shape[0], dtype=torch.float64)
    if tris.shape[0] == 0:
        return out.numpy()
    step = max(1, pair_budget // tris.shape[0])
    for p0 in range(0, pts.shape[0], step):
        omega = _solid_angles(tris[None], pts[p0 : p0 + step, None, :])
        out[p0 : p0 + step] = omega.sum(dim=1)
    return (out / (4.0 * math.pi)).numpy()


def winding_number(
    mesh: trimesh.Trimesh,
    points: np.ndarray,
    cluster_size: int = 32,
    beta: float = 3.0,
    pair_budget: int = 2**20,
) -> np.ndarray:
    """Generalised winding number (n_points,) float64 of ``points`` (n_points, 3), fast.

    A two-level version of Barill et al. 2018: faces are grouped into spatially coherent
    clusters of ``cluster_size`` (sorted by the Morton code of their centroids). A cluster
    farther than ``beta`` times its radius from a point contributes through its dipole term,
    sum(area * normal) . (centre - p) / |centre - p|^3 / (4 pi); nearer clusters are summed
    exactly, triangle by triangle. With beta = 3 the error is a few 1e-3, far below the 0.5
    inside threshold (checked against :func:`winding_number_exact` in the tests).

    Args:
        mesh: triangle mesh, open or closed, with consistent (outward) winding.
        points: query points.
        cluster_size: faces per cluster.
        beta: far-field threshold in cluster radii.
        pair_budget: point-cluster or point-triangle pairs per chunk (bounds memory: the
            near-field chunk holds pair_budget triangles, ~250 bytes each).
    """
    tris_np = np.asarray(mesh.triangles, dtype=np.float64)
    pts_all = torch.tensor(np.asarray(points), dtype=torch.float64)
    n_faces = tris_np.shape[0]
    out = torch.zeros(pts_all.shape[0], dtype=torch.float64)
    if n_faces == 0 or pts_all.shape[0] == 0:
        return out.numpy()
    centroids = tris_np.mean(axis=1)
    lo, hi = centroids.min(axis=0), centroids.max(axis=0)
    q = ((centroids - lo) / np.maximum(hi - lo, 1e-12) * 1023).astype(np.uint64)
    code = np.zeros(n_faces, dtype=np.uint64)
    for bit in range(10):
        for axis in range(3):
            code |= ((q[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    order = np.argsort(code, kind="stable")
    n_clusters = -(-n_faces // cluster_size)
    pad = n_clusters * cluster_size - n_faces
    # Padding triangles are a repeated point: zero area, zero solid angle.
    tris_sorted = np.concatenate([tris_np[order], np.zeros((pad, 3, 3))], axis=0)
    tris = torch.tensor(tris_sorted).reshape(n_clusters, cluster_size, 3, 3)
    real = torch.ones(n_clusters * cluster_size, dtype=torch.bool)
    if pad:
        real[-pad:] = False
    real = real.reshape(n_clusters, cluster_size)
    area_normals = 0.5 * torch.linalg.cross(
        tris[:, :, 1] - tris[:, :, 0], tris[:, :, 2] - tris[:, :, 0], dim=-1
    )  # (n_clusters, cluster_size, 3)
    dipole = area_normals.sum(dim=1)  # (n_clusters, 3)
    weights = area_normals.norm(dim=-1) * real + 1e-30 * real
    centre = (tris.mean(dim=2) * weights[..., None]).sum(1) / weights.sum(1, keepdim=True)
    corner_dist = (tris - centre[:, None, None, :]).norm(dim=-1).reshape(n_clusters, -1)
    corner_dist = corner_dist.masked_fill(~real.repeat_interleave(3, dim=1), 0.0)
    radius = corner_dist.max(dim=1).values  # (n_clusters,)

    step = max(1, pair_budget // n_clusters)
    for p0 in range(0, pts_all.shape[0], step):
        pts = pts_all[p0 : p0 + step]
        dx, dy, dz = (centre[None, :, k] - pts[:, None, k] for k in range(3))
        dist = torch.sqrt(dx * dx + dy * dy + dz * dz)  # (chunk, n_clusters)
        far = dist > beta * radius[None, :]
        flux = dx * dipole[None, :, 0] + dy * dipole[None, :, 1] + dz * dipole[None, :, 2]
        far_term = flux / dist.clamp(min=1e-30) ** 3
        total = torch.where(far, far_term, torch.zeros_like(far_term)).sum(dim=1) / (4 * math.pi)
        near_p, near_c = torch.nonzero(~far, as_tuple=True)
        pair_step = max(1, pair_budget // cluster_size)
        for n0 in range(0, near_p.shape[0], pair_step):
            pi = near_p[n0 : n0 + pair_step]
            ci = near_c[n0 : n0 + pair_step]
            omega = _solid_angles(tris[ci], pts[pi][:, None, :]).sum(dim=1)
            total.index_add_(0, pi, omega / (4 * math.pi))
        out[p0 : p0 + step] = total
    return out.numpy()


def raycasting_scene(mesh: trimesh.Trimesh):
    """An Open3D RaycastingScene holding ``mesh``."""
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor(np.asarray(mesh.vertices, dtype=np.float32)),
        o3d.core.Tensor(np.asarray(mesh.faces, dtype=np.uint32)),
    )
    return scene


def ray_votes(mesh: trimesh.Trimesh, points: np.ndarray, n_rays: int = 7, seed: int = 0):
    """Fraction (n_points,) of ``n_rays`` random rays from each point crossing the mesh oddly."""
    import open3d as o3d

    scene = raycasting_scene(mesh)
    rng = np.random.default_rng(seed)
    dirs = rng.normal(size=(n_rays, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    pts = np.asarray(points, dtype=np.float32)
    odd = np.zeros(pts.shape[0], dtype=np.float64)
    for d in dirs:
        rays = np.concatenate([pts, np.broadcast_to(d.astype(np.float32), pts.shape)], axis=1)
        hits = scene.count_intersections(o3d.core.Tensor(np.ascontiguousarray(rays))).numpy()
        odd += hits % 2
    return odd / n_rays


def inside_mask(
    mesh: trimesh.Trimesh, points: np.ndarray, method: str = "auto", seed: int = 0
) -> np.ndarray:
    """Whether each of ``points`` (n_points, 3) is inside ``mesh`` -> (n_points,) bool."""
    if method not in SIGN_METHODS:
        raise ValueError(f"sign method {method!r}: expected one of {', '.join(SIGN_METHODS)}")
    if method == "winding":
        return winding_number(mesh, points) >= 0.5
    votes = ray_votes(mesh, points, seed=seed)
    inside = votes > 0.5
    if method == "auto":
        unsure = (votes > 0.0) & (votes < 1.0)
        if unsure.any():
            inside[unsure] = winding_number(mesh, np.asarray(points)[unsure]) >= 0.5
    return inside


def unsigned_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Distance (n_points,) float64 from ``points`` (n_points, 3) to the closest surface point."""
    import open3d as o3d

    scene = raycasting_scene(mesh)
    query = o3d.core.Tensor(np.ascontiguousarray(points, dtype=np.float32))
    return scene.compute_distance(query).numpy().astype(np.float64)


def signed_distance(
    mesh: trimesh.Trimesh, points: np.ndarray, method: str = "auto", seed: int = 0
) -> np.ndarray:
    """Signed distance (n_points,) float64, negative inside (see :func:`inside_mask`)."""
    dist = unsigned_distance(mesh, points)
    return np.where(inside_mask(mesh, points, method, seed), -dist, dist)
