"""Benchmark of ``hybridneus convert``: events per second and peak memory on long recordings.

Writes a synthetic recording of N events in one format (a DSEC-style HDF5 file with Blosc
compression, AEDAT4, Prophesee EVT2/EVT3 RAW or DAT written by faery, a ROS 1 bag of
``dvs_msgs/EventArray`` written by rosbags, text, or npz), a turntable description and a
calibration into a temporary folder, then runs
``hybridneus convert`` on it in a fresh process and records its wall time, events per second
and peak RSS (the convert process's own high-water mark, ``VmHWM``). Convert streams the
events twice, so peak memory should not grow with N; the result line states the size of the
events as loaded by a fit (13 bytes per event) beside it.

Usage::

    python benchmarks/bench_convert.py                    # 1e8 events, HDF5
    python benchmarks/bench_convert.py --events 1e7 --format txt
    for f in h5 aedat4 evt3 evt2 dat bag txt npz; do
        python benchmarks/bench_convert.py --format $f; done

npz is the one format read whole (numpy loads an archive member at once), so its peak
memory grows with N.
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

W, H = 346, 260
SECONDS = 600.0  # the recording's length: a ten-minute capture
CHUNK = 1 << 23


FORMATS = ("h5", "aedat4", "evt3", "evt2", "dat", "bag", "txt", "npz")


def _chunks(n: int, rng: np.random.Generator):
    """(t in microseconds, x, y, on) of consecutive events, CHUNK at a time."""
    step = SECONDS / n
    for s in range(0, n, CHUNK):
        e = min(s + CHUNK, n)
        yield (np.round(np.arange(s, e) * step * 1e6).astype(np.int64),
               rng.integers(0, W, e - s), rng.integers(0, H, e - s),
               rng.integers(0, 2, e - s).astype(bool))


def _write_faery(folder: Path, n: int, fmt: str, rng: np.random.Generator) -> Path:
    """faery writes from one array: the writer (not convert) holds 13 bytes per event."""
    import faery

    arr = np.zeros(n, dtype=faery.EVENTS_DTYPE)
    s = 0
    for t, x, y, on in _chunks(n, rng):
        e = s + len(t)
        arr["t"][s:e], arr["x"][s:e], arr["y"][s:e], arr["on"][s:e] = t, x, y, on
        s = e
    path = folder / f"events.{ {'evt2': 'raw', 'evt3': 'raw'}.get(fmt, fmt)}"
    faery.events_stream_from_array(arr, dimensions=(W, H)).to_file(
        path, version=fmt if fmt.startswith("evt") else None, zero_t0=False)
    return path


def _write_bag(folder: Path, n: int, rng: np.random.Generator, per_message: int = 20000
               ) -> Path:
    """A ROS 1 bag; each message is packed with numpy in the ROS 1 wire format (header,
    height, width, then 13 bytes per event), which rosbags' serialiser would take hours
    to build one Python object per event for."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    store.register({
        **get_types_from_msg("uint16 x\nuint16 y\ntime ts\nbool polarity\n",
                             "dvs_msgs/msg/Event"),
        **get_types_from_msg("std_msgs/Header header\nuint32 height\nuint32 width\n"
                             "dvs_msgs/Event[] events\n", "dvs_msgs/msg/EventArray")})
    packed = np.dtype({"names": ["x", "y", "sec", "nsec", "pol"],
                       "formats": ["<u2", "<u2", "<u4", "<u4", "u1"],
                       "offsets": [0, 2, 4, 8, 12], "itemsize": 13})
    path = folder / "events.bag"
    seq = 0
    with Writer(path) as writer:
        conn = writer.add_connection("/dvs/events", "dvs_msgs/msg/EventArray", typestore=store)
        for t, x, y, on in _chunks(n, rng):
            for s in range(0, len(t), per_message):
                sl = slice(s, s + per_message)
                rec = np.zeros(len(t[sl]), packed)
                rec["x"], rec["y"], rec["pol"] = x[sl], y[sl], on[sl]
                rec["sec"], rec["nsec"] = t[sl] // 10**6, (t[sl] % 10**6) * 1000
                head = np.array([seq, rec["sec"][0], rec["nsec"][0], 3], "<u4").tobytes() \
                    + b"dvs" + np.array([H, W, len(rec)], "<u4").tobytes()
                writer.write(conn, int(t[sl][0]) * 1000, head + rec.tobytes())
                seq += 1
    return path


def write_recording(folder: Path, n: int, fmt: str, seed: int = 0) -> Path:
    """``n`` events spread over ten minutes, written chunk by chunk (never all in memory)
    except where the format's writer takes one array (faery's, numpy's npz)."""
    rng = np.random.default_rng(seed)
    step = SECONDS / n
    if fmt in ("aedat4", "evt3", "evt2", "dat"):
        return _write_faery(folder, n, fmt, rng)
    if fmt == "bag":
        return _write_bag(folder, n, rng)
    if fmt == "npz":
        cols = list(zip(*_chunks(n, rng), strict=True))
        path = folder / "events.npz"
        np.savez(path, t=np.concatenate(cols[0]), x=np.concatenate(cols[1]).astype(np.uint16),
                 y=np.concatenate(cols[2]).astype(np.uint16),
                 p=np.concatenate(cols[3]).astype(np.int8) * 2 - 1)
        return path
    if fmt == "h5":
        import h5py
        import hdf5plugin

        path = folder / "events.h5"
        with h5py.File(path, "w") as f:
            g = f.create_group("events")
            cols = {k: g.create_dataset(k, shape=(n,), dtype=d, chunks=(min(n, 1 << 18),),
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


#: The convert process reports its own peak RSS: VmHWM of its own memory map. Not
#: RUSAGE_CHILDREN, nor even the child's RUSAGE_SELF: Linux keeps ru_maxrss across exec, so
#: both count the pages the forked child shared with this process, which holds the
#: recording it just wrote.
_CHILD = """
import resource, sys
from hybridneus.cli.app import main
sys.argv = ["hybridneus", *sys.argv[1:]]
try:
    main()
finally:
    try:
        status = open("/proc/self/status").read().split("VmHWM:")[1].split()[0]
    except (OSError, IndexError):
        status = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print("peak_rss_kb", status, file=sys.stderr)
"""


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
    ap.add_argument("--format", choices=FORMATS, default="h5")
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
        cmd = [sys.executable, "-c", _CHILD, "convert", str(events),
               str(folder / "out"), "--turntable", str(table), "--calib", str(calib),
               "--views", str(args.views), "-q"]
        start = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True)
        seconds = time.perf_counter() - start
        if proc.returncode != 0:
            raise SystemExit(f"convert failed: {proc.stderr.strip()}")
        peak_mb = int(proc.stderr.strip().splitlines()[-1].split()[-1]) / 1024
        written = (folder / "out" / "train" / "events" / "events.npz").stat().st_size
    record = common.stamp(threads=None) | {
        "bench": "convert", "format": args.format, "events": n, "views": args.views,
        "seconds": round(seconds, 2), "events_per_s": round(n / seconds),
        "peak_rss_mb": round(peak_mb, 1), "loaded_size_mb": round(13 * n / 2**20, 1),
        "npz_mb": round(written / 2**20, 1),
    }
    common.append(args.out, record)
    print(f"{args.format}: {n:,} events in {seconds:.1f} s ({n / seconds / 1e6:.2f} M/s), "
          f"peak RSS {peak_mb:.0f} MB (the events loaded: {13 * n / 2**20:.0f} MB)")


if __name__ == "__main__":
    main()
