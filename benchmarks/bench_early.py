"""Does a fit's field empty in its first steps? The opening of an ``--iters`` schedule, per seed.

A field that empties (the rendered opacity near zero) early in a fit is restored by the
collapse guard, but the fit that follows is another fit: on the generated cage, budgeted fits
of one seed scored 0.032 to 0.133 with zero to two such restores. This runs the first
``--steps`` steps of an ``--iters`` schedule (the early phase of a 15-minute fit on a 2-core
CPU, coarse-to-fine still at its first levels) for several seeds and config variants, and
writes one line per variant: per seed the restores, the lowest mean opacity over the collapse
guard's window (25 steps), and the sharpness and the marked share of the occupancy grid at
the last step. A fixed ``--iters`` schedule on a CPU is deterministic, so each seed's line
repeats.

    python benchmarks/bench_early.py /tmp/hybridneus-bench/gen-cage-56731231-999v-346x260-t8 \\
        --seeds 0 1 2 3 4 5 --variants "" priors.hull.enabled=false
"""

from __future__ import annotations

import argparse
import tempfile
from collections import deque
from pathlib import Path

import common


def opening_config(seed: int, iters: int, threads: int, overrides: list[str]):
    """The ``fast`` config of an ``iters``-step schedule with ``overrides``, without previews."""
    from hybridneus.config import apply_overrides, preset_config

    return apply_overrides(preset_config("fast"), [
        f"train.iters={iters}", f"train.seed={seed}", f"train.threads={threads}",
        "train.preview_every=0", *overrides])


def run_opening(dataset: Path, cfg, steps: int, record) -> None:
    """Fit ``dataset`` with ``cfg`` into a throw-away folder, calling ``record(trainer, logs)``
    after every step, and stop after step ``steps``."""
    from hybridneus.api import fit

    def step(trainer, logs) -> None:
        record(trainer, logs)
        if trainer.step >= steps:
            raise KeyboardInterrupt  # as Ctrl-C: the fit saves and returns

    with tempfile.TemporaryDirectory() as tmp:
        fit(dataset, cfg, [step], out=tmp, device="cpu")


def opening(dataset: Path, seed: int, steps: int, iters: int, overrides: list[str],
            threads: int) -> dict:
    """The first ``steps`` steps of a ``fast`` fit of ``iters`` steps; what they did."""
    cfg = opening_config(seed, iters, threads, overrides)
    # the opacity averaged as the collapse guard averages it
    width = cfg.priors.collapse_guard.window
    window: deque[float] = deque(maxlen=width)
    seen = {"lowest": float("inf")}

    def record(trainer, logs) -> None:
        window.append(logs["opacity"])
        if len(window) == width:
            seen["lowest"] = min(seen["lowest"], sum(window) / width)
        seen.update(restores=int(logs.get("restores", 0)), inv_s=logs["inv_s"],
                    occupied=logs["occupied"])

    run_opening(dataset, cfg, steps, record)
    lowest = seen["lowest"]  # None: fewer steps than one window
    return {"seed": seed, "restores": seen["restores"],
            "lowest_opacity": round(lowest, 4) if lowest != float("inf") else None,
            "inv_s": round(seen["inv_s"], 1), "occupied": round(seen["occupied"], 3)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5])
    ap.add_argument("--steps", type=int, default=300, help="steps run of each schedule")
    ap.add_argument("--iters", type=int, default=4500,
                    help="the schedule's length (about a 15-minute fit on a 2-core CPU)")
    ap.add_argument("--variants", nargs="+", default=[""],
                    help="config overrides, KEY=VALUE[+KEY=VALUE...]; '' is the preset")
    ap.add_argument("--threads", type=int, default=2)
    common.add_arguments(ap, "early")
    args = ap.parse_args()
    common.check_tree(args)
    common.require_dataset(args.dataset)
    for variant in args.variants:
        overrides = [o for o in variant.split("+") if o]
        runs = [opening(args.dataset, s, args.steps, args.iters, overrides, args.threads)
                for s in args.seeds]
        emptied = sum(r["restores"] > 0 for r in runs)
        print(f"{variant or 'fast'}: emptied in {emptied} of {len(runs)} seeds; "
              + ", ".join(f"seed {r['seed']}: {r['restores']} restores, lowest opacity "
                          f"{r['lowest_opacity']}" for r in runs))
        common.append(args.out, {
            "bench": "early", "dataset": args.dataset.name, "variant": variant or "fast",
            "steps": args.steps, "iters": args.iters, "emptied": emptied,
            "seeds": len(runs), "restores": [r["restores"] for r in runs],
            "lowest_opacity": [r["lowest_opacity"] for r in runs],
            "inv_s": [r["inv_s"] for r in runs], "occupied": [r["occupied"] for r in runs],
            **common.stamp(args.threads)})


if __name__ == "__main__":
    main()
