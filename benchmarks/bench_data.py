"""Benchmark of hybridneus.data: dataset load time and peak memory, window queries, batches/s.

Generates a synthetic split in a temporary folder (999 views of 346x260, N events spread over
the views, real-scene style float timestamps), then measures in fresh subprocesses (so peak
RSS belongs to one load):

- ``load``: ``load_dataset`` wall time, peak RSS and tracemalloc peak, and the size of the
  loaded arrays;
- ``window``: ``event_frame`` for windows of 1..100 views, plain ``bincount`` of the slice
  against the checkpointed :class:`EventCounter` (plus its one-off build time);
- ``sample``: ``EventWindowSampler.sample`` batches per second (per-iteration windows of up
  to 100 views, the real-scene preset).

Usage::

    python benchmarks/bench_data.py                 # 3M and 30M events
    python benchmarks/bench_data.py --events 3e6    # one size
    python benchmarks/bench_data.py --quick         # 300k events, few repeats
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import common
import numpy as np

W, H, N_VIEWS = 346, 260, 999


def make_dataset(root: Path, n_events: int, xy_dtype: str, seed: int = 0) -> Path:
    """Write ``root/real/bench/train`` with 999 views and ``n_events`` events."""
    split = root / "real" / "bench" / "train"
    rng = np.random.default_rng(seed)
    for sub in ("pose", "intrinsics", "events"):
        (split / sub).mkdir(parents=True, exist_ok=True)
    ang = np.linspace(0, 2 * np.pi, N_VIEWS, endpoint=False)
    for i, a in enumerate(ang):
        c, s = np.cos(a), np.sin(a)
        # Camera on a circle of radius 0.8 looking at the origin (OpenCV axes).
        z = -np.array([s, 0.0, c])
        x = np.array([c, 0.0, -s])
        y = np.cross(z, x)
        pose = np.eye(4)
        pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = x, y, z, -0.8 * z
        np.savetxt(split / "pose" / f"r_{i:05d}.txt", pose.reshape(1, 16))
        K = np.eye(4)
        K[:3, :3] = [[300.0, 0, W / 2], [0, 300.0, H / 2], [0, 0, 1]]
        np.savetxt(split / "intrinsics" / f"r_{i:05d}.txt", np.vstack([K, [0.1, 0.01, 0, 0]]))
    t = np.sort(rng.random(n_events)) * 12.3  # float seconds, real-scene style
    ev = {
        "x": rng.integers(0, W, n_events).astype(xy_dtype),
        "y": rng.integers(0, H, n_events).astype(xy_dtype),
        "t": t,
        "p": rng.integers(0, 2, n_events).astype(xy_dtype) * 2 - 1,
    }
    np.savez(split / "events" / "events.npz", **ev)
    return split.parent


def _median_time(fn, repeats: int) -> float:
    fn()  # warm-up
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def _vm_hwm_mb() -> float:
    """Peak resident memory of this process (VmHWM; unlike ru_maxrss it resets at exec)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def child_load(root: str) -> dict:
    import tracemalloc

    from hybridneus.data import load_dataset

    before = _vm_hwm_mb()
    tracemalloc.start()
    t0 = time.perf_counter()
    ds = load_dataset(root)
    wall = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    ev = ds.splits["train"].events
    final = sum(a.nbytes for a in (ev.x, ev.y, ev.t, ev.p))
    return {
        "load_s": wall,
        "tracemalloc_peak_mb": peak / 2**20,
        "peak_rss_mb": _vm_hwm_mb(),
        "peak_rss_before_load_mb": before,
        "arrays_mb": final / 2**20,
        "n_events": len(ev),
    }


