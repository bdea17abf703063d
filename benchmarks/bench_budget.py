"""A ``--minutes`` budget on a machine that is busy for a while: how much of it the fit uses.

``hybridneus fit DATASET --minutes M`` runs as a user runs it, while ``--hogs`` processes
that spin a core each (default: one per core) run beside it for its first ``--busy``
minutes, as a package install or a second job would; then the machine is the fit's alone.
With ``--quiet-too`` the same fit also runs alone first, for its step count. Per fit one line
to ``benchmarks/results/budget.jsonl``: the budget, the busy minutes, the steps run and
planned, the re-plans and the range of paces they measured (multiples of the probe's step
time), the wall time of the whole command and the share of the budget it used. A fit whose
loading leaves its budget no time for steps refuses to train; its line then holds 0 steps
and the fit's message as ``refused``. Target: at least 95% of the budget used, and never
more than it.

    python benchmarks/bench_budget.py /tmp/hybridneus-bench/bunny-999v-346x260-t8 \\
        --minutes 15 --busy 3 --quiet-too
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import common
import yaml

#: A process that keeps one core busy until it is killed.
SPIN = "while True:\n    pass\n"


def busy(hogs: int, seconds: float) -> threading.Thread:
    """Start ``hogs`` spinning processes now and kill them after ``seconds`` (a thread that
    the caller joins)."""
    procs = [subprocess.Popen([sys.executable, "-c", SPIN]) for _ in range(hogs)]

    def stop() -> None:
        time.sleep(seconds)
        for p in procs:
            p.kill()
            p.wait()

    thread = threading.Thread(target=stop, daemon=True)
    thread.start()
    return thread


def run_fit(dataset: Path, out: Path, minutes: float, threads: int, seed: int) -> dict:
    """``hybridneus fit`` in a fresh process; its scene record and the command's wall time."""
    cmd = [sys.executable, "-m", "hybridneus.cli.app", "fit", str(dataset), "--quiet",
           "--device", "cpu", "--out", str(out), "--minutes", str(minutes), "--seed",
           str(seed), "--set", f"train.threads={threads}"]
    start = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    wall = time.perf_counter() - start
    timing = {"wall_s": round(wall, 1), "used": round(wall / (60.0 * minutes), 4)}
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        # the fit's refusal of a budget that loading used up (hybridneus.api), not a bad
        # train.minutes: on a machine that busy the line says so instead of the bench failing
        if "train.minutes:" in last and " leave time for " in last:
            return {"steps": 0, "planned": 0, "stopped_early": False, "replans": 0,
                    "paces": None, "refused": last, **timing}
        raise SystemExit(f"error: {dataset}: the fit failed ({last})")
    run = out / (out / "latest").read_text().strip()
    record = yaml.safe_load((run / "scene.yaml").read_text())
    ran = record["stopped_at"] if record.get("stopped_at") is not None else record["steps"]
    return {"steps": int(ran), "planned": int(record["steps"]),
            "stopped_early": record.get("stopped_at") is not None,
            "replans": int(record.get("replans", 0)), "paces": record.get("paces"), **timing}

def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--minutes", type=float, default=15.0, help="the fit's budget")
    ap.add_argument("--busy", type=float, default=3.0, help="minutes the hogs run at the start")
    ap.add_argument("--hogs", type=int, default=os.cpu_count() or 2,
                    help="spinning processes beside the fit (default: one per core)")
    ap.add_argument("--threads", type=int, default=2, help="the fit's torch threads")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quiet-too", action="store_true",
                    help="also fit alone first, for the steps the machine gives when quiet")
    common.add_arguments(ap, "budget")
    args = ap.parse_args()
    common.check_tree(args)
    common.require_dataset(args.dataset)
    runs = [("quiet", 0.0)] if args.quiet_too else []
    runs.append(("busy", args.busy))
    with tempfile.TemporaryDirectory() as tmp:
        for name, minutes_busy in runs:
            hogs = busy(args.hogs, 60.0 * minutes_busy) if minutes_busy > 0 else None
            found = run_fit(args.dataset, Path(tmp) / name, args.minutes, args.threads,
                            args.seed)
            if hogs is not None:
                hogs.join()
            line = {"bench": "budget", **common.stamp(args.threads),
                    "dataset": args.dataset.name, "minutes": args.minutes,
                    "busy_minutes": minutes_busy, "hogs": args.hogs if minutes_busy else 0,
                    "seed": args.seed, **found}
            common.append(args.out, line)
            print(json.dumps({k: v for k, v in line.items() if k != "machine"}), flush=True)


if __name__ == "__main__":
    main()
