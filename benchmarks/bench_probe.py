"""How much the budget's probe moves between probes: the mean step it predicts, repeated.

Builds the trainer of a ``--minutes`` fit on a dataset (preset ``fast``) and runs the probe
of :mod:`hybridneus.training.budget` ``--repeats`` times in one process, each time with every
``--steps`` count of timed steps per point in turn (interleaved, so that a drift of the
machine touches each count alike), and reports for each count the median, extremes and
coefficient of variation of the mean seconds per step the probe predicts for a whole
schedule, and the probe's own seconds. Nothing else should run on the machine.

    python benchmarks/bench_probe.py /tmp/hybridneus-bench/gen-cage-56731231-999v-346x260-t8
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

import common


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--repeats", type=int, default=8)
    ap.add_argument("--steps", type=int, nargs="+", default=[5, 10, 20],
                    help="timed steps per probe point (after the warm-up steps)")
    ap.add_argument("--threads", type=int, default=2)
    common.add_arguments(ap, "probe")
    args = ap.parse_args()
    common.check_tree(args)
    common.require_dataset(args.dataset)
    import torch

    from hybridneus.api import prepare
    from hybridneus.training import budget

    torch.set_num_threads(args.threads)
    trainer, _ = prepare(args.dataset, "fast",
                         ["train.iters=3000", f"train.threads={args.threads}"], device="cpu")
    default = budget.PROBE_STEPS
    means: dict[int, list[float]] = {n: [] for n in args.steps}
    seconds: dict[int, list[float]] = {n: [] for n in args.steps}
    try:
        for _ in range(args.repeats):
            for n in args.steps:
                budget.PROBE_STEPS = n
                start = time.perf_counter()
                probed = budget.step_seconds(trainer)
                seconds[n].append(time.perf_counter() - start)
                means[n].append(1000.0 * budget.mean_step_seconds(
                    *probed, budget._full_at(trainer), trainer.cfg.render.occupancy_every))
    finally:
        budget.PROBE_STEPS = default
    for n in args.steps:
        m = means[n]
        cv = statistics.stdev(m) / statistics.mean(m) if len(m) > 1 else 0.0
        print(f"{n} steps per point: mean step {statistics.median(m):.1f} ms (median; "
              f"{min(m):.1f} to {max(m):.1f}, variation {100 * cv:.1f}%), probe "
              f"{statistics.median(seconds[n]):.1f} s")
        common.append(args.out, {
            "bench": "probe", "dataset": args.dataset.name, "steps_per_point": n,
            "warmup": budget.PROBE_WARMUP, "default": n == default, "repeats": args.repeats,
            "mean_step_ms": round(statistics.median(m), 1), "min_ms": round(min(m), 1),
            "max_ms": round(max(m), 1), "variation": round(cv, 3),
            "probe_s": round(statistics.median(seconds[n]), 2),
            **common.stamp(args.threads)})


if __name__ == "__main__":
    main()
