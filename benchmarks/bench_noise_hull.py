"""The event hull under sensor noise, with and without the silhouettes' noise filter.

Sensor noise is added to a clean simulated dataset's training events, following the
simulator's model (:class:`hybridneus.simulate.NoiseConfig`): background activity (Poisson,
``rate`` events per pixel per frame interval, uniform in time, random polarity) and hot
pixels (a share ``hot`` of the pixels, each with one polarity, ``hot_rate`` events per frame
interval). Threshold mismatch is left out: it changes how the object fires, not where
anything fires away from it. For every dataset and noise level, with the filter
(:func:`hybridneus.data.hull.without_noise`) and without it:

- the views kept, and how much of each clean view's silhouette the noisy one covers (mean
  and 5th percentile) and its area against the clean one's (mean);
- the share of the crop box that the free space (:func:`event_free_space`, the ``hull``
  term's) calls empty, and the share of 100k points on the ground-truth surface it calls
  empty (true surface that the term would push out).

    python benchmarks/bench_noise_hull.py DATASET [DATASET ...] [--rates 0 0.002 0.005 0.02]

Writes one JSON line per dataset, level and variant to ``benchmarks/results/noise_hull.jsonl``.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import json
import subprocess
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def with_noise(split, rate: float, hot: float, hot_rate: float, seed: int = 0,
               flags: bool = False):
    """``split`` with background activity and hot pixels added to its events (and, with
    ``flags``, a bool array over the new stream that marks the added events)."""
    from hybridneus.data.events import EventStream

    ev, rng = split.events, np.random.default_rng(seed)
    w, n_pix = split.width, split.width * split.height
    frames, t_max = split.n_views - 1, float(ev.t.max())
    n = rng.poisson(rate * n_pix * frames)
    pix, t = rng.integers(0, n_pix, n), rng.random(n) * t_max
    p = rng.choice(np.array([-1, 1], np.int8), n)
    hot_pix = rng.choice(n_pix, int(round(hot * n_pix)), replace=False)
    counts = rng.poisson(hot_rate * frames, hot_pix.size)
    hot_p = rng.choice(np.array([-1, 1], np.int8), hot_pix.size)
    pix = np.r_[pix, np.repeat(hot_pix, counts)]
    t = np.r_[t, rng.random(int(counts.sum())) * t_max]
    p = np.r_[p, np.repeat(hot_p, counts)]
    x = np.r_[ev.x, (pix % w).astype(ev.x.dtype)]
    y = np.r_[ev.y, (pix // w).astype(ev.y.dtype)]
    t, p = np.r_[ev.t, t], np.r_[ev.p, p]
    order = np.argsort(t, kind="stable")
    noisy = dataclasses.replace(split, events=EventStream(x[order], y[order], t[order], p[order],
                                                          t_end=ev.t_max))
    if not flags:
        return noisy
    return noisy, (np.arange(t.size) >= len(ev))[order]


def add_noise_args(ap: argparse.ArgumentParser) -> None:
    """The datasets and the noise levels to add to them, as both noise benchmarks take them."""
    ap.add_argument("datasets", nargs="+", type=Path, help="clean simulated datasets")
    ap.add_argument("--rates", nargs="+", type=float, default=[0.0, 0.002, 0.005, 0.02],
                    help="background events per pixel per frame interval")
    ap.add_argument("--hot", type=float, default=1e-4, help="share of hot pixels (0 at rate 0)")
    ap.add_argument("--hot-rate", type=float, default=0.5, help="events per hot pixel per frame")


def git_commit() -> str:
    """The checkout's short commit, for the result lines."""
    return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                          capture_output=True, text=True).stdout.strip()


def measure(split, clean: dict, lo, hi, surface, args, denoise: bool) -> dict:
    from hybridneus.data.hull import FreeSpace, event_hull, event_silhouettes, hull_view_step

    step = hull_view_step(split)
    views, masks = event_silhouettes(split, step=step, denoise=denoise)
    cover, area = [], []
    for view, mask in zip(views, masks, strict=True):
        if view in clean:
            c = clean[view]
            cover.append((mask & c).sum() / c.sum())
            area.append(mask.sum() / c.sum())
    t = time.perf_counter()
    hull = event_hull(split, lo, hi, args.hull_res, step=step, denoise=denoise)
    out = {"views": len(views), "views_clean": len(clean),
           "cover_mean": float(np.mean(cover)) if cover else None,
           "cover_p5": float(np.percentile(cover, 5)) if cover else None,
           "area_mean": float(np.mean(area)) if area else None,
           "hull_s": round(time.perf_counter() - t, 1)}
    if hull.n_views and hull.occupied.any():
        free = FreeSpace(hull)
        out["box_free"] = free.free_fraction
        out["surface_free"] = float(free.free(surface).float().mean())
    else:
        out["box_free"] = out["surface_free"] = 0.0
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_noise_args(ap)
    ap.add_argument("--hull-res", type=int, default=96, help="hull grid points, longest side")
    ap.add_argument("--out", type=Path,
                    default=REPO / "benchmarks" / "results" / "noise_hull.jsonl")
    args = ap.parse_args()

    import torch
    import trimesh

    from hybridneus.data import load_dataset
    from hybridneus.data.hull import event_silhouettes, hull_view_step

    commit = git_commit()
    args.out.parent.mkdir(parents=True, exist_ok=True)
    for folder in args.datasets:
        ds = load_dataset(folder)
        split, pr = ds["train"], ds.preset
        r = pr.crop_r
        lo, hi = np.array([-r, pr.crop_y_min, -r]), np.array([r, pr.crop_y_max, r])
        gt = trimesh.load(folder / "gt_mesh.ply", force="mesh")
        points, _ = trimesh.sample.sample_surface(gt, 100_000, seed=0)
        surface = torch.tensor(points, dtype=torch.float32)
        clean = dict(zip(*event_silhouettes(split, step=hull_view_step(split), denoise=False),
                         strict=True))
        for rate in args.rates:
            hot = args.hot if rate > 0 else 0.0
            noisy = with_noise(split, rate, hot, args.hot_rate) if rate > 0 else split
            for denoise in (True, False):
                row = {"dataset": folder.name, "rate": rate, "hot": hot,
                       "hot_rate": args.hot_rate, "filter": denoise,
                       **measure(noisy, clean, lo, hi, surface, args, denoise),
                       "commit": commit, "date": dt.date.today().isoformat()}
                print(f"{folder.name} rate {rate:g} {'filtered' if denoise else 'raw':8s} "
                      f"views {row['views']}/{row['views_clean']} "
                      f"cover {row['cover_mean'] or 0:.4f} (p5 {row['cover_p5'] or 0:.4f}) "
                      f"area x{row['area_mean'] or 0:.2f} box free {row['box_free']:.3f} "
                      f"surface free {row['surface_free']:.5f}", flush=True)
                with args.out.open("a") as fh:
                    fh.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
