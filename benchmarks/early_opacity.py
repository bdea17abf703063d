"""Screen a fit's first steps for the field emptying: mean opacity every 25 steps.

A fit that loses its surface early (mean rendered opacity falling to ~0) never gets it back,
and it shows within a few hundred steps, long before a 15-minute run ends. This runs
``train_step()`` for ``--steps`` steps under a schedule of ``--total`` steps (so the level
and learning-rate schedules are those of a long fit) and prints the mean opacity::

    python benchmarks/early_opacity.py /tmp/hb-nopreset/xylophone-999v-346x260-t8 \\
        --steps 150 --set data.tonemap_eps=0.001
"""

from __future__ import annotations

import argparse
import sys


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="dataset folder")
    ap.add_argument("--steps", type=int, default=150, help="steps to run")
    ap.add_argument("--total", type=int, default=8000, help="schedule length (train.iters)")
    ap.add_argument("--every", type=int, default=25, help="steps per printed mean")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()

    from hybridneus.api import prepare

    overrides = [f"train.iters={args.total}", f"train.threads={args.threads}", *args.set]
    trainer, _ = prepare(args.data, "fast", overrides, None, None, "cpu")
    opacity: list[float] = []
    lowest = float("inf")
    for i in range(args.steps):
        opacity.append(trainer.train_step()["opacity"])
        if (i + 1) % args.every == 0:
            mean = sum(opacity[-args.every:]) / args.every
            lowest = min(lowest, mean)
            print(f"step {i + 1}: opacity {mean:.3f}", flush=True)
    print(f"eps {trainer.scene['tonemap_eps']:g}, lowest mean opacity {lowest:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
