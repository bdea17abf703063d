"""HybridField: initial sphere, numpy/torch interface, double backward, presets."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from hybridneus.config import FieldConfig, GridConfig, preset_config
from hybridneus.data.crop import crop_sdf
from hybridneus.model.field import HybridField
from hybridneus.model.protocol import Field


def small_field(background=(159 / 255,) * 3, **field_kw) -> HybridField:
    torch.manual_seed(0)
    grid = GridConfig(n_levels=4, log2_table_size=12, base_resolution=8, max_resolution=32)
    return HybridField(grid, FieldConfig(**field_kw), background=background)


def test_initial_sdf_is_a_sphere_of_the_init_radius():
    f = small_field(init_radius=0.4)
    dirs = torch.nn.functional.normalize(torch.randn(200, 3), dim=-1)
    inside = f.raw_sdf(dirs * 0.3)
    outside = f.raw_sdf(dirs * 0.5)
    assert (inside < 0).all() and (outside > 0).all()
    # Geometric init of a 64-wide head is approximate (a few hundredths).
    assert f.raw_sdf(dirs * 0.4).abs().max() < 0.1
    assert float(f.raw_sdf(torch.zeros(1, 3))) == pytest.approx(-0.4, abs=0.12)


def test_numpy_in_numpy_out_and_torch_in_torch_out():
    f = small_field()
    assert isinstance(f, Field)
    pts = np.random.default_rng(0).uniform(-1, 1, (10, 3)).astype(np.float32)
    s = f.sdf(pts)
    assert isinstance(s, np.ndarray) and s.shape == (10,)
    st = f.sdf(torch.from_numpy(pts))
    assert isinstance(st, torch.Tensor) and torch.allclose(st, torch.from_numpy(s))
    rgb = f.color(pts, pts)
    assert isinstance(rgb, np.ndarray) and rgb.shape == (10, 3)
    assert (rgb >= 0).all() and (rgb <= 1).all()
    sdf, grad = f.sdf_and_gradient(torch.from_numpy(pts))
    assert grad.shape == (10, 3)
    with pytest.raises(ValueError, match="n_points, 3"):
        f.sdf(np.zeros((4, 2), np.float32))


def test_public_sdf_is_cropped_to_the_cylinder():
    torch.manual_seed(0)
    grid = GridConfig(n_levels=4, log2_table_size=12, base_resolution=8, max_resolution=32)
    f = HybridField(grid, FieldConfig(init_radius=0.5), crop=(0.2, -0.3, 0.3))
    p = torch.tensor([[0.0, 0.0, 0.0], [0.15, 0.0, 0.0], [0.25, 0.0, 0.0], [0.0, 0.35, 0.0]])
    s = f.sdf(p)
    assert s[0] < 0 and s[1] < 0  # inside the cylinder and the (capped) sphere
    assert s[2] > 0 and s[3] > 0  # outside the cylinder
    assert torch.allclose(crop_sdf(p, f.crop)[2:], torch.tensor([0.05, 0.05]), atol=1e-6)
    # The initial sphere is capped to fit the crop radius.
    assert f.init_radius == pytest.approx(0.18)


def test_the_grid_spans_the_volume_and_a_saved_box_is_dropped():
    """The grid reads ``(x + 1) / 2``; a 0.2 checkpoint, which saved the box its grid spanned,
    loads into today's field."""
    torch.manual_seed(0)
    grid = GridConfig(n_levels=4, log2_table_size=12, base_resolution=8, max_resolution=32)
    f = HybridField(grid, FieldConfig(), crop=(0.2, -0.2, 0.2))
    # Geometric init zeroes the weights reading the grid; give them values first.
    torch.nn.init.normal_(f.sdf_net.layers[0].weight, std=0.1)
    f.update_step(10**6, 1)
    p = torch.rand(64, 3) * 0.4 - 0.2
    read = f.sdf_net(torch.cat([p, f.encoding((p + 1) / 2)], dim=-1))[:, 0]
    torch.testing.assert_close(f.raw_sdf(p), read)
    g = HybridField(grid, FieldConfig(), crop=(0.2, -0.2, 0.2))
    g.load_state_dict({**f.state_dict(), "grid_box": torch.tensor([-1.0] * 3 + [1.0] * 3)})
    g.update_step(10**6, 1)
    torch.testing.assert_close(g.raw_sdf(p), f.raw_sdf(p))


def test_eikonal_gradient_reaches_the_grid_tables():
    f = small_field()
    f.update_step(10**6, 1)  # all levels active
    # Geometric init zeroes the weights reading the grid; give them values first.
    torch.nn.init.normal_(f.sdf_net.layers[0].weight, std=0.1)
    pts = torch.rand(256, 3) * 2 - 1
    _, grad, _ = f.sdf_gradient_features(pts, create_graph=True)
    loss = ((grad.norm(dim=-1) - 1) ** 2).mean() + grad[:, 0].mean()
    loss.backward()
    table_grads = [t.grad for t in f.encoding.tables]
    assert all(g is not None for g in table_grads)
    assert sum(float(g.abs().sum()) for g in table_grads) > 0


