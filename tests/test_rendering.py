"""NeuS rendering: opacity, weights, compositing, sampling and the occupancy grid."""

from __future__ import annotations

import torch
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_flatten

from hybridneus.rendering.neus import (
    alpha_from_sdf,
    alpha_from_sdf_pairs,
    composite,
    transmittance_from_alpha,
    weights_from_alpha,
)
from hybridneus.rendering.occupancy import OccupancyGrid
from hybridneus.rendering.sampling import (
    NeuSSampler,
    intervals_from_samples,
    ray_aabb_intersect,
    sample_pdf,
)

R = 0.5


def sphere_sdf(p: torch.Tensor) -> torch.Tensor:
    return p.norm(dim=-1) - R


def _rays(n: int = 16, seed: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """Rays from a 0.9-radius shell aimed at points near the origin (all hit the sphere)."""
    g = torch.Generator().manual_seed(seed)
    origins = torch.nn.functional.normalize(torch.randn(n, 3, generator=g), dim=-1) * 0.9
    targets = (torch.rand(n, 3, generator=g) - 0.5) * 0.2
    dirs = torch.nn.functional.normalize(targets - origins, dim=-1)
    return origins, dirs


def _render_sphere(origins, dirs, t, inv_s):
    mids, deltas = intervals_from_samples(t)
    pts = origins[:, None] + dirs[:, None] * mids[..., None]
    sdf = sphere_sdf(pts)
    grad = torch.nn.functional.normalize(pts, dim=-1)
    dot = (grad * dirs[:, None]).sum(-1)
    alpha = alpha_from_sdf(sdf, dot, deltas, inv_s)
    return mids, weights_from_alpha(alpha)


def test_weights_sum_at_most_one_and_transmittance_decreases():
    g = torch.Generator().manual_seed(1)
    sdf = torch.randn(64, 48, generator=g)
    dot = torch.rand(64, 48, generator=g) * 2 - 1
    deltas = torch.rand(64, 48, generator=g) * 0.05
    alpha = alpha_from_sdf(sdf, dot, deltas, 50.0)
    assert ((alpha >= 0) & (alpha <= 1)).all()
    w = weights_from_alpha(alpha)
    assert (w.sum(-1) <= 1 + 1e-5).all()
    trans = transmittance_from_alpha(alpha)
    assert (trans[:, 1:] <= trans[:, :-1] + 1e-6).all()


def test_sphere_renders_surface_at_the_right_depth():
    origins, dirs = _rays()
    # Analytic first hit of the ray with the sphere |x| = R.
    b = (origins * dirs).sum(-1)
    c = (origins * origins).sum(-1) - R**2
    t_hit = -b - torch.sqrt(b * b - c)
    t = torch.linspace(0.0, 1.8, 1025)[None].expand(origins.shape[0], -1).contiguous()
    mids, w = _render_sphere(origins, dirs, t, inv_s=1000.0)
    depth = (w * mids).sum(-1) / w.sum(-1)
    assert (w.sum(-1) > 0.99).all()
    assert torch.allclose(depth, t_hit, atol=5e-3)


def test_composite_uses_background_for_missing_weight():
    w = torch.tensor([[0.2, 0.3], [0.0, 0.0]])
    vals = torch.ones(2, 2, 3)
    bg = torch.tensor([0.5, 0.25, 0.0])
    out = composite(w, vals, bg)
    assert torch.allclose(out[0], 0.5 + 0.5 * bg)
    assert torch.allclose(out[1], bg)


def test_alpha_gradcheck_first_and_second_order():
    g = torch.Generator().manual_seed(2)
    sdf = (torch.randn(3, 5, generator=g, dtype=torch.float64) * 0.05).requires_grad_(True)
    # Keep the cosine away from the relu kinks at 0.
    dot = (-0.3 - torch.rand(3, 5, generator=g, dtype=torch.float64) * 0.6).requires_grad_(True)
    deltas = torch.full((3, 5), 0.02, dtype=torch.float64)
    inv_s = torch.tensor(20.0, dtype=torch.float64, requires_grad=True)

    def fn(s, d, k):
        return alpha_from_sdf(s, d, deltas, k)

    assert torch.autograd.gradcheck(fn, (sdf, dot, inv_s))
    assert torch.autograd.gradgradcheck(fn, (sdf, dot, inv_s))


def test_sample_pdf_stays_in_bins_and_follows_weights():
    bins = torch.linspace(0, 1, 11)[None].expand(4, -1).contiguous()
    weights = torch.zeros(4, 10)
    weights[:, 3] = 1.0
    t = sample_pdf(bins, weights, 32)
    assert (t[:, 1:] >= t[:, :-1]).all()
    inside = ((t >= 0.3) & (t <= 0.4)).float().mean()
    assert inside > 0.95


def test_ray_aabb_intersect():
    o = torch.tensor([[0.0, 0.0, -2.0], [0.0, 3.0, -2.0]])
    d = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    aabb = torch.tensor([-1.0, -1, -1, 1, 1, 1])
    near, far, hit = ray_aabb_intersect(o, d, aabb)
    assert hit.tolist() == [True, False]
    assert torch.allclose(near[0], torch.tensor(1.0)) and torch.allclose(far[0], torch.tensor(3.0))


def test_occupancy_grid_marks_the_surface_band():
    grid = OccupancyGrid(torch.tensor([-1.0, -1, -1, 1, 1, 1]), 32)
    frac = grid.update(sphere_sdf, inv_s=200.0, band=1.0)
    assert 0.0 < frac < 0.5
    on = torch.nn.functional.normalize(torch.randn(100, 3), dim=-1) * R
    assert grid.query(on).all()
    far_pts = torch.tensor([[0.0, 0.0, 0.0], [0.95, 0.95, 0.95], [2.0, 0.0, 0.0]])
    assert not grid.query(far_pts).any()


def test_sampler_concentrates_samples_near_the_surface():
    origins, dirs = _rays(8, seed=3)
    b = (origins * dirs).sum(-1)
    c = (origins * origins).sum(-1) - R**2
    t_hit = -b - torch.sqrt(b * b - c)
    aabb = torch.tensor([-1.0, -1, -1, 1, 1, 1])
    occ = OccupancyGrid(aabb, 32)
    occ.update(sphere_sdf, inv_s=100.0)
    sampler = NeuSSampler(aabb, n_coarse=16, n_importance=16, up_rounds=2, occupancy=occ)
    t = sampler(origins, dirs, sphere_sdf, generator=torch.Generator().manual_seed(0))
    assert t.shape == (8, sampler.n_samples)
    assert (t[:, 1:] >= t[:, :-1]).all()
    near = ((t - t_hit[:, None]).abs() < 0.05).float().sum(-1)
    # Uniform samples over the ~1.8-long box chord would put ~1 sample in that window.
    assert (near >= 8).all()
    mids, w = _render_sphere(origins, dirs, t, inv_s=100.0)
    depth = (w * mids).sum(-1) / w.sum(-1).clamp_min(1e-6)
    assert torch.allclose(depth, t_hit, atol=0.02)


class _SubnormalWatch(TorchDispatchMode):
    """Records whether any op in the block outputs a subnormal float32."""

    found = False

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        out = func(*args, **(kwargs or {}))
        for t in tree_flatten(out)[0]:
            if isinstance(t, torch.Tensor) and t.dtype == torch.float32 and t.numel():
                a = t.abs()
                self.found |= bool(((a > 0) & (a < torch.finfo(t.dtype).tiny)).any())
        return out


def test_alpha_far_inside_computes_no_subnormal_floats():
    # inv_s * sdf down to -2000: the plain sigmoid's value and derivative there are subnormal
    # in float32 (slow on x86); the clamped tail changes alpha by less than 1e-6.
    sdf = torch.linspace(-1.0, 0.05, 2001).reshape(1, -1).requires_grad_(True)
    dot = torch.full_like(sdf, -0.5)
    deltas = torch.full_like(sdf, 0.01)
    tiny = torch.finfo(torch.float32).tiny
    with _SubnormalWatch() as watch:
        alpha = alpha_from_sdf(sdf, dot, deltas, 2000.0)
        torch.autograd.grad(alpha.sum(), sdf)
        alpha_from_sdf_pairs(sdf + 0.0025, sdf - 0.0025, 2000.0)
    assert not watch.found
    # A ray that meets opaque samples: its transmittance behind them, the weights and the
    # gradients (which the colour network's backward multiplies) stop at exact zeros.
    opaque = torch.cat([torch.zeros(1, 4), torch.full((1, 60), 0.999)], dim=1)
    opaque.requires_grad_(True)
    colour = torch.rand(1, 64, 3, requires_grad=True)
    weights = weights_from_alpha(opaque)
    grads = torch.autograd.grad(composite(weights, colour).sum(), (opaque, colour))
    for t in (weights.detach(), *grads):
        assert not bool(((t.abs() > 0) & (t.abs() < tiny)).any())
    assert float(weights[0, 5].detach()) > 1e-4 and float(weights[0, -1].detach()) == 0.0
    with torch.no_grad():
        s64, d64 = sdf.double(), dot.double()
        prev = torch.sigmoid((s64 - d64 * 0.005) * 2000.0)
        nxt = torch.sigmoid((s64 + d64 * 0.005) * 2000.0)
        exact = ((prev - nxt + 1e-5) / (prev + 1e-5)).clamp(0, 1)
    assert float((alpha.detach().double() - exact).abs().max()) < 1e-6
