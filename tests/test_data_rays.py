"""Ray convention checked against independent projection, distortion, sphere bounds, slerp."""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial.transform import Rotation

from hybridneus.data import camera_rays, interpolate_pose, near_far_unit_sphere


def _random_cameras(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    c2w = np.tile(np.eye(4), (n, 1, 1))
    c2w[:, :3, :3] = Rotation.random(n, random_state=seed).as_matrix()
    c2w[:, :3, 3] = rng.uniform(-0.5, 0.5, (n, 3))
    K = np.tile(np.eye(3), (n, 1, 1))
    K[:, 0, 0] = rng.uniform(200, 400, n)
    K[:, 1, 1] = rng.uniform(200, 400, n)
    K[:, 0, 2] = rng.uniform(150, 200, n)
    K[:, 1, 2] = rng.uniform(100, 160, n)
    return c2w, K


def test_ray_through_projected_pixel_centre_hits_point():
    n = 200
    rng = np.random.default_rng(1)
    c2w, K = _random_cameras(n)
    # A world point in front of each camera (OpenCV: +z forward).
    local = np.stack([rng.uniform(-0.3, 0.3, n), rng.uniform(-0.2, 0.2, n),
                      rng.uniform(0.5, 2.0, n), np.ones(n)], 1)
    X = np.einsum("nij,nj->ni", c2w, local)[:, :3]
    # Project with K and the inverse pose (independent of the code under test).
    w2c = np.linalg.inv(c2w)
    Xc = np.einsum("nij,nj->ni", w2c[:, :3, :3], X) + w2c[:, :3, 3]
    uvw = np.einsum("nij,nj->ni", K, Xc)
    uv = uvw[:, :2] / uvw[:, 2:]
    pix = np.floor(uv).astype(np.int64)
    # Move the principal point so that X projects exactly onto the pixel centre.
    K2 = K.copy()
    K2[:, 0, 2] += pix[:, 0] + 0.5 - uv[:, 0]
    K2[:, 1, 2] += pix[:, 1] + 0.5 - uv[:, 1]
    o, d = camera_rays(K2, None, c2w, pix)
    o, d = o.double().numpy(), d.double().numpy()
    v = X - o
    dist = np.linalg.norm(v - (v * d).sum(1, keepdims=True) * d, axis=1)
    assert np.all((v * d).sum(1) > 0)  # in front
    assert dist.max() < 1e-5
    np.testing.assert_allclose(o, c2w[:, :3, 3], atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-6)


def test_x_is_column_y_is_row():
    K = np.array([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    _, d = camera_rays(K, None, np.eye(4), np.array([[60, 20]]))
    d = d[0].double().numpy()
    # Column 60 is right of cx=50 (+x), row 20 is above cy=40 (-y).
    np.testing.assert_allclose(d / d[2], [(60.5 - 50) / 100, (20.5 - 40) / 100, 1.0], atol=1e-6)


def test_distortion_matches_reference_formula():
    K = np.array([[300.0, 0, 173], [0, 310.0, 130], [0, 0, 1]])
    k1, k2 = -0.3, 0.12
    c2w = np.eye(4)
    c2w[:3, :3] = Rotation.from_euler("xyz", [0.1, -0.4, 0.3]).as_matrix()
    xy = np.array([[0, 0], [345, 259], [10, 200], [173, 130]])
    _, d = camera_rays(K, np.array([k1, k2]), c2w, xy)
    for (u, v), got in zip(xy, d.double().numpy(), strict=True):
        x = (u + 0.5 - 173) / 300.0
        y = (v + 0.5 - 130) / 310.0
        r2 = x * x + y * y
        f = 1 + k1 * r2 + k2 * r2 * r2
        ref = c2w[:3, :3] @ np.array([x / f, y / f, 1.0])
        np.testing.assert_allclose(got, ref / np.linalg.norm(ref), atol=1e-6)


def test_torch_inputs_and_single_pose():
    K = torch.tensor([[100.0, 0, 50], [0, 100.0, 40], [0, 0, 1]])
    xy = torch.tensor([[1, 2], [3, 4]])
    o, d = camera_rays(K, torch.zeros(2), torch.eye(4), xy)
    assert o.shape == (2, 3) and d.dtype == torch.float32 and o.dtype == torch.float32


def test_near_far_inside_unit_sphere():
    rng = np.random.default_rng(0)
    o = torch.as_tensor(rng.uniform(-0.5, 0.5, (100, 3)), dtype=torch.float32)
    d = torch.nn.functional.normalize(torch.randn(100, 3), dim=-1)
    near, far = near_far_unit_sphere(o, d)
    assert torch.allclose(near, torch.full_like(near, 1e-2))
    exit_pts = o + far[:, None] * d
    assert torch.allclose(exit_pts.norm(dim=-1), torch.ones(100), atol=1e-5)


def test_near_far_outside_and_miss():
    o = torch.tensor([[0.0, 0.0, -3.0], [0.0, 2.0, -3.0]])
    d = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    near, far = near_far_unit_sphere(o, d)
    assert torch.allclose(near[0], torch.tensor(2.0)) and torch.allclose(far[0], torch.tensor(4.0))
    assert near[1] == far[1]


def test_interpolate_pose_endpoints_and_midpoint():
    a = np.eye(4)
    a[:3, 3] = [1.0, 0.0, 0.0]
    b = np.eye(4)
    b[:3, :3] = Rotation.from_euler("y", 90, degrees=True).as_matrix()
    b[:3, 3] = [0.0, 0.0, 2.0]
    np.testing.assert_array_equal(interpolate_pose(a, b, 0.0), a)
    np.testing.assert_array_equal(interpolate_pose(a, b, 1.0), b)
    mid = interpolate_pose(a, b, 0.5)
    np.testing.assert_allclose(
        mid[:3, :3], Rotation.from_euler("y", 45, degrees=True).as_matrix(), atol=1e-12
    )
    np.testing.assert_allclose(mid[:3, 3], [0.5, 0.0, 1.0])
    np.testing.assert_allclose(mid[3], [0, 0, 0, 1])


def test_interpolate_pose_batched_shorter_arc():
    ra = Rotation.random(10, random_state=3)
    rb = Rotation.random(10, random_state=4)
    a = np.tile(np.eye(4), (10, 1, 1))
    b = a.copy()
    a[:, :3, :3], b[:, :3, :3] = ra.as_matrix(), rb.as_matrix()
    w = np.linspace(0, 1, 10)
    out = interpolate_pose(a, b, w)
    assert out.shape == (10, 4, 4)
    rot = Rotation.from_matrix(out[:, :3, :3])
    total = (ra.inv() * rb).magnitude()
    assert np.all(total <= np.pi + 1e-9)
    np.testing.assert_allclose((ra.inv() * rot).magnitude(), w * total, atol=1e-9)
    np.testing.assert_allclose(
        np.einsum("nji,njk->nik", out[:, :3, :3], out[:, :3, :3]),
        np.tile(np.eye(3), (10, 1, 1)), atol=1e-12,
    )
