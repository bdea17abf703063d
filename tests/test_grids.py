"""HashGrid / DenseGrid against a slow per-point reference, plus gradients of all orders."""

from __future__ import annotations

import math

import pytest
import torch
from torch.autograd import gradcheck, gradgradcheck
from torch.func import functional_call

import hybridneus.grids as grids
from hybridneus.errors import ConfigError
from hybridneus.grids import DenseGrid, HashGrid

P1, P2 = 2654435761, 805459861


def _reference_encode(x, tables, n_levels, base, finest, log2_t):
    """Obviously-correct encoding: Python loops over points, levels and corners."""
    t_max = None if log2_t is None else 2**log2_t
    b = math.exp(math.log(finest / base) / (n_levels - 1)) if n_levels > 1 else 1.0
    rows = []
    for p in range(x.shape[0]):
        feats = []
        for lvl in range(n_levels):
            scale = base * b**lvl - 1.0
            side = math.floor(scale + 0.5) + 2
            hashed = t_max is not None and side**3 > t_max
            pos = [x[p, d] * scale + 0.5 for d in range(3)]
            cell = [math.floor(float(v.detach()) if torch.is_tensor(v) else v) for v in pos]
            acc = 0.0
            for dz in (0, 1):
                for dy in (0, 1):
                    for dx in (0, 1):
                        c = (cell[0] + dx, cell[1] + dy, cell[2] + dz)
                        if hashed:
                            h = ((c[0] * 1) ^ (c[1] * P1) ^ (c[2] * P2)) & 0xFFFFFFFF
                            row = h % t_max
                        else:
                            row = c[0] + c[1] * side + c[2] * side * side
                        w = 1.0
                        for d, bit in enumerate((dx, dy, dz)):
                            frac = pos[d] - cell[d]
                            w = w * (frac if bit else 1.0 - frac)
                        acc = acc + w * tables[lvl][row]
            feats.append(acc)
        rows.append(torch.cat(feats))
    return torch.stack(rows)


CONFIGS = [
    # (n_levels, F, log2_T, base, finest): mixes dense and hashed levels.
    (4, 2, 9, 4, 40),
    (3, 1, 10, 3, 30),
    (3, 4, 8, 2, 20),
    (2, 3, 9, 5, 9),
]


def _points(n, dtype=torch.float64, seed=0):
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(n, 3, generator=g, dtype=dtype)
    # Include the borders, where the top corner of the half-cell offset is used.
    x[0] = 0.0
    x[1] = 1.0
    x[2] = torch.tensor([1.0, 0.0, 0.999999], dtype=dtype)
    return x


def _random_tables(grid, seed=1):
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for t in grid.tables:
            t.copy_(torch.randn(t.shape, generator=g, dtype=t.dtype))


@pytest.mark.parametrize("cfg", CONFIGS)
def test_hashgrid_matches_reference(cfg):
    n_levels, f, log2_t, base, finest = cfg
    grid = HashGrid(n_levels, f, log2_t, base, finest, dtype=torch.float64)
    _random_tables(grid)
    assert any(lvl.hashed for lvl in grid.levels) and any(not lvl.hashed for lvl in grid.levels)
    x = _points(9)
    ref = _reference_encode(x, list(grid.tables), n_levels, base, finest, log2_t)
    out = grid(x)
    assert out.shape == (9, n_levels * f) == (9, grid.out_dim)
    torch.testing.assert_close(out, ref, rtol=1e-12, atol=1e-12)


def test_default_hashgrid_matches_reference():
    """Full default geometry (16 levels, T = 2^19, 16 -> 2048) on a few points."""
    grid = HashGrid(dtype=torch.float64)
    _random_tables(grid)
    x = _points(5, seed=7)
    ref = _reference_encode(x, list(grid.tables), 16, 16, 2048, 19)
    # The reference does not snap scale 2046.9999999999984 to 2047: ~1e-12 differences.
    torch.testing.assert_close(grid(x), ref, rtol=1e-9, atol=1e-9)


