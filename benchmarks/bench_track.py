"""Smoothing a jittery camera track: the pose errors left by each window, against the truth.

No fit: the simulator's camera paths (999 views by default), their written poses made with
``CaptureErrors`` (per-view rotation and centre errors, a clock offset) for several noise
seeds, and the track smoothed as ``refine.pose_smoothing`` does it
(:func:`hybridneus.data.track.smooth_track`) with fixed windows and with the window chosen
from the track (``-1``, :func:`hybridneus.data.track.choose_window`). Errors are measured
against the true poses: rotation in degrees, camera centre in % of the camera distance,
mean over the views and the largest, each averaged over the noise seeds.

One line per path, error level, window and order to ``benchmarks/results/track.jsonl``.
What it answers: which window leaves the smallest error, and how near the chosen one comes
to it on paths and error levels it was not chosen for.

    python benchmarks/bench_track.py
    python benchmarks/bench_track.py --paths seiffert --levels 0.5:0.01 --windows 0 41 -1
"""

from __future__ import annotations

import argparse
import json
import sys

import common
import numpy as np
from bench_poses import pose_error_stats


def path_poses(kind: str, n_views: int) -> np.ndarray:
    """(n, 4, 4) camera-to-world poses of the simulator's training path ``kind``."""
    from hybridneus.simulate.dataset import CAMERA_RADIUS
    from hybridneus.simulate.trajectory import circle, even_spiral, look_at_origin, seiffert_spiral

    make = {"seiffert": seiffert_spiral, "even": even_spiral, "circle": circle}[kind]
    traj = make(n_views)
    return look_at_origin(traj.directions, traj.azimuth, CAMERA_RADIUS)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    ap.add_argument("--paths", nargs="+", default=["seiffert", "even", "circle"])
    ap.add_argument("--views", type=int, default=999)
    ap.add_argument("--levels", nargs="+", default=["0.2:0.004", "0.5:0.01", "1:0.02"],
                    help="error levels, RMS degrees : RMS share of the camera distance")
    ap.add_argument("--clock", type=float, default=0.01, help="clock offset, views")
    ap.add_argument("--windows", type=int, nargs="+", default=[0, 21, 41, 61, 81, -1],
                    help="smoothing windows (0: the given track; -1: chosen from the track)")
    ap.add_argument("--orders", type=int, nargs="+", default=[5])
    ap.add_argument("--noise-seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    common.add_arguments(ap, "track")
    args = ap.parse_args()
    common.check_tree(args)

    from hybridneus.data.track import choose_window, smooth_track
    from hybridneus.simulate.capture import CaptureErrors, written_poses

    for kind in args.paths:
        truth = path_poses(kind, args.views)
        for level in args.levels:
            rotation, translation = (float(v) for v in level.split(":"))
            given = [written_poses(truth, CaptureErrors(rotation, translation, args.clock, s))
                     for s in args.noise_seeds]
            for order in args.orders:
                for window in args.windows:
                    chosen = [choose_window(g, order) if window < 0 else window for g in given]
                    per_seed = [pose_error_stats(smooth_track(g, w, order), truth)
                                for g, w in zip(given, chosen, strict=True)]
                    mean = {k: round(float(np.mean([e[k] for e in per_seed])), 4)
                            for k in per_seed[0]}
                    line = {"bench": "track", **common.stamp(1), "path": kind,
                            "views": args.views, "rotation_deg": rotation,
                            "translation": translation, "clock_offset_views": args.clock,
                            "noise_seeds": args.noise_seeds, "order": order,
                            "window": window, "chosen": chosen, **mean}
                    common.append(args.out, line)
                    print(json.dumps({k: v for k, v in line.items()
                                      if k not in ("machine", "command")}), file=sys.stderr)


if __name__ == "__main__":
    main()