def test_level_schedule_opens_levels_over_training():
    f = small_field()
    f.grid_config.start_levels = 2
    f.grid_config.levels_full_at = 0.5
    f.update_step(0, 100)
    assert f.active_levels() == 2
    f.update_step(50, 100)
    assert f.active_levels() == 4


def test_coarse_to_fine_opens_everything_where_the_grid_config_says():
    grid = GridConfig(levels_full_at=0.3, frequency_anneal_at=0.7)
    assert grid.opened_at == 0.3
    grid.kind = "frequency"
    assert grid.opened_at == 0.7
    f = small_field()
    f.grid_config.start_levels = 1
    f.grid_config.levels_full_at = 0.3
    f.update_step(29, 100)
    assert f.active_levels() < f.grid_config.n_levels
    f.update_step(30, 100)
    assert f.active_levels() == f.grid_config.n_levels


def test_eventneus_preset_builds_the_paper_network():
    cfg = preset_config("eventneus")
    torch.manual_seed(0)
    f = HybridField(cfg.grid, cfg.field)
    linear = [m for m in f.sdf_net.modules() if isinstance(m, torch.nn.Linear)]
    assert len(linear) == 9 and linear[1].out_features == 256
    assert f.sdf_net.skips == (4,)
    f.update_step(0, 100)
    # The deep geometric init is a rougher sphere: zero level between 0.3 and 0.6.
    dirs = torch.nn.functional.normalize(torch.randn(64, 3), dim=-1)
    assert (f.raw_sdf(dirs * 0.3) < 0).all() and (f.raw_sdf(dirs * 0.6) > 0).all()
    out = f.sdf_gradient_features(torch.rand(8, 3) - 0.5, create_graph=True)
    assert out[1].shape == (8, 3)


def test_the_untrained_colour_starts_at_the_sigmoid_midpoint():
    grey = small_field()
    pts = torch.rand(500, 3) * 0.6 - 0.3
    dirs = torch.nn.functional.normalize(torch.randn(500, 3), dim=-1)
    with torch.no_grad():
        assert (grey.color(pts, dirs) - 0.5).abs().max() < 0.05


def _subnormal_share(t: torch.Tensor) -> float:
    a = t.detach().abs()
    return float(((a > 0) & (a < torch.finfo(t.dtype).tiny)).float().mean())


def test_flushed_softplus_matches_softplus_and_leaves_no_subnormals():
    from hybridneus.model.eventneus import TAIL_CUTOFF, FlushedSoftplus

    x = torch.linspace(-2.0, 0.5, 20001, dtype=torch.float64).requires_grad_(True)
    ours, ref = FlushedSoftplus(100.0), torch.nn.Softplus(beta=100.0)
    y, y_ref = ours(x), ref(x)
    (g,) = torch.autograd.grad(y.sum(), x, create_graph=True)
    (g_ref,) = torch.autograd.grad(y_ref.sum(), x, create_graph=True)
    (h,) = torch.autograd.grad(g.sum(), x)
    (h_ref,) = torch.autograd.grad(g_ref.sum(), x)
    cut = x.detach() * 100.0 < -TAIL_CUTOFF
    for mine, theirs in ((y, y_ref), (g, g_ref), (h, h_ref)):
        assert torch.allclose(mine.detach()[~cut], theirs.detach()[~cut], rtol=0, atol=1e-15)
        assert float(mine.detach()[cut].abs().max()) < 1e-20
        assert float(theirs.detach()[cut].abs().max()) < 1e-11  # what the cut drops
    assert torch.equal(g.detach()[~cut], g_ref.detach()[~cut])
    # In float32 the plain Softplus's tail and its derivative are subnormal; ours are zeros.
    x32 = torch.linspace(-2.0, 0.0, 4001).requires_grad_(True)
    for act, expect_subnormals in ((ref, True), (ours, False)):
        y = act(x32)
        (g,) = torch.autograd.grad(y.sum() * 1e-3, x32)
        found = _subnormal_share(y) + _subnormal_share(g)
        assert (found > 0.01) == expect_subnormals, (act, found)


def test_the_sdf_head_of_a_field_uses_the_flushed_softplus():
    from hybridneus.model.eventneus import FlushedSoftplus

    f = HybridField(GridConfig(n_levels=2, max_resolution=32), FieldConfig())
    assert isinstance(f.sdf_net.activation, FlushedSoftplus)
    assert f.sdf_net.activation.beta == FieldConfig().softplus_beta


def test_the_colour_head_reads_the_normal():
    """The same point and view change colour with the normal (SH of the view, the normal
    and the features go into the head)."""
    f = small_field()
    normals = torch.tensor([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    pts = torch.full((2, 3), 0.1)
    dirs = torch.tensor([[0.0, 0.0, 1.0]]).expand(2, 3)
    _, feats = f.sdf_and_features(pts)
    with torch.no_grad():
        rgb = f.radiance(pts, dirs, normals, feats)
    assert (rgb[0] - rgb[1]).abs().max() > 1e-3
