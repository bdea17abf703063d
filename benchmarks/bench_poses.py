"""Poses with known errors: Chamfer and pose error of a fit on the track as given and on the
track smoothed (``refine.pose_smoothing``), against a fit on the true poses.

1. Simulate a scene (a shared asset, or a generated / built-in source) at full size with the
   errors of a realistic capture in its written training poses (``CaptureErrors``: by default
   0.5 degrees RMS rotation, 1% of the camera distance RMS translation, a 0.01-view clock
   offset); the events come from the true poses, which go to ``train/pose_true/``.
2. Make the exact-pose copy: the same events, the true poses.
3. Fit four times with the same preset, seed and number of steps: exact poses; the erroneous
   poses as given; the erroneous poses smoothed (``--set`` settings, by default
   ``refine.pose_smoothing=-1``: the window chosen from the track); the exact poses smoothed
   the same way (what smoothing costs where nothing needs it). Mesh and score each with the
   suite's protocol (Chamfer against the scene's ground truth).
4. Measure the given and the smoothed poses against the truth (rotation in degrees, camera
   centre as a share of the camera distance), and the smoothed fits' time per step against
   the plain ones' (whole fit; fits run one after another, so run it alone on the machine,
   or give ``--shared-machine`` to leave the step times out).

One line per scene to ``benchmarks/results/poses.jsonl`` (the smoothed fit's fields are named
``refined``). Targets: smoothed / exact Chamfer at most 1.2; on exact poses, smoothing costs at
most 5% of Chamfer and 15% of step time.

    python benchmarks/bench_poses.py --scene bunny --iters 2000
    python benchmarks/bench_poses.py --scene electricGuitar --set refine.pose_smoothing=41
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import common
import numpy as np
import yaml
from bench_roundtrip import add_fit_arguments, fit, score, simulated_variant


def noisy_dataset(args) -> Path:
    """The scene simulated with capture errors (cached beside the suite's datasets)."""
    from hybridneus.simulate import CaptureErrors

    suffix = (f"pose{args.rotation:g}-{args.translation:g}-{args.clock:g}-s{args.noise_seed}"
              + (f"-drift{args.drift:g}" if args.drift else ""))
    capture = CaptureErrors(args.rotation, args.translation, args.clock, args.noise_seed,
                            smooth_views=args.drift)
    return simulated_variant(args, suffix, "poses", capture=capture)


def exact_copy(noisy: Path) -> Path:
    """The same dataset with the true training poses."""
    exact = noisy.with_name(noisy.name + "-exact")
    if not (exact / "scene.json").is_file():
        shutil.copytree(noisy, exact, dirs_exist_ok=True)
        shutil.rmtree(exact / "train" / "pose")
        shutil.move(exact / "train" / "pose_true", exact / "train" / "pose")
    return exact


def pose_error_stats(poses: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """Rotation error in degrees and camera-centre shift in % of the true camera distance,
    mean and largest over the views (unrounded)."""
    from hybridneus.data.track import pose_errors

    degrees, moved = pose_errors(poses, truth)
    share = moved / np.linalg.norm(truth[:, :3, 3], axis=1)
    return {"rot_deg_mean": float(degrees.mean()), "rot_deg_max": float(degrees.max()),
            "centre_pct_mean": 100 * float(share.mean()),
            "centre_pct_max": 100 * float(share.max())}


def pose_error_summary(poses: np.ndarray, truth: np.ndarray) -> dict:
    return {k: round(v, 4) for k, v in pose_error_stats(poses, truth).items()}


def _poses(folder: Path) -> np.ndarray:
    return np.stack([np.loadtxt(p) for p in sorted(folder.glob("*.txt"))])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    add_fit_arguments(ap, iters=3000)
    ap.add_argument("--rotation", type=float, default=0.5, help="RMS degrees per view")
    ap.add_argument("--translation", type=float, default=0.01, help="RMS share of distance")
    ap.add_argument("--clock", type=float, default=0.01, help="clock offset, views")
    ap.add_argument("--drift", type=float, default=0.0,
                    help="errors drawn every this many views, linear between (0: per view)")
    ap.add_argument("--noise-seed", type=int, default=0)
    ap.add_argument("--set", dest="sets", action="append", default=[],
                    help="config override of the smoothed fits (repeatable; default "
                    "refine.pose_smoothing=-1)")
    ap.add_argument("--shared-machine", action="store_true",
                    help="other work runs on the machine too: the line keeps the Chamfers and "
                    "pose errors (fixed steps, so they do not depend on it) and leaves the "
                    "step-time ratios out")
    common.add_arguments(ap, "poses")
    args = ap.parse_args()
    common.check_tree(args)
    noisy = noisy_dataset(args)
    exact = exact_copy(noisy)
    truth = _poses(noisy / "train" / "pose_true")
    given = _poses(noisy / "train" / "pose")
    args.gt = noisy / "gt_mesh.ply"
    scores, runs = {}, {}
    refine = args.sets or ["refine.pose_smoothing=-1"]
    for name, folder, extra in (("exact", exact, []), ("given", noisy, []),
                                ("refined", noisy, refine), ("exact_refined", exact, refine)):
        run_dir = fit(args, f"{args.scene}-poses-{name}", folder, tuple(extra))
        runs[name] = run_dir
        scores[name] = score(args, run_dir, folder)
        print(f"[poses] {name}: CD {scores[name]['chamfer']}", file=sys.stderr, flush=True)
    saved = runs["refined"] / "poses_refined.npz"  # none where the settings smoothed nothing
    refined = np.load(saved)["refined"] if saved.is_file() else given
    record = yaml.safe_load((runs["refined"] / "scene.yaml").read_text())
    e, g, r = (scores[k]["chamfer"] for k in ("exact", "given", "refined"))
    step = {k: scores[k]["fit_s"] / max(scores[k]["steps"], 1) for k in scores}
    line = {"bench": "poses", **common.stamp(args.threads), "scene": args.scene,
            "views": args.views, "size": f"{args.width}x{args.height}",
            "pose_noise": {"rotation_deg": args.rotation, "translation": args.translation,
                           "clock_offset_views": args.clock, "seed": args.noise_seed,
                           "smooth_views": args.drift},
            "preset": args.preset, "iters": args.iters, "seed": args.seed,
            "refine_sets": refine, "chamfer_exact": e, "chamfer_given": g,
            "chamfer_refined": r, "given_ratio": round(g / e, 3),
            "refined_ratio": round(r / e, 3),
            "chamfer_exact_refined": scores["exact_refined"]["chamfer"],
            "exact_refined_ratio": round(scores["exact_refined"]["chamfer"] / e, 3),
            "poses_given": pose_error_summary(given, truth),
            "poses_refined": pose_error_summary(refined, truth),
            # the smoothing window the fit chose from the track (refine.pose_smoothing=-1)
            "pose_window": record.get("pose_window"),
            "alone": not args.shared_machine,
            "step_time_ratio": (None if args.shared_machine
                                else round(step["refined"] / step["given"], 3)),
            "exact_step_time_ratio": (None if args.shared_machine
                                      else round(step["exact_refined"] / step["exact"], 3)),
            "fits": scores}
    common.append(args.out, line)
    print(json.dumps({k: v for k, v in line.items() if k != "machine"}))


if __name__ == "__main__":
    main()