def test_densegrid_matches_reference():
    grid = DenseGrid(3, 2, 3, 17, dtype=torch.float64)
    _random_tables(grid)
    assert not any(lvl.hashed for lvl in grid.levels)
    x = _points(7)
    ref = _reference_encode(x, list(grid.tables), 3, 3, 17, None)
    torch.testing.assert_close(grid(x), ref, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("cfg", CONFIGS[:2])
def test_gradients_match_reference(cfg):
    """First and second-order (Eikonal-style) gradients against autograd on the reference."""
    n_levels, f, log2_t, base, finest = cfg
    grid = HashGrid(n_levels, f, log2_t, base, finest, dtype=torch.float64)
    _random_tables(grid)
    x = _points(6, seed=3)
    gen = torch.Generator().manual_seed(5)
    head = torch.randn(grid.out_dim, dtype=torch.float64, generator=gen)

    def losses(encode, params):
        xr = x.clone().requires_grad_(True)
        sdf = encode(xr) @ head
        (gx,) = torch.autograd.grad(sdf.sum(), xr, create_graph=True)
        eik = ((gx.norm(dim=-1) - 1.0) ** 2).sum()
        g1 = torch.autograd.grad(sdf.sum(), params, retain_graph=True)
        g2 = torch.autograd.grad(eik, [*params, xr])
        return gx.detach(), g1, g2

    fast = losses(grid, list(grid.tables))
    ref_tables = [t.detach().clone().requires_grad_(True) for t in grid.tables]
    slow = losses(
        lambda xr: _reference_encode(xr, ref_tables, n_levels, base, finest, log2_t), ref_tables
    )
    torch.testing.assert_close(fast[0], slow[0])
    for a, b in zip(fast[1], slow[1], strict=True):
        torch.testing.assert_close(a, b)
    for a, b in zip(fast[2], slow[2], strict=True):
        torch.testing.assert_close(a, b)


def _tiny_grid():
    grid = HashGrid(3, 2, 6, 2, 12, dtype=torch.float64)
    _random_tables(grid)
    return grid


def test_gradcheck_x_first_and_second_order():
    grid = _tiny_grid()
    # Keep points away from cell faces, where the trilinear derivative jumps.
    x = torch.tensor([[0.31, 0.47, 0.62], [0.13, 0.88, 0.41]], dtype=torch.float64)
    x.requires_grad_(True)
    assert gradcheck(grid, (x,), eps=1e-6, atol=1e-6)
    assert gradgradcheck(grid, (x,), eps=1e-6, atol=1e-6)


def test_gradcheck_tables_first_and_second_order():
    grid = _tiny_grid()
    x = torch.tensor([[0.31, 0.47, 0.62], [0.13, 0.88, 0.41]], dtype=torch.float64)
    names = [f"tables.{i}" for i in range(grid.n_levels)]

    def f(xx, *tables):
        return functional_call(grid, dict(zip(names, tables, strict=True)), (xx,))

    tables = tuple(t.detach().clone().requires_grad_(True) for t in grid.tables)
    xx = x.clone().requires_grad_(True)
    assert gradcheck(f, (xx, *tables), eps=1e-6, atol=1e-6)
    assert gradgradcheck(f, (xx, *tables), eps=1e-6, atol=1e-6)


@pytest.mark.parametrize("n_features", [1, 2, 3, 4])
def test_primitive_gradchecks(n_features):
    g = torch.Generator().manual_seed(0)
    table = torch.randn(5, n_features, dtype=torch.float64, generator=g, requires_grad=True)
    idx = torch.randint(0, 5, (8, 4), generator=g)
    w = torch.rand(8, 4, dtype=torch.float64, generator=g, requires_grad=True)
    fn = grids.interpolate_corners
    assert gradcheck(fn, (table, idx, w))
    assert gradgradcheck(fn, (table, idx, w))
    src = torch.randn(6, n_features, dtype=torch.float64, generator=g, requires_grad=True)
    flat = torch.tensor([0, 2, 2, 4, 0, 1])
    assert gradgradcheck(lambda s: grids.scatter_rows(s, flat, 5), (src,))
    assert gradgradcheck(lambda t: grids.gather_rows(t, flat), (table,))


def _level_rows(grid, xt):
    """Per-level rows (relative to the level's first row) and weights from grid.corners."""
    idx, frac = grid.corners(xt)
    bits = torch.tensor([[dx, dy, dz] for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)])
    f = frac.unsqueeze(1)  # (n_levels, 1, 3, n)
    w = torch.where(bits.view(1, 8, 3, 1).bool(), f, 1 - f).prod(2)
    return idx.long(), w


