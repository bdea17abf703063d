"""The clock offset found from the data (``convert --clock-offset auto``), against the truth.

No fit. Each scene is simulated as the suite simulates it (cached in ``--cache``), then re-timed
as a hand-held capture (:func:`hybridneus.simulate.recording.handheld_times`: the camera's
log-speed is smooth random noise over 0.1 to 3 seconds with the given standard deviation,
0 for a constant speed) lasting ``--durations`` seconds, its events in seconds from a
host-epoch start, and its poses a 200 Hz track on a clock ``offset`` seconds ahead
(``--offsets``, one per seed in turn). The estimate
(:func:`hybridneus.recordings.clock.estimate_clock_offset`, with the scene's focal length)
either answers, with its standard error, or refuses with a reason.

One line per scene, duration, speed variation and seed to
``benchmarks/results/clock.jsonl``: the true offset, the estimate, its error and standard
error (ms), the image shift the standard error leaves (px) and the coherence, or the refusal.
Targets (issue: a real capture): within 2 ms of the truth on hand-held tracks; refused at a
constant speed.

    python benchmarks/bench_clock.py
    python benchmarks/bench_clock.py --scenes bunny --durations 60 --variations 0.5 --seeds 0 1
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import common
import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    ap.add_argument("--scenes", nargs="+",
                    default=["bunny", "toyTrain", "generated:device:161576974"])
    ap.add_argument("--assets", type=Path, default=common.REPO.parent / "shared" / "assets")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench"))
    ap.add_argument("--views", type=int, default=999,
                    help="views simulated along the path (the events between two views are "
                         "timed on a brightness interpolated linearly between them)")
    ap.add_argument("--durations", type=float, nargs="+", default=[30.0, 60.0])
    ap.add_argument("--variations", type=float, nargs="+", default=[0.5, 1.0, 0.0],
                    help="standard deviation of the log-speed (0: constant speed)")
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--offsets", type=float, nargs="+", default=[0.04, 0.35, -1.7],
                    help="true offsets (pose clock - event clock), one per seed in turn")
    common.add_arguments(ap, "clock")
    args = ap.parse_args()
    common.check_tree(args)

    import run_suite

    from hybridneus.data import load_dataset
    from hybridneus.errors import RecordingError
    from hybridneus.recordings import make_track
    from hybridneus.recordings.clock import estimate_clock_offset
    from hybridneus.recordings.stream import EventChunk, EventSource
    from hybridneus.simulate.recording import as_recording, handheld_times

    class Events(EventSource):
        def __init__(self, rec) -> None:
            self.rec, self.path = rec, Path("events")

        def chunks(self):
            r = self.rec
            yield EventChunk(r.t, r.x.astype(np.int32), r.y.astype(np.int32), r.p > 0)

    ns = SimpleNamespace(views=args.views, width=346, height=260, test_views=8, noise=(0.0, 0.0),
                         cache=args.cache, assets=args.assets)
    assets = run_suite.find_assets(args.assets)
    for scene in args.scenes:
        folder = run_suite.dataset_for(scene, assets, ns)
        split = load_dataset(folder, splits="train")["train"]
        focal = float(split.intrinsics[0][0, 0])
        for duration in args.durations:
            for variation in args.variations:
                for k, seed in enumerate(args.seeds):
                    offset = args.offsets[k % len(args.offsets)]
                    rec = as_recording(split.events, split.c2w,
                                       handheld_times(split.n_views, duration, seed, variation),
                                       t0=1_650_000_000.0, clock_offset=offset)
                    track = make_track(rec.pose_t, rec.quat, rec.position, "track")
                    line = {"bench": "clock", **common.stamp(1), "scene": run_suite.scene_name(
                        scene), "views": args.views, "events": int(len(rec.t)),
                            "duration_s": duration,
                            "variation": variation, "seed": seed, "offset_s": offset}
                    t0 = time.perf_counter()
                    try:
                        est = estimate_clock_offset(Events(rec), track, focal)
                    except RecordingError as exc:
                        line["refused"] = str(exc).split(": ", 1)[1]
                    else:
                        line |= {"estimate_s": est.offset,
                                 "error_ms": 1e3 * (est.offset - offset),
                                 "sigma_ms": 1e3 * est.uncertainty, "shift_px": est.shift_px,
                                 "coherence": est.coherence}
                    line["seconds"] = round(time.perf_counter() - t0, 2)
                    common.append(args.out, line)
                    shown = (f"error {line['error_ms']:+.2f} ms (sigma {line['sigma_ms']:.2f})"
                             if "error_ms" in line else f"refused: {line['refused'][:70]}")
                    print(f"[clock] {line['scene']} {duration:g} s, variation {variation:g}, "
                          f"seed {seed}: {shown}", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
