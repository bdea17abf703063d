"""Is a fit repeatable? The same ``--iters`` fit twice, and on a slower machine; a budget
replayed with ``--iters``.

Three checks on one dataset, each with the CLI in a fresh process:

- ``rerun``: the same ``--iters N --seed S`` fit twice: are the final fields bit for bit the
  same (the CPU is deterministic)?
- ``slower``: the same fit with one thread instead of two and with another process
  competing for the cores (a slower machine): is its schedule (learning rate and open grid
  levels, logged every step) the same?
- ``budget``: a ``--minutes`` fit, then ``--iters`` with the step count its ``scene.yaml``
  recorded: the same length; and where the fit never re-planned (``budget_replans`` 0: a
  budget too short for a re-plan's stretch), the same schedule and (same threads) the same
  field. A fit that re-planned its length to the pace of its steps repeats only the length.

    python benchmarks/bench_repeat.py /tmp/hybridneus-bench/bunny-999v-346x260-t8
"""

from __future__ import annotations

import argparse
import csv
import subprocess
import sys
import tempfile
from pathlib import Path

import common
import torch
import yaml


def fit(dataset: Path, out: Path, *args: str) -> Path:
    """Run ``hybridneus fit`` and return its run folder."""
    cmd = [sys.executable, "-m", "hybridneus.cli.app", "fit", str(dataset), "--quiet",
           "--device", "cpu", "--out", str(out), "--set", "train.log_every=1",
           "--set", "train.preview_every=0", *args]
    subprocess.run(cmd, check=True, capture_output=True, text=True)
    return out / (out / "latest").read_text().strip()


def schedule(run: Path) -> list[tuple[str, str, str]]:
    """(step, lr, levels) of every logged step."""
    with open(run / "metrics.csv", newline="") as fh:
        return [(r["step"], r["lr"], r["levels"]) for r in csv.DictReader(fh)]


def same_field(a: Path, b: Path) -> bool:
    load = [torch.load(r / "checkpoints" / "last.pt", weights_only=True)["model"] for r in (a, b)]
    return all(torch.equal(load[0][k], load[1][k]) for k in load[0])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--iters", type=int, default=300)
    ap.add_argument("--minutes", type=float, default=1.0)
    ap.add_argument("--seed", type=int, default=3)
    common.add_arguments(ap, "repeat")
    args = ap.parse_args()
    common.check_tree(args)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        base = ["--iters", str(args.iters), "--seed", str(args.seed)]
        two = ["--set", "train.threads=2"]
        a = fit(args.dataset, tmp / "a", *base, *two)
        b = fit(args.dataset, tmp / "b", *base, *two)
        busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
        try:
            c = fit(args.dataset, tmp / "c", *base, "--set", "train.threads=1")
        finally:
            busy.kill()
        d = fit(args.dataset, tmp / "d", "--minutes", str(args.minutes), "--seed",
                str(args.seed), *two)
        record = yaml.safe_load((d / "scene.yaml").read_text())
        steps = int(record["steps"])
        e = fit(args.dataset, tmp / "e", "--iters", str(steps), "--seed", str(args.seed), *two)
        found = {
            "rerun_same_field": same_field(a, b),
            "slower_same_schedule": schedule(a) == schedule(c),
            "slower_same_field": same_field(a, c),
            "budget_steps": steps,
            "budget_replans": int(record.get("replans", 0)),
            # a budgeted fit that met its deadline early has a prefix of the schedule
            "budget_completed": len(schedule(d)) == len(schedule(e)),
            "budget_same_schedule": schedule(e)[:len(schedule(d))] == schedule(d),
            "budget_same_field": same_field(d, e),
        }
    for key, value in found.items():
        print(f"{key}: {value}")
    common.append(args.out, {"bench": "repeat", "dataset": args.dataset.name,
                             "iters": args.iters, "minutes": args.minutes, **found,
                             **common.stamp(2)})


if __name__ == "__main__":
    main()