@pytest.mark.parametrize("index_dtype", [torch.int64, torch.int32])
def test_hash_rows_inside_table_and_match_tcnn_hash(index_dtype):
    grid = HashGrid(16, 2, 15, 16, 2048)
    grid.index_dtype = index_dtype
    xt = torch.rand(3, 2000) * 1.4 - 0.2  # includes points outside [0, 1]^3
    idx, w = _level_rows(grid, xt)
    assert grid.corners(xt)[0].dtype == index_dtype
    for lvl in grid.levels:
        rows = idx[lvl.index]
        assert int(rows.min()) >= 0 and int(rows.max()) < lvl.table_size
        torch.testing.assert_close(w[lvl.index].sum(0), torch.ones(2000))
    lvl = grid.levels[-1]
    assert lvl.hashed
    xi = torch.tensor([[0.3], [0.6], [0.9]])
    idx, _ = _level_rows(grid, xi)
    c = [math.floor(float(v) * lvl.scale + 0.5) for v in xi[:, 0]]
    h = (c[0] ^ (c[1] * P1) ^ (c[2] * P2)) & 0xFFFFFFFF & (2**15 - 1)
    assert int(idx[-1, 0, 0]) == h
    # Corner 7 is (x + 1, y + 1, z + 1).
    h7 = ((c[0] + 1) ^ ((c[1] + 1) * P1) ^ ((c[2] + 1) * P2)) & 0xFFFFFFFF & (2**15 - 1)
    assert int(idx[-1, 7, 0]) == h7


def test_dense_levels_are_collision_free():
    grid = HashGrid(4, 2, 15, 6, 31)
    assert grid.n_dense >= 2
    for lvl in grid.levels:
        if lvl.hashed:
            continue
        s = lvl.side
        assert lvl.table_size == s**3 <= 2**15
        # One point per reachable cell (cell centres of the staggered grid) covers every corner.
        c = torch.arange(s - 1, dtype=torch.float32)
        cz, cy, cx = torch.meshgrid(c, c, c, indexing="ij")
        cells = torch.stack((cx, cy, cz)).reshape(3, -1)
        x = (cells / lvl.scale).clamp(0, 1)
        idx, _ = _level_rows(grid, x)
        idx = idx[lvl.index]
        pos = (x * lvl.scale + 0.5).floor().long()
        corners = {}
        for k, (dz, dy, dx) in enumerate(
            (dz, dy, dx) for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)
        ):
            coords = pos + torch.tensor([[dx], [dy], [dz]])
            for j in range(coords.shape[1]):
                key = tuple(coords[:, j].tolist())
                row = int(idx[k, j])
                assert corners.setdefault(key, row) == row
        assert len(set(corners.values())) == len(corners)  # distinct corners, distinct rows
        assert len(corners) == s**3  # every vertex is reachable
        assert max(corners.values()) < lvl.table_size


def test_default_level_geometry():
    grid = HashGrid()
    assert grid.out_dim == 32
    assert [lvl.hashed for lvl in grid.levels] == [False] * 5 + [True] * 11
    assert grid.levels[0].scale == 15.0 and grid.levels[0].resolution == 16
    assert grid.levels[-1].resolution == 2048
    assert all(t.shape == (lvl.table_size, 2) for t, lvl in zip(grid.tables, grid.levels,
                                                                  strict=True))
    for t in grid.tables:
        assert float(t.detach().abs().max()) <= 1e-4 and float(t.detach().std()) > 5e-5
    assert grid.levels[5].table_size == 2**19


