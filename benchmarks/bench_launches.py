"""How many operations one training step dispatches, how many read a value back from the
device, and (on a GPU) what the step costs, with the hash grid gathered per level or joined.

On a GPU a pure-PyTorch step is launch-bound: every non-view operation is at least one
kernel launch, and every read-back (``.item()``, ``float()``, boolean-mask indexing) stops the
host until the device has caught up. The counts are the same on any device, so they can be
taken on a CPU; only the times need the GPU.

    python benchmarks/bench_launches.py --cache DATASET [--device cuda] [--steps 20]

Prints, per gather mode: dispatched operations per step, the non-view ones (kernels, or
CPU loops), read-backs per step, and the median step time over ``--steps`` after
``--warmup``. Steps refresh the occupancy grid every ``render.occupancy_every`` steps; the
counted steps skip that refresh, the timed ones include it as training does. On a CPU,
encodings whose corner buffers exceed ``HashGrid.batch_bytes`` go level by level (CUDA always
batches the levels), so CPU counts stand for CUDA's only at batches under that size: the
default 256 pixels, not 1,024.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import common
import torch


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cache", type=Path, required=True, help="a dataset folder")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--preset", default="fast")
    ap.add_argument("--rays", type=int, default=0, help="pixels per step (0: the device's)")
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--threads", type=int, default=0)
    common.add_arguments(ap, "step")
    args = ap.parse_args()
    common.check_tree(args)
    if args.threads:
        torch.set_num_threads(args.threads)

    from hybridneus.api import prepare
    from hybridneus.config import apply_overrides, preset_config
    from hybridneus.dispatch_count import DispatchCount

    cfg = apply_overrides(preset_config(args.preset),
                          [f"train.n_rays={args.rays}", "train.iters=1000000"])
    trainer, _ = prepare(args.cache, cfg, device=args.device)
    every = max(cfg.render.occupancy_every, 1)
    encoding = trainer.field.encoding
    modes = [None, False, True] if hasattr(encoding, "joined_gather") else [None]

    def sync() -> None:
        if trainer.device.type == "cuda":
            torch.cuda.synchronize()

    print(f"device {trainer.device}, preset {args.preset}, {trainer.record.n_rays} pixels "
          f"per step, threads {torch.get_num_threads()}")
    print("| gather | ops / step | non-view | read-backs | median step s |")
    print("|---|---|---|---|---|")
    for mode in modes:
        if mode is not None:
            encoding.joined_gather = mode
        # late in training: every level on, the expensive end
        trainer.step, trainer.total_steps = 500_000, 1_000_000
        for _ in range(args.warmup):
            trainer.train_step()
        if trainer.step % every == 0:
            trainer.train_step()
        counter = DispatchCount()
        with counter:
            trainer.train_step()
        times = []
        for _ in range(args.steps):
            sync()
            t0 = time.perf_counter()
            trainer.train_step()
            sync()
            times.append(time.perf_counter() - t0)
        name = {None: "default", False: "per level", True: "joined"}[mode]
        if mode is None:
            name += f" ({'joined' if trainer.device.type == 'cuda' else 'per level'})"
        print(f"| {name} | {counter.ops} | {counter.kernels} | {len(counter.reads)} | "
              f"{statistics.median(times):.4f} |", flush=True)
        common.append(args.out, {
            "bench": "launches", "preset": args.preset, "rays": trainer.record.n_rays,
            "gather": name, "ops": counter.ops, "kernels": counter.kernels,
            "reads": len(counter.reads), "step_s": round(statistics.median(times), 5),
            **common.stamp(torch.get_num_threads(), str(trainer.device))})


if __name__ == "__main__":
    main()
