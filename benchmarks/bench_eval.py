"""Evaluation cost: Chamfer and SDF-MAE (per sign method) on the shared benchmark meshes.

    python benchmarks/bench_eval.py            # bunny (closed) and xylophone (open), 10^4 points
    python benchmarks/bench_eval.py --quick    # bunny only, 2000 points, one repeat

The prediction is the ground truth with Gaussian vertex noise (0.2% of the box side), so the
numbers also show the metric values for a near-perfect reconstruction. Medians over --repeats
after one warm-up; other processes on the machine make absolute times noisy.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch
import trimesh
from run_suite import DEFAULT_ASSETS as ASSETS  # the scripts run from benchmarks/

MESHES = {
    "bunny": ASSETS / "bunny" / "bunny.off",
    "xylophone": ASSETS / "xylophone" / "xylophone.obj",
}


def perturbed(mesh: trimesh.Trimesh, sigma: float, seed: int = 1) -> trimesh.Trimesh:
    """A copy with N(0, sigma * box side) noise on every vertex."""
    rng = np.random.default_rng(seed)
    scale = sigma * float(np.ptp(mesh.vertices, axis=0).max())
    noise = rng.normal(scale=scale, size=mesh.vertices.shape)
    return trimesh.Trimesh(mesh.vertices + noise, mesh.faces, process=False)


def median_time(fn, repeats: int):
    """(median seconds, last result) of ``fn()`` over ``repeats`` calls after one warm-up."""
    result = fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--meshes", nargs="+", default=list(MESHES))
    parser.add_argument("--samples", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--quick", action="store_true")
    parser.add_argument(
        "--winding", action="store_true", help="also time SDF-MAE with the winding number only"
    )
    args = parser.parse_args()
    if args.quick:
        args.meshes, args.samples, args.repeats = ["bunny"], 2000, 1
    torch.set_num_threads(args.threads)

    from hybridneus.evaluation import chamfer_distance, inside_mask, normalize_pair, sdf_mae
    from hybridneus.evaluation.inside import ray_votes
    from hybridneus.meshing import load_mesh

    print(f"{args.samples} samples, median of {args.repeats}, torch threads {args.threads}")
    print("| mesh | faces | watertight | metric | seconds | value |")
    print("|---|---|---|---|---|---|")
    for name in args.meshes:
        gt = load_mesh(MESHES[name])
        pred = perturbed(gt, 0.002)
        row = f"| {name} | {len(gt.faces)} | {gt.is_watertight} |"
        secs, cd = median_time(
            lambda p=pred, g=gt: chamfer_distance(p, g, args.samples), args.repeats
        )
        print(f"{row} Chamfer | {secs:.2f} | {cd.chamfer:.5f} (F {cd.fscore:.3f}) |", flush=True)
        for method in ("rays", "auto", "winding") if args.winding else ("rays", "auto"):
            secs, mae = median_time(
                lambda m=method, p=pred, g=gt: sdf_mae(p, g, args.samples, sign_method=m),
                args.repeats,
            )
            print(f"{row} SDF-MAE {method} | {secs:.2f} | {mae.mae:.5f} |", flush=True)
        # how many points the auto mode hands to the winding number
        from hybridneus.evaluation.geometry import sdf_mae_points

        npred, ngt = normalize_pair(pred, gt)
        pts, _ = sdf_mae_points(npred, ngt, args.samples)
        votes = ray_votes(ngt, pts)
        unsure = float(((votes > 0) & (votes < 1)).mean())
        disagree = float((inside_mask(ngt, pts, "rays") != inside_mask(ngt, pts, "auto")).mean())
        print(f"{row} rays: unsure share / differs from auto | - | {unsure:.3f} / {disagree:.3f} |")


if __name__ == "__main__":
    main()
