"""A DAVIS's frames in a converted recording: the threshold taken from them.

No fit. Each scene is simulated as a DAVIS346 at indoor light (``--noise davis346``: its
ON / OFF thresholds, mismatch, background activity, hot pixels, refractory period, timestamp
jitter; 999 views, 346x260, cached in ``--cache``), re-timed as a hand-held capture
(:func:`hybridneus.simulate.recording.handheld_times`), its frames made at ``--fps`` with
``--exposure`` (the rendered views' light averaged over each exposure), stored with 8 and
with 16 bits of linear light (``--bits``), and written with the events into one AEDAT4 file
(dv-processing, as DV writes it), with a 200 Hz TUM track. That
recording is converted with ``hybridneus convert --views frames`` as a user would. Two
estimates are scored: the conversion's, on the frames' stored values (what ``scene.json``
states as C; ``converted``), and the fit's ``estimate.threshold`` on the kept ``rgb/`` files,
re-encoded as 8-bit sRGB (``estimated``).

One line per scene and bit depth to ``benchmarks/results/frames.jsonl``: the true and
estimated ON / OFF thresholds, the error of C, the share of the counts the replay explains,
the frames kept and the seconds each stage took. Target (issue: a real capture): C within
10% of the truth.

    python benchmarks/bench_frames.py
    python benchmarks/bench_frames.py --scenes bunny --fps 30
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import common
import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    ap.add_argument("--scenes", nargs="+",
                    default=["bunny", "generated:device:161576974", "generated:box:1829338325"])
    ap.add_argument("--assets", type=Path, default=common.REPO.parent / "shared" / "assets")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench"))
    ap.add_argument("--duration", type=float, default=30.0, help="seconds of the capture")
    ap.add_argument("--fps", type=float, default=20.0)
    ap.add_argument("--exposure", type=float, default=0.005, help="seconds")
    ap.add_argument("--bits", type=int, nargs="+", default=[8, 16],
                    help="bits the frames are stored with (a line for each)")
    ap.add_argument("--seed", type=int, default=0)
    common.add_arguments(ap, "frames")
    args = ap.parse_args()
    common.check_tree(args)

    import json

    import run_suite
    from PIL import Image

    from hybridneus.data import load_dataset
    from hybridneus.data.threshold import estimate_thresholds
    from hybridneus.simulate import DAVIS346_THRESHOLD
    from hybridneus.simulate.recording import (
        aps_frames,
        as_recording,
        handheld_times,
        write_aedat4,
    )

    assets = run_suite.find_assets(args.assets)
    c, o = DAVIS346_THRESHOLD
    for source in args.scenes:
        name = run_suite.scene_name(source)
        stages = {}
        t = time.perf_counter()
        folder = run_suite.davis346_dataset(source, assets, args.cache, args.duration,
                                            args.seed)
        stages["simulate_s"] = round(time.perf_counter() - t, 1)
        sp = load_dataset(folder, splits="train")["train"]
        for bits in args.bits:
            work = args.cache / f"{name}-davis346-recording-{bits}bit"
            work.mkdir(parents=True, exist_ok=True)
            t = time.perf_counter()
            times = handheld_times(sp.n_views, args.duration, args.seed, 0.5)
            rec = as_recording(sp.events, sp.c2w, times, t0=1_650_000_000.0)
            paths = sp.rgb_paths

            def view_image(i, paths=paths):
                return np.asarray(Image.open(paths[i]).convert("RGB"))

            frames = aps_frames(view_image, times, args.fps, args.exposure,
                                t0=1_650_000_000.0, bits=bits)
            write_aedat4(work / "davis.aedat4", rec, frames, (sp.width, sp.height))
            np.savetxt(work / "mocap.txt", rec.tum_rows(), fmt="%.9f")
            common.write_calibration(sp, work / "calib.json")
            stages["write_s"] = round(time.perf_counter() - t, 1)
            t = time.perf_counter()
            out = work / "data"
            proc = subprocess.run(
                [sys.executable, "-m", "hybridneus.cli.app", "convert", str(work / "davis.aedat4"),
                 str(out), "--poses", str(work / "mocap.txt"), "--calib", str(work / "calib.json"),
                 "--sensor", "RGGB", "--views", "frames", "-q"], capture_output=True, text=True)
            if proc.returncode != 0:
                raise SystemExit(f"[frames] {name}: convert failed: {proc.stderr.strip()}")
            stages["convert_s"] = round(time.perf_counter() - t, 1)
            found = json.loads((out / "scene.json").read_text())["sensor"].get(
                "threshold_from_frames")
            t = time.perf_counter()
            ds = load_dataset(out)
            est, reason = estimate_thresholds(ds["train"], ds.preset)
            stages["estimate_s"] = round(time.perf_counter() - t, 1)
            true_on, true_off = c * (1 + o), c * (1 - o)
            line = {"bench": "frames", **common.stamp(None), "scene": name,
                    "duration_s": args.duration, "fps": args.fps, "exposure_s": args.exposure,
                    "bits": bits, "frames": len(frames), "views": ds["train"].n_views,
                    "events": int(len(ds["train"].events)),
                    "true": {"on": true_on, "off": true_off, "threshold": c},
                    **stages}
            if found is not None:
                line |= {"converted": found, "converted_error": found["threshold"] / c - 1.0}
            if est is None:
                line["refused"] = reason
                shown = f"no estimate: {reason}"
            else:
                line |= {"estimated": {"on": est.on, "off": est.off, "threshold": est.threshold},
                         "threshold_error": est.threshold / c - 1.0, "explained": est.explained}
                shown = (f"C {est.threshold:.4f} against {c:.4f} "
                         f"({100 * line['threshold_error']:+.1f}%)")
            common.append(args.out, line)
            if found is not None:
                shown += (f"; at conversion C {found['threshold']:.4f} "
                          f"({100 * line['converted_error']:+.1f}%)")
            print(f"[frames] {name}, {bits}-bit frames: {len(frames)}, {shown}", file=sys.stderr,
                  flush=True)


if __name__ == "__main__":
    main()
