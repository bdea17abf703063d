"""HashGrid: all levels batched vs one level at a time, interleaved in one process.

``grid.batch_bytes`` decides which path a chunk takes; this script forces each in turn
(2**40: always batched, 0: always per level) on the same inputs and prints M points/s for
forward, forward+backward and the Eikonal double backward (medians of --repeats).

    python benchmarks/bench_grid_batching.py
    python benchmarks/bench_grid_batching.py --log2-n 14 15 16 17 --threads 2
"""

from __future__ import annotations

import argparse
import time

import torch

from hybridneus.grids import HashGrid


def fwd(grid: HashGrid, head: torch.Tensor, x: torch.Tensor) -> None:
    with torch.no_grad():
        grid(x)


def fwd_bwd(grid: HashGrid, head: torch.Tensor, x: torch.Tensor) -> None:
    grid.zero_grad(set_to_none=True)
    (grid(x) @ head).sum().backward()


def eikonal(grid: HashGrid, head: torch.Tensor, x: torch.Tensor) -> None:
    grid.zero_grad(set_to_none=True)
    xx = x.clone().requires_grad_(True)
    sdf = grid(xx) @ head
    (g,) = torch.autograd.grad(sdf.sum(), xx, create_graph=True)
    (sdf.sum() + ((g.norm(dim=-1) - 1) ** 2).sum()).backward()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log2-n", type=int, nargs="+", default=[14, 15, 16, 17])
    ap.add_argument("--tables", nargs="+", default=["17:512", "19:2048"],
                    help="log2 table size : finest resolution")
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    torch.manual_seed(0)
    torch.set_num_threads(args.threads)
    print("| T | N | fwd | fwd+bwd | eikonal |  (M points/s, batched / per level)")
    print("|---|---|---|---|---|")
    for spec in args.tables:
        log2_t, finest = (int(v) for v in spec.split(":"))
        grid = HashGrid(16, 2, log2_t, 16, finest)
        head = torch.randn(32, 1)

        for log2_n in args.log2_n:
            x = torch.rand(2**log2_n, 3)
            cells = []
            for f in (fwd, fwd_bwd, eikonal):
                times: dict[int, list[float]] = {2**40: [], 0: []}
                for bb in times:  # warm-up
                    grid.batch_bytes = bb
                    f(grid, head, x)
                for _ in range(args.repeats):
                    for bb in times:
                        grid.batch_bytes = bb
                        t = time.perf_counter()
                        f(grid, head, x)
                        times[bb].append(time.perf_counter() - t)
                rates = [x.shape[0] / sorted(v)[len(v) // 2] / 1e6 for v in times.values()]
                cells.append(f"{rates[0]:.2f} / {rates[1]:.2f}")
            print(f"| 2^{log2_t} | 2^{log2_n} | " + " | ".join(cells) + " |", flush=True)


if __name__ == "__main__":
    main()