def test_inactive_levels_are_zero_and_get_no_gradient():
    grid = _tiny_grid()
    grid.set_active_levels(1)
    assert grid.active_levels == 1
    x = torch.rand(10, 3, dtype=torch.float64)
    out = grid(x)
    assert torch.all(out[:, 2:] == 0) and torch.any(out[:, :2] != 0)
    out.sum().backward()
    assert grid.tables[0].grad is not None and torch.any(grid.tables[0].grad != 0)
    assert grid.tables[1].grad is None and grid.tables[2].grad is None
    grid.set_active_levels(2)
    full = _tiny_grid()
    torch.testing.assert_close(grid(x)[:, :4], full(x)[:, :4])
    assert torch.all(grid(x)[:, 4:] == 0)
    grid.set_active_levels(99)
    assert grid.active_levels == 3
    grid.set_active_levels(0)
    assert grid.active_levels == 1


@pytest.mark.parametrize("shape", [(3,), (0, 3), (2, 5, 3), (2, 1, 4, 3)])
def test_any_batch_shape(shape):
    grid = _tiny_grid()
    x = torch.rand(shape, dtype=torch.float64)
    out = grid(x)
    assert out.shape == (*shape[:-1], grid.out_dim)
    torch.testing.assert_close(out.reshape(-1, grid.out_dim), grid(x.reshape(-1, 3)))


def test_float32_matches_float64_and_casts_input():
    g64 = HashGrid(4, 2, 10, 4, 64, dtype=torch.float64)
    g32 = HashGrid(4, 2, 10, 4, 64)
    _random_tables(g64)
    g32.load_state_dict({k: v.float() for k, v in g64.state_dict().items()})
    x = torch.rand(100, 3, dtype=torch.float64) * 0.98 + 0.01
    out32 = g32(x)
    assert out32.dtype == torch.float32
    torch.testing.assert_close(out32.double(), g64(x), rtol=1e-4, atol=1e-4)


def test_int32_indices_and_chunking_match():
    grid = HashGrid(6, 2, 12, 4, 256)
    x = torch.rand(500, 3, requires_grad=True)
    grid.index_dtype = torch.int64
    ref = grid(x)
    (gx_ref,) = torch.autograd.grad(ref.square().sum(), x)
    grid.index_dtype = torch.int32
    grid.chunk_size = 64
    out = grid(x)
    (gx,) = torch.autograd.grad(out.square().sum(), x)
    torch.testing.assert_close(out, ref)
    torch.testing.assert_close(gx, gx_ref)


@pytest.mark.parametrize("active", [3, 6])
def test_batched_and_per_level_encoding_agree_to_second_order(active):
    """Small batches encode all levels at once, large ones level by level, and the joined
    table (CUDA's default) gathers all levels at once: same results, same table gradients
    and the same double backward (Eikonal)."""
    grid = HashGrid(6, 2, 12, 4, 256, dtype=torch.float64)
    with torch.no_grad():
        for t in grid.tables:
            t.normal_()
    grid.set_active_levels(active)
    x = torch.rand(300, 3, dtype=torch.float64)
    results = []
    for batch_bytes, joined in ((1 << 40, False), (0, False), (1 << 40, True), (0, True)):
        grid.batch_bytes, grid.joined_gather = batch_bytes, joined
        grid.zero_grad(set_to_none=True)
        xx = x.clone().requires_grad_(True)
        out = grid(xx)
        (gx,) = torch.autograd.grad(out.sum(), xx, create_graph=True)
        (out.square().sum() + gx.square().sum()).backward()
        grads = [t.grad for t in grid.tables[:active]]
        results.append((out.detach(), gx.detach(), grads, xx.grad))
    o1, g1, t1, x1 = results[0]
    for o2, g2, t2, x2 in results[1:]:
        torch.testing.assert_close(o1, o2)
        torch.testing.assert_close(g1, g2)
        torch.testing.assert_close(x1, x2)
        for a, b in zip(t1, t2, strict=True):
            torch.testing.assert_close(a, b)


