"""Points per second of the hash-grid encoding: forward, forward+backward, Eikonal double backward.

Compares, in one run and on the same inputs:
  ours     hybridneus.grids.HashGrid (per-level tables, complex pairs, custom autograd)
  ours-i64 the same with int64 row indices (int32 is the default)
  ours-joined / ours-per-level   ours with its tables gathered as one joined table / level
           by level (the defaults: joined on CUDA, per level on the CPU)
  flat     a straightforward version: one flat table, all levels broadcast, int64 table[idx]
  floor    only the memory traffic: index_select (+ scatter_add_) of the same number of rows

Examples:
  python benchmarks/bench_grids.py                       # --quick subset
  python benchmarks/bench_grids.py --log2-t 19 --log2-n 18 --repeats 5
  python benchmarks/bench_grids.py --full                # T 2^15..2^19 x N 2^14..2^18
  python benchmarks/bench_grids.py --device cuda --impl ours flat floor
  python benchmarks/bench_grids.py --device cuda --impl ours-joined ours-per-level --log2-n 14 16 18
  THP_MEM_ALLOC_ENABLE=1 python benchmarks/bench_grids.py ...   # transparent huge pages
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections.abc import Callable

import common
import torch

from hybridneus.grids import DenseGrid, HashGrid
from hybridneus.grids.levels import PRIMES

MODES = ("fwd", "fwd+bwd", "eikonal")


class FlatHashGrid(torch.nn.Module):
    """The straightforward version: every level at once, one table, int64 ``table[idx]``."""

    def __init__(self, grid: HashGrid) -> None:
        super().__init__()
        sizes = [lvl.table_size for lvl in grid.levels]
        self.table = torch.nn.Parameter(torch.cat([t.detach() for t in grid.tables]))
        self.register_buffer("offsets", torch.tensor([0, *sizes[:-1]]).cumsum(0))
        self.register_buffer(
            "scales", torch.tensor([lvl.scale for lvl in grid.levels], dtype=torch.float64)
        )
        self.register_buffer("sides", torch.tensor([lvl.side for lvl in grid.levels]))
        self.register_buffer("hashed", torch.tensor([lvl.hashed for lvl in grid.levels]))
        self.register_buffer("masks", torch.tensor(sizes) - 1)
        bits = torch.tensor([[dx, dy, dz] for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)])
        self.register_buffer("bits", bits)
        self.out_dim = grid.out_dim

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        pos = x[:, None, :] * self.scales.to(x.dtype)[None, :, None] + 0.5  # (n, L, 3)
        cell = pos.detach().floor()
        frac = pos - cell
        corner = cell.long()[:, :, None, :] + self.bits  # (n, L, 8, 3)
        s = self.sides[None, :, None]
        dense = corner[..., 0] + corner[..., 1] * s + corner[..., 2] * s * s
        hashed = (corner[..., 0] * PRIMES[0]) ^ (corner[..., 1] * PRIMES[1])
        hashed = (hashed ^ (corner[..., 2] * PRIMES[2])) & self.masks[None, :, None]
        idx = torch.where(self.hashed[None, :, None], hashed, dense) + self.offsets[None, :, None]
        w = torch.where(self.bits.bool(), frac[:, :, None, :], 1.0 - frac[:, :, None, :]).prod(-1)
        feats = (self.table[idx] * w[..., None]).sum(2)  # (n, L, F)
        return feats.reshape(x.shape[0], self.out_dim)


def make_floor(grid: HashGrid) -> Callable[[torch.Tensor, str], None]:
    """Gathers and scatters as many complex rows as the grid: the memory-traffic floor."""
    tables = [torch.view_as_complex(t.detach()) for t in grid.tables]
    cache: dict[int, list[torch.Tensor]] = {}

    def run(x: torch.Tensor, mode: str) -> None:
        n = x.shape[0]
        if n not in cache:
            cache[n] = [torch.randint(0, lvl.table_size, (8 * n,), device=x.device)
                        for lvl in grid.levels]
        n_pass = {"fwd": (1, 0), "fwd+bwd": (1, 1), "eikonal": (2, 2)}[mode]
        for tab, idx in zip(tables, cache[n], strict=True):
            for _ in range(n_pass[0]):
                vals = tab.index_select(0, idx)
            for _ in range(n_pass[1]):
                torch.zeros_like(tab).scatter_add_(0, idx, vals)

    return run


def run_mode(model: torch.nn.Module, x: torch.Tensor, mode: str) -> None:
    if mode == "fwd":
        with torch.no_grad():
            model(x)
        return
    head = torch.ones(model.out_dim, device=x.device, dtype=x.dtype)
    if mode == "fwd+bwd":
        (model(x) @ head).sum().backward()
        return
    xr = x.detach().requires_grad_(True)
    sdf = model(xr) @ head
    (grad_x,) = torch.autograd.grad(sdf.sum(), xr, create_graph=True)
    (sdf.sum() + ((grad_x.norm(dim=-1) - 1.0) ** 2).sum()).backward()


def bench_dense(args: argparse.Namespace) -> None:
    """DenseGrid() against a HashGrid with the same 8 levels (16 -> 128, T = 2^19)."""
    device = torch.device(args.device)
    n = 2 ** (args.log2_n or [16])[0]
    x = torch.rand(n, 3, device=device)
    models = {
        "DenseGrid()": DenseGrid().to(device),
        "HashGrid(8, 2, 19, 16, 128)": HashGrid(8, 2, 19, 16, 128).to(device),
    }
    print(f"| grid (N = {n}) | " + " | ".join(args.modes) + " |")
    print("|---|" + "---|" * len(args.modes))
    rows = {name: [] for name in models}
    for mode in args.modes:
        times: dict[str, list[float]] = {k: [] for k in models}
        for rep in range(args.repeats + 1):
            for name, model in models.items():
                sync(device)
                t0 = time.perf_counter()
                run_mode(model, x, mode)
                sync(device)
                if rep:
                    times[name].append(time.perf_counter() - t0)
                model.zero_grad(set_to_none=True)
        for name in models:
            rows[name].append(f"{n / statistics.median(times[name]) / 1e6:.3g}")
    for name, cells in rows.items():
        print(f"| {name} | " + " | ".join(cells) + " |")


def sync(device: torch.device) -> None:
    if device.type == "cuda":
        torch.cuda.synchronize()


def bench_case(log2_t: int, log2_n: int, impls: list[str], args: argparse.Namespace) -> dict:
    device = torch.device(args.device)
    torch.manual_seed(0)
    grid = HashGrid(log2_hashmap_size=log2_t).to(device)
    x = torch.rand(2**log2_n, 3, device=device)
    runners: dict[str, Callable[[str], None]] = {}
    for impl in impls:
        if impl == "ours":
            runners[impl] = lambda m, g=grid: run_mode(g, x, m)
        elif impl == "ours-i64":
            g64 = HashGrid(log2_hashmap_size=log2_t).to(device)
            g64.load_state_dict(grid.state_dict())
            g64.index_dtype = torch.int64
            runners[impl] = lambda m, g=g64: run_mode(g, x, m)
        elif impl in ("ours-joined", "ours-per-level"):
            gj = HashGrid(log2_hashmap_size=log2_t).to(device)
            gj.load_state_dict(grid.state_dict())
            gj.joined_gather = impl == "ours-joined"
            runners[impl] = lambda m, g=gj: run_mode(g, x, m)
        elif impl.startswith("ours-chunk"):
            gc = HashGrid(log2_hashmap_size=log2_t).to(device)
            gc.load_state_dict(grid.state_dict())
            gc.chunk_size = 2 ** int(impl.removeprefix("ours-chunk"))
            runners[impl] = lambda m, g=gc: run_mode(g, x, m)
        elif impl == "flat":
            flat = FlatHashGrid(grid).to(device)
            runners[impl] = lambda m, g=flat: run_mode(g, x, m)
        elif impl == "compiled-ours":
            comp = torch.compile(grid)
            comp.out_dim = grid.out_dim
            runners[impl] = lambda m, g=comp: run_mode(g, x, m)
        elif impl == "floor":
            floor = make_floor(grid)
            runners[impl] = lambda m, f=floor: f(x, m)
        else:
            raise SystemExit(f"unknown --impl {impl}")
    results = {}
    for mode in args.modes:
        times: dict[str, list[float]] = {k: [] for k in runners}
        for rep in range(args.repeats + 1):  # first round is warm-up
            for name, run in runners.items():
                if name == "flat" and log2_n > args.flat_max_log2_n:
                    continue
                sync(device)
                t0 = time.perf_counter()
                run(mode)
                sync(device)
                if rep:
                    times[name].append(time.perf_counter() - t0)
                for p in grid.parameters():
                    p.grad = None
        for name, ts in times.items():
            if ts:
                results[(mode, name)] = 2**log2_n / statistics.median(ts) / 1e6
    return results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--log2-t", type=int, nargs="+", help="table sizes (log2); quick: 15 19")
    ap.add_argument("--log2-n", type=int, nargs="+", help="batch sizes (log2); quick: 16 18")
    ap.add_argument("--full", action="store_true", help="T 2^15..2^19 x N 2^14..2^18")
    ap.add_argument("--modes", nargs="+", default=list(MODES), choices=MODES)
    ap.add_argument("--impl", nargs="+", default=["ours", "ours-i64", "flat", "floor"],
                    help="ours ours-i64 ours-chunk<log2> flat floor compiled-ours")
    ap.add_argument("--repeats", type=int, default=5, help="timed repeats (median); default 5")
    ap.add_argument("--flat-max-log2-n", type=int, default=18,
                    help="skip the slow flat version above this batch size")
    ap.add_argument("--threads", type=int, help="torch.set_num_threads")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--dense", action="store_true",
                    help="compare DenseGrid() with a HashGrid of the same levels instead")
    common.add_arguments(ap, "grids")
    args = ap.parse_args()
    common.check_tree(args)
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.dense:
        bench_dense(args)
        return
    if args.full:
        ts, ns = args.log2_t or list(range(15, 20)), args.log2_n or list(range(14, 19))
    else:
        ts, ns = args.log2_t or [15, 19], args.log2_n or [16, 18]
    print(f"# torch {torch.__version__}, device {args.device}, threads {torch.get_num_threads()},"
          f" 16 levels x 2 features, 16 -> 2048; M points/s, median of {args.repeats}")
    print("| T | N | mode | " + " | ".join(args.impl) + " | ours / flat |")
    print("|---|---|---|" + "---|" * (len(args.impl) + 1))
    for log2_t in ts:
        for log2_n in ns:
            res = bench_case(log2_t, log2_n, args.impl, args)
            for mode in args.modes:
                cells = [res.get((mode, k)) for k in args.impl]
                txt = ["-" if c is None else f"{c:.3g}" for c in cells]
                ours, flat = res.get((mode, "ours")), res.get((mode, "flat"))
                ratio = f"{ours / flat:.1f}x" if ours and flat else "-"
                print(f"| 2^{log2_t} | 2^{log2_n} | {mode} | " + " | ".join(txt) + f" | {ratio} |",
                      flush=True)
                common.append(args.out, {
                    "bench": "grids", "log2_t": log2_t, "log2_n": log2_n, "mode": mode,
                    "mpoints_per_s": {k: (None if c is None else round(c, 4))
                                      for k, c in zip(args.impl, cells, strict=True)},
                    **common.stamp(torch.get_num_threads(), args.device)})


if __name__ == "__main__":
    main()
