"""The polarity offset estimated from the events (:mod:`hybridneus.data.balance`) against the
offset the datasets were simulated with.

For every dataset (its ``scene.json`` records the simulator's ``events.polarity_offset`` and
noise): the estimate a fit takes (per-pixel median after the noise filter), the same median
without the filter, and the event-weighted mean ``-mean(p)``; the error of each, and the time
the estimate takes.

    python benchmarks/bench_balance.py DATASET [DATASET ...]

Writes one JSON line per dataset to ``benchmarks/results/balance.jsonl``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from bench_noise_hull import git_commit  # noqa: E402


def _f(value: float | None) -> str:
    return "none" if value is None else f"{value:+.3f}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", type=Path, nargs="+")
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "balance.jsonl")
    args = ap.parse_args()

    from hybridneus.data import load_dataset
    from hybridneus.data.balance import balance_offset, polarity_balance

    commit = git_commit()
    rows = []
    for path in args.datasets:
        scene = json.loads((path / "scene.json").read_text())
        truth = float(scene["events"]["polarity_offset"])
        split = load_dataset(path, splits="train")["train"]
        start = time.perf_counter()
        found = polarity_balance(split)
        seconds = time.perf_counter() - start
        raw = balance_offset(split.events, split.width, split.height)
        mean = float(-split.events.p.mean())
        row = {
            "dataset": str(path), "commit": commit,
            "date": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
            "events": len(split.events), "noise": scene.get("noise"), "truth": truth,
            "estimate": found.offset, "suggested": found.suggested(), "pixels": found.pixels,
            "dense_noise": found.dense_noise, "unfiltered_median": raw.offset,
            "event_mean": mean, "seconds": round(seconds, 2),
        }
        rows.append(row)
        print(f"{path.name:36s} truth {truth:+.3f}  estimate {_f(found.offset)} "
              f"(takes {_f(found.suggested())}; {found.pixels} px, {seconds:.1f} s)  "
              f"unfiltered {_f(raw.offset)}  event mean {mean:+.3f}"
              + ("  [noise too dense to filter]" if found.dense_noise else ""))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with args.out.open("a") as fh:
        for row in rows:
            fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