def test_joined_gather_matches_per_level_to_second_order():
    """gather_levels on one joined table equals the level-by-level gather, for 1, 2 and 4
    features per level, through gradcheck and gradgradcheck."""
    gen = torch.Generator().manual_seed(0)
    sizes = (50, 70, 30)
    idx = torch.stack([torch.randint(0, n, (8, 13), generator=gen) for n in sizes]).int()
    for n_features in (1, 2, 4):
        tables = [torch.randn(n, n_features, dtype=torch.float64, generator=gen,
                              requires_grad=True) for n in sizes]
        per_level = grids.gather_levels(tables, idx, joined=False)
        joined = grids.gather_levels(tables, idx, joined=True)
        for a, b in zip(per_level, joined, strict=True):
            assert torch.equal(a, b)
        assert gradcheck(lambda *t: grids.gather_levels(list(t), idx, joined=True), tables)
        assert gradgradcheck(lambda *t: grids.gather_levels(list(t), idx, joined=True), tables)


def test_the_encoding_makes_no_tensor_from_host_data_once_warm():
    """After the first call an encoding builds nothing from Python numbers (on a GPU each
    such tensor is a host-to-device copy that waits for the device)."""
    from torch.utils._python_dispatch import TorchDispatchMode

    grid = HashGrid(6, 2, 12, 4, 256)
    x = torch.rand(100, 3, requires_grad=True)
    made: list[str] = []

    class Watch(TorchDispatchMode):
        def __torch_dispatch__(self, func, types, args=(), kwargs=None):
            if "lift_fresh" in str(func):
                made.append(str(func))
            return func(*args, **(kwargs or {}))

    for joined in (False, True):
        grid.joined_gather = joined
        grid(x).sum().backward()  # warm: per-device constants are made here
        with Watch():
            out = grid(x)
            (gx,) = torch.autograd.grad(out.sum(), x, create_graph=True)
            (out.sum() + gx.square().sum()).backward()
    assert made == []


def test_bad_config_and_shape_raise():
    with pytest.raises(ConfigError, match="log2_hashmap_size"):
        HashGrid(log2_hashmap_size=40)
    with pytest.raises(ConfigError, match="n_levels"):
        HashGrid(n_levels=0)
    with pytest.raises(ConfigError, match="dtype"):
        HashGrid(dtype=torch.float16)
    with pytest.raises(ValueError, match=r"\(\*, 3\)"):
        HashGrid(2, 2, 8, 2, 4)(torch.rand(4, 2))


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_cuda_matches_cpu():
    grid = HashGrid(8, 2, 14, 8, 256, dtype=torch.float64)
    _random_tables(grid)
    x = torch.rand(1000, 3, dtype=torch.float64)
    gcuda = HashGrid(8, 2, 14, 8, 256, dtype=torch.float64).cuda()
    gcuda.load_state_dict(grid.state_dict())
    head = torch.randn(grid.out_dim, dtype=torch.float64)

    def run(g, xx):
        xx = xx.clone().requires_grad_(True)
        sdf = g(xx) @ head.to(xx.device)
        (gx,) = torch.autograd.grad(sdf.sum(), xx, create_graph=True)
        (gx.square().sum() + sdf.sum()).backward()
        return sdf.detach().cpu(), [t.grad.cpu() for t in g.tables]

    a, ga = run(grid, x)
    for joined in (None, False):  # CUDA's default (the joined table), then level by level
        gcuda.joined_gather = joined
        gcuda.zero_grad(set_to_none=True)
        b, gb = run(gcuda, x.cuda())
        torch.testing.assert_close(a, b)
        for u, v in zip(ga, gb, strict=True):
            torch.testing.assert_close(u, v)
