"""Benchmark the event simulator: rendering, event generation and a full dataset run.

Usage:
    python benchmarks/bench_simulate.py                      # oakChair, 999 views, 346 x 260
    python benchmarks/bench_simulate.py --quick              # 120 views at 173 x 130
    python benchmarks/bench_simulate.py --mesh builtin:device --views 300

Reports (1) render throughput in frames/s for supersample 1 and 2 (median over batches after
a warm-up batch), (2) event-simulation throughput on those frames, and (3) the wall time of a
full ``simulate_dataset`` run of the train split with its render / events / write split.
Timings on a shared machine are noisy: compare ratios within one run.
"""

from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

import common
import numpy as np
from run_suite import DEFAULT_ASSETS as ASSETS  # the scripts run from benchmarks/

DEFAULT_MESH = str(ASSETS / "oakChair" / "oakChair.obj")


def _render_rate(renderer, c2w: np.ndarray, batch: int,
                 n_batches: int) -> tuple[float, float, list]:
    """(frames/s wall, CPU ms per frame summed over threads, frames); medians over batches."""
    renderer.render(c2w[:batch])  # warm-up (page faults, BVH caches)
    times, cpus, frames = [], [], []
    for b in range(n_batches):
        sl = slice(b * batch, (b + 1) * batch)
        t0, c0 = time.perf_counter(), time.process_time()
        f, _ = renderer.render(c2w[sl])
        times.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
        frames.append(f)
    return batch / statistics.median(times), 1e3 * statistics.median(cpus) / batch, frames


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", default=DEFAULT_MESH, help="mesh path or builtin:<name>")
    ap.add_argument("--views", type=int, default=999)
    ap.add_argument("--width", type=int, default=346)
    ap.add_argument("--height", type=int, default=260)
    ap.add_argument("--supersample", type=int, default=2)
    ap.add_argument("--threads", type=int, default=0, help="Open3D threads (0 = all)")
    ap.add_argument("--batch", type=int, default=8, help="views per cast_rays call")
    ap.add_argument("--rate-batches", type=int, default=5, help="timed batches for rates")
    ap.add_argument("--skip-full", action="store_true", help="only the throughput parts")
    ap.add_argument("--quick", action="store_true", help="120 views at 173 x 130")
    common.add_arguments(ap, "simulate")
    args = ap.parse_args(argv)
    common.check_tree(args)
    if args.quick:
        args.views, args.width, args.height = 120, 173, 130

    from hybridneus.simulate import (
        EventModel,
        EventSimulator,
        PinholeCamera,
        Renderer,
        SimulationConfig,
        look_at_origin,
        normalization_for,
        resolve_mesh,
        seiffert_spiral,
        simulate_dataset,
    )

    cfg = SimulationConfig(n_views=args.views, width=args.width, height=args.height,
                           supersample=args.supersample, val_views=0, test_views=0,
                           n_threads=args.threads, batch_views=args.batch)
    mesh, name = resolve_mesh(args.mesh)
    norm = normalization_for(mesh, cfg.object_radius)
    world = mesh.transformed(norm.scale, np.asarray(norm.translation))
    cam = PinholeCamera.from_fov(args.width, args.height, cfg.fov_y_deg)
    traj = seiffert_spiral(args.views, cfg.revolutions)
    # Views from the middle of the spiral: the object is seen from the side, as in most views.
    c2w = look_at_origin(traj.directions, traj.azimuth, cfg.camera_radius)
    c2w = c2w[args.views // 3:]
    results: dict = {"mesh": args.mesh, "n_faces": mesh.n_faces, "views": args.views,
                     "width": args.width, "height": args.height, "threads": args.threads}

    for ss in sorted({1, args.supersample}):
        r = Renderer(world, cam, ss, n_threads=args.threads)
        rate, cpu_ms, frames = _render_rate(r, c2w, args.batch, args.rate_batches)
        results[f"render_fps_ss{ss}"] = rate
        results[f"render_cpu_ms_per_frame_ss{ss}"] = cpu_ms
        print(f"render supersample {ss}: {rate:.1f} frames/s "
              f"({ss * ss * args.width * args.height * rate / 1e6:.1f} M rays/s), "
              f"{cpu_ms:.1f} ms CPU per frame")
    frames = np.concatenate(frames)
    t0, c0 = time.perf_counter(), time.process_time()
    sim = EventSimulator(frames[0], EventModel(threshold=cfg.events.threshold,
                                               eps=cfg.events.eps))
    n_events = sum(len(sim.step(f)) for f in frames[1:])
    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
    results["event_cpu_ms_per_interval"] = 1e3 * cpu / (len(frames) - 1)
    results["events_per_interval"] = n_events / (len(frames) - 1)
    results["event_intervals_per_s"] = (len(frames) - 1) / dt
    results["events_per_s"] = n_events / dt
    print(f"events: {n_events / (len(frames) - 1):,.0f} per interval, "
          f"{(len(frames) - 1) / dt:.1f} intervals/s, {n_events / dt / 1e6:.2f} M events/s, "
          f"{1e3 * cpu / (len(frames) - 1):.1f} ms CPU per interval")

    if not args.skip_full:
        tmp = Path(tempfile.mkdtemp(prefix="bench_simulate_"))
        try:
            t0, c0 = time.perf_counter(), time.process_time()
            info = simulate_dataset(args.mesh, tmp / name, cfg)
            wall, cpu = time.perf_counter() - t0, time.process_time() - c0
            tr = info["splits"]["train"]
            size = (tmp / name / "train" / "events" / "events.npz").stat().st_size
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        results.update(full_wall_s=wall, full_cpu_s=cpu, full_render_s=tr["render_s"],
                       full_events_s=tr["events_s"], full_write_s=tr["write_s"],
                       full_n_events=tr["n_events"], events_npz_mb=size / 2**20)
        print(f"full train split ({args.views} views): {wall:.1f} s wall ({cpu:.1f} s CPU, "
              f"all threads) = render "
              f"{tr['render_s']:.1f} s + events {tr['events_s']:.1f} s + write "
              f"{tr['write_s']:.1f} s (+ setup); {tr['n_events']:,} events, "
              f"events.npz {size / 2**20:.0f} MiB")
    common.append(args.out, {"bench": "simulate", **results, **common.stamp(args.threads)})
    return 0


if __name__ == "__main__":
    sys.exit(main())
