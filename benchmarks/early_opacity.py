"""Screen a fit's first steps for the field emptying: mean opacity every ``--every`` steps.

A fit that loses its surface early (mean rendered opacity falling to ~0) never gets it back
unless the trainer's collapse guard restores it, and it shows within a few hundred steps, long
before a 15-minute run ends. This runs ``train_step()`` for ``--steps`` steps under a schedule
of ``--total`` steps (so the level and learning-rate schedules are those of a long fit), for
each of ``--seeds``, and prints the mean opacity, the guard's restores and the final mean::

    python benchmarks/early_opacity.py /tmp/hb-turn3/real/bunny-999v-346x260-t8 \\
        --steps 400 --total 11000 --threads 2 --every 50 --seeds 0 1 2 3 4 5 6 7 \\
        --set train.collapse_opacity=0
"""

from __future__ import annotations

import argparse
import logging
import sys


def screen(data: str, seed: int, args: argparse.Namespace) -> dict[str, float]:
    from hybridneus.api import prepare

    overrides = [f"train.iters={args.total}", f"train.threads={args.threads}",
                 f"train.seed={seed}", *args.set]
    trainer, _ = prepare(data, "fast", overrides, None, None, "cpu")
    opacity: list[float] = []
    means: list[float] = []
    for i in range(args.steps):
        opacity.append(trainer.train_step()["opacity"])
        if (i + 1) % args.every == 0:
            means.append(sum(opacity[-args.every:]) / args.every)
    print(f"seed {seed}: mean opacity per {args.every} steps "
          + " ".join(f"{m:.3f}" for m in means), flush=True)
    return {"seed": seed, "lowest": min(means), "final": means[-1],
            "restores": trainer.restores, "eps": trainer.scene["tonemap_eps"]}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="dataset folder")
    ap.add_argument("--steps", type=int, default=150, help="steps to run")
    ap.add_argument("--total", type=int, default=8000, help="schedule length (train.iters)")
    ap.add_argument("--every", type=int, default=25, help="steps per printed mean")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0], help="train.seed values")
    ap.add_argument("--empty", type=float, default=0.05,
                    help="a final mean opacity below this counts as emptied")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    args = ap.parse_args()
    if args.steps < args.every:
        ap.error("--steps must be at least --every")
    logging.basicConfig(level=logging.WARNING, format="  %(message)s")

    rows = [screen(args.data, seed, args) for seed in args.seeds]
    for r in rows:
        print(f"seed {r['seed']}: lowest {r['lowest']:.3f}, final {r['final']:.3f}, "
              f"restores {r['restores']}")
    held = sum(r["final"] >= args.empty for r in rows)
    print(f"eps {rows[0]['eps']:g}; {held} of {len(rows)} seeds end with mean opacity >= "
          f"{args.empty} ({' '.join(args.set) or 'defaults'})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