def child_window(root: str, repeats: int) -> dict:
    from hybridneus.data import EventCounter, load_dataset
    from hybridneus.data.windows import event_counter, event_frame

    ds = load_dataset(root)
    sp = ds.splits["train"]
    off = ds.preset.polarity_offset
    code = sp.events.pixel_code(W)
    t = sp.events.t
    dt = sp.t_max / (sp.n_views - 1)
    out = {}
    t0 = time.perf_counter()
    counter = EventCounter(sp.events, W, H)
    counter._cum = counter._build()
    out["checkpoint_build_s"] = time.perf_counter() - t0
    out["checkpoint_mb"] = counter._cum.nbytes / 2**20
    out["stride_events"] = counter.stride
    sp.events.cache[("counter", W, H)] = counter
    rng = np.random.default_rng(1)
    for views in (1, 10, 50, 100):
        ends = rng.integers(views, sp.n_views, size=16)

        def plain(ends=ends, views=views):
            for e in ends:
                i0, i1 = np.searchsorted(t, [(e - views) * dt, e * dt])
                c = np.bincount(code[i0:i1], minlength=2 * W * H).reshape(-1, 2)
                _ = c[:, 1] * (1 + off) + c[:, 0] * (off - 1)

        def indexed(ends=ends, views=views):
            for e in ends:
                event_frame(sp, (e - views) * dt, e * dt, off)

        n_in = int(np.mean([np.diff(np.searchsorted(t, [(e - views) * dt, e * dt]))[0]
                            for e in ends]))
        out[f"{views}_views"] = {
            "events_per_window": n_in,
            "plain_bincount_ms": 1e3 * _median_time(plain, repeats) / len(ends),
            "event_frame_ms": 1e3 * _median_time(indexed, repeats) / len(ends),
        }
    assert event_counter(sp) is counter
    return out


def child_sample(root: str, repeats: int, n_rays: int) -> dict:
    from hybridneus.data import EventWindowSampler, load_dataset

    ds = load_dataset(root)
    sampler = EventWindowSampler(ds.splits["train"], ds.preset, seed=0)
    t0 = time.perf_counter()
    sampler.sample(n_rays)  # builds the checkpoints
    first = time.perf_counter() - t0
    n = 20 * repeats
    t0 = time.perf_counter()
    for _ in range(n):
        sampler.sample(n_rays)
    per = (time.perf_counter() - t0) / n
    return {"first_batch_s": first, "batch_ms": 1e3 * per, "batches_per_s": 1.0 / per,
            "n_rays": n_rays}


def run_child(*args: str) -> dict:
    cmd = [sys.executable, __file__, "--child", *args]
    res = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if res.returncode != 0:
        raise RuntimeError(res.stderr)
    return json.loads(res.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--events", type=float, nargs="+", default=[3e6, 3e7])
    ap.add_argument("--xy-dtype", default="int64", help="dtype of x, y, p in the npz")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rays", type=int, default=1024)
    ap.add_argument("--quick", action="store_true", help="300k events, 2 repeats")
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    common.add_arguments(ap, "data")
    args = ap.parse_args()
    if args.child:
        kind, root = args.child[0], args.child[1]
        if kind == "load":
            res = child_load(root)
        elif kind == "window":
            res = child_window(root, int(args.child[2]))
        else:
            res = child_sample(root, int(args.child[2]), int(args.child[3]))
        print(json.dumps(res))
        return
    common.check_tree(args)
    sizes = [3e5] if args.quick else args.events
    repeats = 2 if args.quick else args.repeats
    for n in sizes:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            root = make_dataset(Path(tmp), int(n), args.xy_dtype)
            npz = root / "train" / "events" / "events.npz"
            print(f"## {int(n):,} events, 999 views, {W}x{H}, x/y/p stored as {args.xy_dtype} "
                  f"(npz {npz.stat().st_size / 2**20:.0f} MB, generated in "
                  f"{time.perf_counter() - t0:.1f} s)")
            found = {"load": run_child("load", str(root)),
                     "window": run_child("window", str(root), str(repeats)),
                     "sample": run_child("sample", str(root), str(repeats), str(args.rays))}
            for name, res in found.items():
                print(f"{name}:", json.dumps(res))
            common.append(args.out, {"bench": "data", "events": int(n), "rays": args.rays,
                                     **found, **common.stamp(None)})


if __name__ == "__main__":
    main()
