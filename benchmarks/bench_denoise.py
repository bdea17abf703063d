"""The training events' noise filter (:mod:`hybridneus.data.denoise`) against known noise.

Background activity and hot pixels are added to clean simulated datasets as in
``bench_noise_hull.py`` (so every added event is known), and the filter runs on the result.
For every dataset and noise level:

- the company bar it chose, and the noise share it estimated against the true one;
- the share of the clean events kept and of the added events kept;
- over 40 training windows (the preset's lengths, drawn as training draws them), the firing
  pixels per window and the share of them that are noise (away from the clean window's
  firing pixels grown by 3), before and after the filter;
- the filter's wall time.

    python benchmarks/bench_denoise.py DATASET [DATASET ...] [--rates 0 0.002 0.005 0.02]

Writes one JSON line per dataset and level to ``benchmarks/results/denoise.jsonl``.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from bench_noise_hull import add_noise_args, git_commit, with_noise  # noqa: E402


def window_noise(clean, noisy, windows, offset: float) -> tuple[float, float]:
    """Mean firing pixels per window of ``noisy``, and the share of them away from
    ``clean``'s firing pixels (grown by 3 pixels)."""
    import cv2

    from hybridneus.data.windows import event_frame

    grow = np.ones((7, 7), np.uint8)
    fired = away = 0
    for t0, t1 in windows:
        near = cv2.dilate((event_frame(clean, t0, t1, offset) != 0).astype(np.uint8), grow) > 0
        f = event_frame(noisy, t0, t1, offset) != 0
        fired += int(f.sum())
        away += int((f & ~near).sum())
    return fired / len(windows), away / max(fired, 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_noise_args(ap)
    ap.add_argument("--slab", type=float, default=2.0, help="data.denoise_slab, in views")
    ap.add_argument("--windows", type=int, default=40)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "denoise.jsonl")
    args = ap.parse_args()

    from hybridneus.data import EventWindowSampler, load_dataset
    from hybridneus.data.denoise import kept_events, signal_events

    commit = git_commit()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    for folder in args.datasets:
        ds = load_dataset(folder)
        split, preset = ds["train"], ds.preset
        sampler = EventWindowSampler(split, preset, seed=0)
        windows = []
        for _ in range(args.windows):
            _, t0, t1 = sampler.draw_window()
            windows.append((t0, t1))
        for rate in args.rates:
            hot = args.hot if rate > 0 else 0.0
            if rate > 0:
                noisy, added = with_noise(split, rate, hot, args.hot_rate, flags=True)
            else:
                noisy, added = split, np.zeros(len(split.events), bool)
            ev = noisy.events
            start = time.perf_counter()
            slab = args.slab * noisy.t_max / (noisy.n_views - 1)
            keep, found = signal_events(ev, noisy.width, noisy.height, slab)
            seconds = time.perf_counter() - start
            kept = dataclasses.replace(noisy, events=kept_events(ev, keep))
            raw_px, raw_share = window_noise(split, noisy, windows, preset.polarity_offset)
            px, share = window_noise(split, kept, windows, preset.polarity_offset)
            row = {"dataset": folder.name, "rate": rate, "hot": hot, "hot_rate": args.hot_rate,
                   "slab": args.slab, "events": len(ev), "bar": found.bar,
                   "noise_share": float(added.mean()), "noise_share_est": found.noise_share,
                   "clean_kept": float(keep[~added].mean()) if (~added).any() else None,
                   "noise_kept": float(keep[added].mean()) if added.any() else None,
                   "window_px_raw": raw_px, "window_noise_raw": raw_share,
                   "window_px": px, "window_noise": share, "seconds": round(seconds, 2),
                   "commit": commit, "date": dt.date.today().isoformat()}
            nk = row["noise_kept"]
            print(f"{folder.name} rate {rate:g}: bar {found.bar}, noise {row['noise_share']:.3f}"
                  f" (est {found.noise_share:.3f}), clean kept {row['clean_kept']:.4f}, noise "
                  f"kept {'-' if nk is None else f'{nk:.4f}'}; per window {raw_px:.0f} px, "
                  f"{raw_share:.1%} noise -> {px:.0f} px, {share:.1%} noise; {seconds:.2f} s",
                  flush=True)
            with args.out.open("a") as fh:
                fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
