"""How long `hybridneus fit` takes from its start to its first training step.

Runs the CLI in a fresh process on a full-size dataset (999 views, about 3 million events),
with a fixed step count (loading, the estimators, the hull prior's outline, the trainer) and
with a time budget (the same, plus the probe that turns the budget into steps), and reports
the seconds from the command's start to the start of its first step. Medians over
``--repeats`` processes; nothing else should run on the machine.

    python benchmarks/bench_startup.py /tmp/hybridneus-bench/xylophone-999v-346x260-t8
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import common

# The child: the fit command in this process, with its first training step timed.
CHILD = """
import json, sys, time
start = time.perf_counter()
from hybridneus.training.trainer import Trainer
from hybridneus.cli.app import main
real, seen = Trainer.fit, {}
def stop(trainer, logs):  # one step is enough: stop the fit as Ctrl-C would
    raise KeyboardInterrupt
def timed(self, callbacks=(), run=None, progress=True):
    seen["first_step_s"] = time.perf_counter() - start
    return real(self, [stop], run, progress)
Trainer.fit = timed
sys.argv = ["hybridneus", "fit", *sys.argv[1:]]
try:
    main()
except SystemExit:
    pass
print(json.dumps(seen))
"""


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    common.add_arguments(ap, "startup")
    args = ap.parse_args()
    common.check_tree(args)
    from hybridneus.data import load_dataset

    events = len(load_dataset(args.dataset, splits="train")["train"].events)
    for mode, budget in (("iters", ["--iters", "100"]), ("minutes", ["--minutes", "15"])):
        times = []
        for _ in range(args.repeats):
            with tempfile.TemporaryDirectory() as tmp:
                cmd = [sys.executable, "-c", CHILD, str(args.dataset), *budget, "--quiet",
                       "--device", "cpu", "--out", tmp, "--set",
                       f"train.threads={args.threads}", "--set", "train.preview_every=0"]
                out = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
                if out.returncode not in (0, 130):  # 130: stopped after its first step
                    raise SystemExit(out.stderr[-2000:])
                times.append(json.loads(out.stdout.strip().splitlines()[-1])["first_step_s"])
        median = statistics.median(times)
        print(f"{mode}: {median:.2f} s from the command's start to the first step "
              f"(runs: {', '.join(f'{t:.2f}' for t in times)})")
        common.append(args.out, {"bench": "startup", "mode": mode, "dataset": args.dataset.name,
                                 "events": events, "first_step_s": round(median, 3),
                                 "runs_s": [round(t, 3) for t in times],
                                 **common.stamp(args.threads)})


if __name__ == "__main__":
    main()
