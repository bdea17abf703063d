"""A trained field's training step at this commit and at another, in fresh processes,
interleaved; with the share of the step's float32 results (of its arithmetic: pointwise
operations, matrix products and reductions) that are subnormal.

x86 CPUs compute with subnormal floats (below 1.2e-38) many times slower than with normal
ones. A fresh field (what ``bench_step.py`` and the budget's probe time) makes almost none; a
trained one made many in the SDF head's Softplus tail and the NeuS sigmoid's, so this resumes a
finished run: its checkpoint, dataset and config (the run folder is copied first, as resuming
writes to it). ``--against`` runs the same steps with another commit's package, from a worktree
(see ``compare_commits.py``).

    python benchmarks/bench_trained_step.py RUN_FOLDER [RUN_FOLDER ...] --against bcf44df
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
import torch
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils._pytree import tree_flatten
from hybridneus.api import prepare

MATH = ("mm", "addmm", "bmm", "sum", "mean", "cumsum", "cumprod")

class Watch(TorchDispatchMode):
    total = subnormal = 0
    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        out = func(*args, **(kwargs or {}))
        # arithmetic only: views and empty buffers show whatever memory held, and the
        # optimizer's moments decay through the subnormal range by design
        name = func.__name__.split(".")[0]
        if "adam" in name or (torch.Tag.pointwise not in func.tags and name not in MATH):
            return out
        for t in tree_flatten(out)[0]:
            if isinstance(t, torch.Tensor) and t.dtype == torch.float32 and t.numel():
                a = t.detach().abs()
                self.total += a.numel()
                self.subnormal += int(((a > 0) & (a < torch.finfo(a.dtype).tiny)).sum())
        return out

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
with Watch() as watch:
    trainer.train_step()
print(torch.get_num_threads(), statistics.median(times), watch.subnormal / max(watch.total, 1))
"""


def step_seconds(run: Path, steps: int, site: Path | None) -> tuple[int, float, float]:
    """(torch threads, median seconds per step, subnormal share) of ``steps`` training steps
    of ``run`` resumed in a fresh process; ``site``: a folder put first on the path (another
    commit's package)."""
    env = dict(os.environ)
    if site is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(site), env.get("PYTHONPATH", "")])
    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / run.name
        shutil.copytree(run, copy, ignore=shutil.ignore_patterns("snapshots", "previews"))
        out = subprocess.run([sys.executable, "-c", _CHILD, str(copy), str(steps)], env=env,
                             check=True, capture_output=True, text=True, cwd=tmp)
    threads, seconds, share = out.stdout.strip().splitlines()[-1].split()
    return int(threads), float(seconds), float(share)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path,
                    help="finished run folders (checkpoints/last.pt)")
    ap.add_argument("--against", help="another commit, timed the same way")
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--repeats", type=int, default=2)
    common.add_arguments(ap, "trained_step")
    args = ap.parse_args()
    common.check_tree(args)
    for run in args.runs:
        if not (run / "checkpoints" / "last.pt").is_file():
            raise SystemExit(f"bench_trained_step: {run}: no checkpoints/last.pt")
    site = None
    if args.against:
        import compare_commits

        args.against = common.short_commit(args.against)
        site = compare_commits.worktree(args.against)[1]
    for run in args.runs:
        measure(run, args, site)


def measure(run: Path, args: argparse.Namespace, site: Path | None) -> None:
    """Time ``run`` here (and against ``site``), interleaved; print and append its line."""
    here, there, share, share_there = [], [], 0.0, 0.0
    for _ in range(args.repeats):
        threads, seconds, share = step_seconds(run, args.steps, None)
        here.append(seconds)
        if site is not None:
            _, seconds, share_there = step_seconds(run, args.steps, site)
            there.append(seconds)
    found = {"run": run.name, "steps": args.steps, "repeats": args.repeats,
             "step_s": round(statistics.median(here), 4), "subnormal_share": round(share, 5)}
    if site is not None:
        found.update({"against": args.against,
                      "against_step_s": round(statistics.median(there), 4),
                      "against_subnormal_share": round(share_there, 5)})
        found["speedup"] = round(found["against_step_s"] / found["step_s"], 2)
    print("  ".join(f"{key}: {value}" for key, value in found.items()), flush=True)
    common.append(args.out, {"bench": "trained_step", **found, **common.stamp(threads)})


if __name__ == "__main__":
    main()
