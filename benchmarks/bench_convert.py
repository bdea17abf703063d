"""Benchmark of ``hybridneus convert``: events per second and peak memory on long recordings.

Writes a synthetic recording of N events (a DSEC-style HDF5 file with Blosc compression, or
a text file), a turntable description and a calibration into a temporary folder, then runs
``hybridneus convert`` on it in a fresh process and records its wall time, events per second
and peak RSS (the child's ``ru_maxrss``). Convert streams the events twice, so peak memory
should not grow with N; the result line states the size of the events as loaded by a fit
(13 bytes per event) beside it.

Usage::

    python benchmarks/bench_convert.py                    # 1e8 events, HDF5
    python benchmarks/bench_convert.py --events 1e7 --format txt
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import common
import numpy as np

W, H = 346, 260
SECONDS = 600.0  # the recording's length: a ten-minute capture
CHUNK = 1 << 23


def write_recording(folder: Path, n: int, fmt: str, seed: int = 0) -> Path:
    """``n`` events spread over ten minutes, written chunk by chunk (never all in memory)."""
    rng = np.random.default_rng(seed)
    step = SECONDS / n
    if fmt == "h5":
        import h5py
        import hdf5plugin

        path = folder / "events.h5"
        with h5py.File(path, "w") as f:
            g = f.create_group("events")
            cols = {k: g.create_dataset(k, shape=(n,), dtype=d, chunks=(1 << 18,),
                                        **hdf5plugin.Blosc())
                    for k, d in (("t", np.int64), ("x", np.uint16), ("y", np.uint16),
                                 ("p", np.uint8))}
            for s in range(0, n, CHUNK):
                e = min(s + CHUNK, n)
                cols["t"][s:e] = np.round((np.arange(s, e) * step) * 1e6).astype(np.int64)
                cols["x"][s:e] = rng.integers(0, W, e - s)
                cols["y"][s:e] = rng.integers(0, H, e - s)
                cols["p"][s:e] = rng.integers(0, 2, e - s)
            f.create_dataset("t_offset", data=np.int64(0))
        return path
    path = folder / "events.txt"
    with open(path, "w") as f:
        for s in range(0, n, CHUNK):
            e = min(s + CHUNK, n)
            rows = np.column_stack([np.arange(s, e) * step, rng.integers(0, W, e - s),
                                    rng.integers(0, H, e - s), rng.integers(0, 2, e - s)])
            np.savetxt(f, rows, fmt=["%.6f", "%d", "%d", "%d"])
    return path


def write_setup(folder: Path) -> tuple[Path, Path]:
    cam = np.eye(4)
    cam[:3, 3] = [0.0, 0.0, -0.5]
    table = folder / "turntable.json"
    table.write_text(json.dumps({"axis": [0, -1, 0], "speed_deg_s": 360.0 / 60.0,
                                 "camera": cam.tolist()}))
    calib = folder / "calib.json"
    calib.write_text(json.dumps({"fx": 300.0, "fy": 300.0, "cx": W / 2 - 0.5,
                                 "cy": H / 2 - 0.5, "width": W, "height": H}))
    return table, calib


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--events", type=float, default=1e8)
    ap.add_argument("--format", choices=("h5", "txt"), default="h5")
    ap.add_argument("--views", type=int, default=1000)
    ap.add_argument("--tmp", type=Path, default=None, help="folder for the recording")
    common.add_arguments(ap, "convert")
    args = ap.parse_args()
    common.check_tree(args)
    n = int(args.events)
    with tempfile.TemporaryDirectory(dir=args.tmp) as tmp:
        folder = Path(tmp)
        made = time.perf_counter()
        events = write_recording(folder, n, args.format)
        print(f"wrote {n:,} events ({events.stat().st_size / 1e9:.2f} GB) in "
              f"{time.perf_counter() - made:.0f} s", flush=True)
        table, calib = write_setup(folder)
        cmd = [sys.executable, "-m", "hybridneus.cli.app", "convert", str(events),
               str(folder / "out"), "--turntable", str(table), "--calib", str(calib),
               "--views", str(args.views), "-q"]
        start = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        seconds = time.perf_counter() - start
        if proc.returncode != 0:
            raise SystemExit(f"convert failed: {proc.stderr.strip()}")
        peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
        written = (folder / "out" / "train" / "events" / "events.npz").stat().st_size
    record = common.stamp(threads=None) | {
        "benchmark": "convert", "format": args.format, "events": n, "views": args.views,
        "seconds": round(seconds, 2), "events_per_s": round(n / seconds),
        "peak_rss_mb": round(peak_mb, 1), "loaded_size_mb": round(13 * n / 2**20, 1),
        "npz_mb": round(written / 2**20, 1),
    }
    common.append(args.out, record)
    print(f"{args.format}: {n:,} events in {seconds:.1f} s ({n / seconds / 1e6:.2f} M/s), "
          f"peak RSS {peak_mb:.0f} MB (the events loaded: {13 * n / 2**20:.0f} MB)")


if __name__ == "__main__":
    main()
