"""A real-capture stand-in, end to end: a noisy DAVIS346 recording with a messy motion-capture
track and an unstated clock offset, converted with nothing stated but ``--clock-offset auto``,
fitted, and scored against the clean direct fit.

1. The scene simulated as a DAVIS346 at indoor light (``--noise davis346``: its thresholds,
   mismatch, background activity, hot pixels, refractory period, timestamp jitter; 999 views,
   346x260, cached in ``--cache``) and, for the reference, without noise at a symmetric
   threshold, as the suite simulates it.
2. Re-timed as a hand-held capture (``--duration`` s, log-speed spread ``--variation``), the
   events written to an AEDAT4 file (dv-processing) with the camera's APS frames (``--fps``,
   ``--exposure``, ``--frame-bits`` of linear light; ``--fps 0``: none), the track a 200 Hz
   CSV in a metric frame
   (rotated, 0.37 m per unit, shifted) on a clock ``--offset`` s ahead, with what motion
   capture writes: occluded rows (empty cells, zeros), repeated stamps and a 40 ms dropout
   (between two views).
3. ``hybridneus convert davis.aedat4 OUT --poses mocap.csv --calib calib.json --sensor RGGB
   --clock-offset auto``: no threshold, box or offset stated (C is taken from the frames).
4. Both datasets fitted with the same preset, seed and steps, meshed, and scored in the
   original scene's frame with the paper's Chamfer protocol. ``--fits`` adds, to find where a
   gap comes from, ``noisy`` (the DAVIS346 simulation fitted directly, its preset stating the
   true threshold) and ``told`` (the recording converted with the true offset and threshold
   stated), or leaves fits out.

One line per scene and seed to ``benchmarks/results/capture.jsonl``: the clock estimate
against the truth, what the conversion reported, both Chamfers and their ratio. Target
(issue: a real capture): the converted fit within 1.25x of the clean direct one.

    python benchmarks/bench_capture.py --scene bunny --seed 0
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import common
import numpy as np
from bench_roundtrip import EULER_DEG, SCALE, SHIFT, add_fit_arguments, fit, score

POSE_HZ = 200.0


def messy_track(rows: np.ndarray, view_t: np.ndarray, rng) -> tuple[list[str], dict]:
    """CSV lines of a TUM ``rows`` track as motion capture writes them: about 0.5% of the
    rows occluded (empty cells or zeros in place of the pose), 0.2% written twice, and a
    40 ms dropout centred between two views (``view_t``, pose clock) in the middle."""
    lines = ["time,x,y,z,qx,qy,qz,qw"]
    k = view_t.size // 2
    gap_mid = 0.5 * (view_t[k] + view_t[k + 1])
    dropped = np.abs(rows[:, 0] - gap_mid) < 0.02
    occluded = repeated = 0
    for i, (row, drop) in enumerate(zip(rows, dropped, strict=True)):
        if drop:
            continue
        u = rng.random()
        if 0 < i < len(rows) - 1 and u < 0.005:
            lines.append(f"{row[0]:.6f}" + ("," * 7 if u < 0.0025 else ",0" * 7))
            occluded += 1
            continue
        lines.append(",".join(f"{v:.9f}" for v in row))
        if rng.random() < 0.002:
            lines.append(lines[-1])
            repeated += 1
    return lines, {"occluded": occluded, "repeated": repeated,
                   "dropout_s": [float(gap_mid - 0.02), float(gap_mid + 0.02)]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    add_fit_arguments(ap, 4500)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--variation", type=float, default=1.0)
    ap.add_argument("--offset", type=float, default=0.04, help="pose clock - event clock, s")
    ap.add_argument("--fps", type=float, default=20.0, help="APS frames a second (0: none)")
    ap.add_argument("--exposure", type=float, default=0.005, help="APS exposure, s")
    ap.add_argument("--frame-bits", type=int, default=8, choices=[8, 16])
    ap.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE",
                    help="a config override for the fits of the converted recording "
                    "(converted, told), to find where a gap comes from (the line keeps it)")
    ap.add_argument("--fits", nargs="+", default=["clean", "converted"],
                    choices=["clean", "converted", "noisy", "told"])
    common.add_arguments(ap, "capture")
    args = ap.parse_args()
    common.check_tree(args)

    import run_suite
    from PIL import Image
    from scipy.spatial.transform import Rotation

    from hybridneus.data import load_dataset
    from hybridneus.recordings import read_scene_frame
    from hybridneus.simulate import DAVIS346_THRESHOLD
    from hybridneus.simulate.recording import (
        aps_frames,
        as_recording,
        handheld_times,
        write_aedat4,
    )

    assets = run_suite.find_assets(args.assets)
    name = run_suite.scene_name(args.scene)
    ns = SimpleNamespace(views=999, width=346, height=260, test_views=8, noise=(0.0, 0.0),
                         cache=args.cache, assets=args.assets)
    clean = run_suite.dataset_for(args.scene, assets, ns)
    noisy = run_suite.davis346_dataset(args.scene, assets, args.cache, args.duration)
    c = DAVIS346_THRESHOLD[0]
    args.gt = clean / "gt_mesh.ply"
    sp = load_dataset(noisy, splits="train")["train"]
    work = args.cache / f"{name}-capture-s{args.seed}"
    work.mkdir(parents=True, exist_ok=True)
    times = handheld_times(sp.n_views, args.duration, args.seed, args.variation)
    R = Rotation.from_euler("xyz", EULER_DEG, degrees=True).as_matrix()
    c2w = sp.c2w.copy()
    c2w[:, :3, :3] = R @ sp.c2w[:, :3, :3]
    c2w[:, :3, 3] = SCALE * sp.c2w[:, :3, 3] @ R.T + SHIFT
    t0 = 1_650_000_000.0
    rec = as_recording(sp.events, c2w, times, t0=t0, pose_rate=POSE_HZ,
                       clock_offset=args.offset)
    frames = []
    if args.fps > 0:
        def view_image(i: int) -> np.ndarray:
            return np.asarray(Image.open(sp.rgb_paths[i]).convert("RGB"))

        frames = aps_frames(view_image, times, args.fps, args.exposure, t0=t0,
                            bits=args.frame_bits)
    write_aedat4(work / "davis.aedat4", rec, frames, (sp.width, sp.height))
    del frames
    # convert places 1000 views evenly from the first to the last event
    views = np.linspace(rec.t[0], rec.t[-1], 1000) + args.offset
    lines, mess = messy_track(rec.tum_rows(), views, np.random.default_rng(args.seed))
    (work / "mocap.csv").write_text("\n".join(lines) + "\n")
    common.write_calibration(sp, work / "calib.json")

    def convert(out: Path, *stated: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "hybridneus.cli.app", "convert", str(work / "davis.aedat4"),
             str(out), "--poses", str(work / "mocap.csv"), "--calib",
             str(work / "calib.json"), "--sensor", "RGGB", "--quiet", *stated],
            capture_output=True, text=True)

    converted = work / "data"
    t = time.perf_counter()
    proc = convert(converted, "--clock-offset", "auto")
    convert_s = round(time.perf_counter() - t, 1)
    line = {"bench": "capture", **common.stamp(args.threads), "scene": name,
            "preset": args.preset, "iters": args.iters, "seed": args.seed,
            "duration_s": args.duration, "variation": args.variation,
            "offset_s": args.offset, "track": mess, "convert_s": convert_s,
            "frames": {"fps": args.fps, "exposure_s": args.exposure, "bits": args.frame_bits},
            "convert_stderr": proc.stderr.strip().splitlines()}
    if args.sets:
        line["sets"] = list(args.sets)
    if proc.returncode != 0:
        line["refused"] = proc.stderr.strip()
        common.append(args.out, line)
        raise SystemExit(f"[capture] {name}: convert refused: {proc.stderr.strip()}")
    doc = json.loads((converted / "scene.json").read_text())
    est = doc["poses"]["clock_offset_estimate"]
    line |= {"clock_error_ms": 1e3 * (est["offset_s"] - args.offset),
             "clock_sigma_ms": 1e3 * est["uncertainty_s"],
             "hot_pixels": doc["events"]["hot_pixels"]["n"],
             "threshold": {"true": c, "converted": doc["preset"].get("threshold"),
                           "from_frames": doc["sensor"].get("threshold_from_frames")}}
    told = work / "told"
    if "told" in args.fits:
        shutil.rmtree(told, ignore_errors=True)
        proc = convert(told, "--clock-offset", repr(args.offset), "--threshold", repr(c))
        if proc.returncode != 0:
            raise SystemExit(f"[capture] {name}: convert (told) failed: {proc.stderr.strip()}")

    def back_from(folder: Path):
        frame = read_scene_frame(folder)
        return lambda v: ((frame.to_recording(v) - SHIFT) @ R) / SCALE

    runs = {"clean": (clean, None), "converted": (converted, back_from(converted)),
            "noisy": (noisy, None), "told": (told, back_from(told) if told.exists() else None)}
    scores = {}
    for label in args.fits:
        folder, back = runs[label]
        try:
            sets = tuple(args.sets) if label in ("converted", "told") else ()
            run_dir = fit(args, f"{name}-{label}", folder, sets)
        except subprocess.CalledProcessError as exc:  # the fit's own error is on stderr
            line[f"failed_{label}"] = f"the fit failed (exit {exc.returncode})"
            print(f"[capture] {label}: the fit failed", file=sys.stderr, flush=True)
            continue
        scores[label] = score(args, run_dir, folder, back)
        line[f"chamfer_{label}"] = scores[label]["chamfer"]
        print(f"[capture] {label}: CD {scores[label]['chamfer']}", file=sys.stderr, flush=True)
    line["fits"] = scores
    if {"clean", "converted"} <= set(scores):
        line["ratio"] = round(scores["converted"]["chamfer"] / scores["clean"]["chamfer"], 3)
    common.append(args.out, line)
    print(json.dumps(line))


if __name__ == "__main__":
    main()
