"""Fit a simulated scene for a time budget, extract the mesh, report Chamfer, time and memory.

Simulates (and caches) a dataset from a shared asset or a built-in scene, trains with a
preset for ``--minutes`` of wall time, extracts the mesh and scores it against the
simulator's ``gt_mesh.ply`` with the paper's Chamfer protocol (hybridneus.evaluation).
The initial sphere is scored as a reference.

    python benchmarks/bench_fit.py --quick                       # builtin:device, 2 min
    python benchmarks/bench_fit.py --scene bunny --minutes 15     # full-size (999 views)
    python benchmarks/bench_fit.py --run runs/bunny-...           # score an existing run
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path

from run_suite import DEFAULT_ASSETS as ASSETS  # the scripts run from benchmarks/


def _mesh_source(scene: str) -> str:
    if scene.startswith("builtin:"):
        return scene
    folder = ASSETS / scene
    for ext in ("obj", "off", "ply", "glb"):
        found = sorted(folder.glob(f"*.{ext}"))
        if found:
            return str(found[0])
    raise SystemExit(f"{folder}: no mesh found (expected an asset name or builtin:<name>)")


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _score(field, gt_path: Path, res: int) -> dict:
    from hybridneus.evaluation.geometry import chamfer_distance
    from hybridneus.meshing import extract_mesh
    from hybridneus.meshing.convert import load_mesh
    from hybridneus.meshing.postprocess import keep_largest_component

    t = time.perf_counter()
    mesh = extract_mesh(field, res=res, progress=False)
    t_mesh = time.perf_counter() - t
    if len(mesh.faces) == 0:
        return {"chamfer": None, "faces": 0, "mesh_s": round(t_mesh, 1)}
    gt = load_mesh(gt_path)
    cd = chamfer_distance(mesh, gt)
    # As in the anchors' experiment, also score the largest connected component alone
    # (floaters are the typical failure; the default clean-up keeps large ones).
    largest = keep_largest_component(mesh)
    cd_largest = chamfer_distance(largest, gt)
    return {"chamfer": cd.chamfer, "accuracy": cd.accuracy, "completeness": cd.completeness,
            "fscore": cd.fscore, "faces": int(len(mesh.faces)),
            "chamfer_largest_component": cd_largest.chamfer, "mesh_s": round(t_mesh, 1)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="builtin:device", help="asset folder name or builtin:x")
    ap.add_argument("--views", type=int, default=999)
    ap.add_argument("--width", type=int, default=346)
    ap.add_argument("--height", type=int, default=260)
    ap.add_argument("--revolutions", type=float, default=8.0)
    ap.add_argument("--minutes", type=float, default=15.0)
    ap.add_argument("--preset", default="fast")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--res", type=int, default=256, help="mesh extraction resolution")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench"))
    ap.add_argument("--out", type=Path, default=Path("/tmp/hybridneus-bench/runs"))
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    ap.add_argument("--run", type=Path, help="score this run folder instead of fitting")
    ap.add_argument("--gt", type=Path, help="ground-truth mesh (default: the dataset's)")
    ap.add_argument("--fit-only", action="store_true", help="train and save, do not score")
    ap.add_argument("--quick", action="store_true",
                    help="builtin:device, 120 views at 173x130, 2 minutes")
    args = ap.parse_args()
    if args.quick:
        args.views, args.width, args.height, args.revolutions = 120, 173, 130, 3.0
        args.minutes = min(args.minutes, 2.0)

    import torch

    from hybridneus.training.runs import load_field

    torch.set_num_threads(args.threads)
    name = args.scene.replace("builtin:", "")
    data = args.cache / f"{name}-{args.views}v-{args.width}x{args.height}"
    report: dict = {"scene": args.scene, "dataset": str(data), "preset": args.preset,
                    "threads": args.threads, "device": args.device}
    if args.run is None:
        if not (data / "scene.json").is_file():
            from hybridneus.simulate import SimulationConfig, simulate_dataset

            t = time.perf_counter()
            simulate_dataset(
                _mesh_source(args.scene), data,
                SimulationConfig(n_views=args.views, width=args.width, height=args.height,
                                 revolutions=args.revolutions, val_views=0, test_views=0),
            )
            report["simulate_s"] = round(time.perf_counter() - t, 1)
        from hybridneus.api import fit
        from hybridneus.config import preset_config

        overrides = [f"train.minutes={args.minutes}", "train.iters=100000000",
                     f"train.threads={args.threads}", *args.overrides]
        t = time.perf_counter()
        field = fit(data, preset_config(args.preset), overrides=overrides, out=args.out,
                    device=args.device, progress=False)
        report.update(fit_s=round(time.perf_counter() - t, 1), steps=field.trainer_step,
                      run=str(field.run_dir), inv_s=round(float(field.inv_s().detach()), 1))
        run_dir = field.run_dir
    else:
        run_dir = args.run
        report["run"] = str(run_dir)
    report["peak_rss_mb"] = round(_peak_rss_mb(), 0)
    if not args.fit_only:
        from hybridneus.config import load_config

        cfg = load_config(run_dir / "config.yaml")
        report.update(dataset=cfg.data.path, preset=cfg.preset)
        gt = args.gt or Path(cfg.data.path) / "gt_mesh.ply"
        field = load_field(run_dir, device="cpu")
        report["trained"] = _score(field, gt, args.res)
        from hybridneus.training.runs import build_field, load_checkpoint

        torch.manual_seed(cfg.train.seed)
        initial = build_field(cfg, load_checkpoint(run_dir)["scene"]).eval()
        report["initial_sphere"] = _score(initial, gt, args.res)
        report["peak_rss_mb"] = round(_peak_rss_mb(), 0)
    print(json.dumps(report, indent=1))


if __name__ == "__main__":
    main()
