"""A trained field's training step with subnormal floats flushed to zero (the default) and
kept (``HYBRIDNEUS_KEEP_DENORMALS=1``): each in a fresh process, interleaved.

A trained field's networks hold many subnormal values, and a fresh field (what
``bench_step.py`` and the budget's probe time) holds almost none, so this resumes a finished
run: its checkpoint, dataset and config. The run folder is copied first (resuming writes to it).

    python benchmarks/bench_trained_step.py /tmp/hybridneus-compare/runs/gen-slab-...
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import common

_CHILD = """
import statistics, sys, time
from hybridneus.api import prepare
trainer, _ = prepare(None, None, resume=sys.argv[1], device="cpu")
trainer.plan = None
times = []
for i in range(int(sys.argv[2]) + 3):
    if trainer.step % max(trainer.cfg.render.occupancy_every, 1) == 0:
        trainer.step += 1  # time steps without an occupancy refresh
    start = time.perf_counter()
    trainer.train_step()
    if i >= 3:
        times.append(time.perf_counter() - start)
import torch
print(torch.get_num_threads(), statistics.median(times))
"""


def step_seconds(run: Path, keep: bool, steps: int) -> tuple[int, float]:
    """(torch threads, median seconds) of ``steps`` training steps of ``run`` resumed in a
    fresh process."""
    env = dict(os.environ)
    env.pop("HYBRIDNEUS_KEEP_DENORMALS", None)
    if keep:
        env["HYBRIDNEUS_KEEP_DENORMALS"] = "1"
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / run.name
        shutil.copytree(run, copy, ignore=shutil.ignore_patterns("snapshots", "previews"))
        out = subprocess.run([sys.executable, "-c", _CHILD, str(copy), str(steps)], env=env,
                             check=True, capture_output=True, text=True)
    threads, seconds = out.stdout.strip().splitlines()[-1].split()
    return int(threads), float(seconds)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a finished run folder (checkpoints/last.pt)")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=2)
    common.add_arguments(ap, "trained_step")
    args = ap.parse_args()
    common.check_tree(args)
    if not (args.run / "checkpoints" / "last.pt").is_file():
        raise SystemExit(f"bench_trained_step: {args.run}: no checkpoints/last.pt")
    flushed, kept = [], []
    for _ in range(args.repeats):
        threads, seconds = step_seconds(args.run, False, args.steps)
        flushed.append(seconds)
        kept.append(step_seconds(args.run, True, args.steps)[1])
    found = {"run": args.run.name, "steps": args.steps, "repeats": args.repeats,
             "flushed_s": round(statistics.median(flushed), 4),
             "kept_s": round(statistics.median(kept), 4)}
    found["kept_over_flushed"] = round(found["kept_s"] / found["flushed_s"], 2)
    for key, value in found.items():
        print(f"{key}: {value}")
    common.append(args.out, {"bench": "trained_step", **found, **common.stamp(threads)})


if __name__ == "__main__":
    main()
