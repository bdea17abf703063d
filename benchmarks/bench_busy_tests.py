"""The default test run on a busy machine: does it pass while other processes spin every core?

Runs ``python -m pytest -q`` (the README's test command, on this checkout) while ``--hogs``
processes that spin a core each run beside it (default: one per core), and records how many
tests passed and failed, its wall time and the load it ran under. No test may depend on the
machine's speed, so the counts must be those of a quiet run. One line to
``benchmarks/results/busy_tests.jsonl``.

    python benchmarks/bench_busy_tests.py --hogs 2
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time

import common
from bench_budget import SPIN


def counts(summary: str) -> dict[str, int]:
    """pytest's closing line (``610 passed, 7 deselected in 12.3s``) as numbers."""
    found = {word: int(n) for n, word in re.findall(r"(\d+) (passed|failed|errors?|skipped"
                                                   r"|deselected)", summary)}
    found["errors"] = found.pop("error", 0) + found.pop("errors", 0)
    return {k: found.get(k, 0) for k in ("passed", "failed", "errors", "skipped", "deselected")}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    ap.add_argument("--hogs", type=int, default=os.cpu_count() or 2,
                    help="spinning processes beside the tests (default: one per core)")
    common.add_arguments(ap, "busy_tests")
    args = ap.parse_args()
    common.check_tree(args)
    hogs = [subprocess.Popen([sys.executable, "-c", SPIN]) for _ in range(args.hogs)]
    try:
        start = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "pytest", "-q"], cwd=common.REPO,
                              capture_output=True, text=True)
        wall = time.perf_counter() - start
    finally:
        for p in hogs:
            p.kill()
            p.wait()
    summary = (proc.stdout.strip().splitlines() or [""])[-1]
    line = {"bench": "busy_tests", **common.stamp(None), "hogs": args.hogs,
            "exit_code": proc.returncode, **counts(summary), "wall_s": round(wall, 1)}
    common.append(args.out, line)
    print(json.dumps({k: v for k, v in line.items() if k != "machine"}))
    if proc.returncode != 0:
        failed = [x for x in proc.stdout.splitlines() if x.startswith(("FAILED", "ERROR"))]
        raise SystemExit("\n".join(["error: the tests failed beside the spinning processes",
                                    *failed]))


if __name__ == "__main__":
    main()
