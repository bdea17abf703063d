"""Batch throughput: N small fits run as a shell loop would, and by ``hybridneus batch``.

The same N jobs (one dataset, seeds 0..N-1, ``--iters`` steps of the ``fast`` preset, no mesh)
run these ways, alone on the machine, one after another:

- ``loop``: ``hybridneus fit`` N times in a row, each with every core (``--threads`` 0), as a
  shell loop does;
- ``local-1``: ``hybridneus batch --workers 1 --threads 1``;
- ``local-2``: ``hybridneus batch --workers 2 --threads 1``;
- ``ray-2``: ``hybridneus batch --executor ray --threads 1`` (each task one CPU, so as many at
  once as there are cores), Ray started for the batch;
- ``killed``: ``local-2`` killed outright (SIGKILL to its process group) once half the jobs are
  done and a running one is past its first checkpoint, then the same command again: the line
  says whether every job ended done, with one finished fit each, and how many were resumed
  from a checkpoint.

Per way: the total wall time and its ratio to the loop's, and for the batch ways the engine's
overhead per job: the batch's wall time less the mean job wall time (``summary.csv``) times the
jobs over the workers, divided by the jobs. One line per way to
``benchmarks/results/batch.jsonl``.

    python benchmarks/bench_batch.py --jobs 4 --iters 300
"""

from __future__ import annotations

import argparse
import csv
import shutil
import subprocess
import sys
import time
from pathlib import Path

import common
import yaml

WAYS = ("loop", "local-1", "local-2", "ray-2", "killed")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    ap.add_argument("--dataset", type=Path,
                    default=Path("/tmp/hybridneus-bench/bunny-999v-346x260-t8"))
    ap.add_argument("--jobs", type=int, default=4)
    ap.add_argument("--iters", type=int, default=300)
    ap.add_argument("--ways", nargs="+", choices=WAYS, default=list(WAYS))
    ap.add_argument("--work", type=Path, default=Path("/tmp/hybridneus-bench/batch-runs"))
    common.add_arguments(ap, "batch")
    args = ap.parse_args()
    common.check_tree(args)
    common.require_dataset(args.dataset)
    shutil.rmtree(args.work, ignore_errors=True)
    args.work.mkdir(parents=True)
    manifest = args.work / "manifest.yaml"
    manifest.write_text(yaml.safe_dump({
        "defaults": {"iters": args.iters, "seeds": list(range(args.jobs)), "mesh": False,
                     "device": "cpu"},
        "jobs": [{"name": "job", "data": str(args.dataset.resolve())}]}))
    cli = [sys.executable, "-m", "hybridneus.cli.app"]
    loop_s = None
    for way in args.ways:
        out = args.work / way
        t0 = time.perf_counter()
        if way == "killed":
            common.append(args.out, {"bench": "batch", **common.stamp(None), "way": way,
                                     "jobs": args.jobs, "iters": args.iters,
                                     "dataset": args.dataset.name,
                                     **killed(cli, manifest, out, args.jobs)})
            continue
        if way == "loop":
            for seed in range(args.jobs):
                _run([*cli, "fit", str(args.dataset), "--iters", str(args.iters), "--seed",
                      str(seed), "--out", str(out), "--device", "cpu", "--quiet"])
        else:
            engine, workers = way.split("-")
            extra = (["--workers", workers] if engine == "local"
                     else ["--executor", "ray", "--cpus-per-task", "1"])
            _run([*cli, "batch", str(manifest), "--out", str(out), "--threads", "1", "-q",
                  *extra])
        wall = time.perf_counter() - t0
        line = {"bench": "batch", **common.stamp(None), "way": way, "jobs": args.jobs,
                "iters": args.iters, "dataset": args.dataset.name, "wall_s": round(wall, 1)}
        if way == "loop":
            loop_s = wall
        else:
            with open(out / "summary.csv") as f:
                jobs = [float(r["wall_s"]) for r in csv.DictReader(f)]
            at_once = int(way.split("-")[1])
            busy = sum(jobs) / at_once
            line |= {"job_mean_s": round(sum(jobs) / len(jobs), 1),
                     "overhead_per_job_s": round((wall - busy) / len(jobs), 2)}
        if loop_s is not None:
            line["ratio_to_loop"] = round(wall / loop_s, 3)
        common.append(args.out, line)
        print(f"[batch] {way}: {wall:.1f} s"
              + (f" ({line['ratio_to_loop']:.2f}x the loop)" if "ratio_to_loop" in line else ""),
              file=sys.stderr, flush=True)


def killed(cli: list[str], manifest: Path, out: Path, n: int) -> dict:
    """Kill a 2-worker batch once half its jobs are done, run it again, and check the end."""
    import json
    import os
    import signal

    cmd = [*cli, "batch", str(manifest), "--out", str(out), "--threads", "1", "-q",
           "--workers", "2"]
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    done, started = 0, False
    while not (done >= n // 2 and started) and proc.poll() is None:
        time.sleep(0.5)
        try:
            state = json.loads((out / "batch.json").read_text())["jobs"]
        except (OSError, ValueError, KeyError):
            continue
        done = sum(r["status"] == "done" for r in state.values())
        # mid-fit: a running job past its first checkpoint
        started = any(r["status"] == "running" and any(
            (out / j / "fit").glob("*/checkpoints/last.pt")) for j, r in state.items())
    time.sleep(2.0)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    _run(cmd)
    state = json.loads((out / "batch.json").read_text())["jobs"]
    logs = {j: (out / j / "job.log").read_text().splitlines() for j in state}
    fits = {j: [ln for ln in lines if ln.startswith("$ hybridneus fit")]
            for j, lines in logs.items()}
    runs = {j: [p for p in (out / j / "fit").iterdir() if p.is_dir()] for j in state}
    return {"done_before_kill": done, "wall_s": round(time.perf_counter() - t0, 1),
            "all_done": all(r["status"] == "done" for r in state.values()),
            "one_run_each": all(len(r) == 1 for r in runs.values()),
            "resumed": sum(any("--resume" in f for f in fs) for fs in fits.values()),
            "rerun_from_start": sum(len(fs) > 1 and not any("--resume" in f for f in fs)
                                    for fs in fits.values())}


def _run(cmd: list[str]) -> None:
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"[batch] {' '.join(cmd[2:5])}: exit {proc.returncode}: "
                         f"{(proc.stderr.strip().splitlines() or [''])[-1]}")


if __name__ == "__main__":
    main()
