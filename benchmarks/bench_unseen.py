"""What filling the space no camera saw does to the Chamfer distance of trained runs.

For each run folder made by ``run_suite.py`` (its ``fit.json`` names the dataset and so the
ground truth), the trained field is meshed at ``--res`` as the suite meshes it, once as it
is and once with the unseen pockets filled (``extract_mesh(..., cameras=...)``, the default
of ``hybridneus mesh``), and both meshes are scored against the ground truth.

    python benchmarks/bench_unseen.py RUN [RUN ...] [--res 300] [--radius 0.1]

Writes one JSON line per run to ``benchmarks/results/unseen.jsonl``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def score(run: Path, res: int, radius: float) -> dict:
    from hybridneus.evaluation.geometry import chamfer_distance
    from hybridneus.meshing import extract_mesh
    from hybridneus.meshing.convert import load_mesh
    from hybridneus.meshing.extract import ExtractionStats
    from hybridneus.training.runs import load_cameras, load_field

    info = json.loads((run / "fit.json").read_text())
    gt = load_mesh(Path(info["dataset"]) / "gt_mesh.ply")
    field = load_field(run, device="cpu")
    cameras = load_cameras(run)
    if cameras is None:
        raise SystemExit(f"{run}: no camera poses saved or found")
    out = {"run": run.name, "scene": info["scene"], "preset": info["preset"], "res": res,
           "radius": radius, "date": dt.datetime.now().isoformat(timespec="seconds")}
    for name, cams in (("plain", None), ("filled", cameras)):
        stats = ExtractionStats()
        t0 = time.perf_counter()
        mesh = extract_mesh(field, res=res, cameras=cams, fill_radius=radius, progress=False,
                            stats=stats)
        seconds = time.perf_counter() - t0
        if len(mesh.faces) == 0:
            out[name] = None
            continue
        cd = chamfer_distance(mesh, gt)
        out[name] = {"chamfer": round(cd.chamfer, 5), "accuracy": round(cd.accuracy, 5),
                     "completeness": round(cd.completeness, 5), "faces": len(mesh.faces),
                     "mesh_s": round(seconds, 2), "filled_voxels": stats.filled_voxels,
                     "unseen_s": round(stats.times.get("unseen", 0.0), 2)}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--res", type=int, default=300)
    ap.add_argument("--radius", type=float, default=0.1, help="fill_radius (box fraction)")
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()
    import torch

    torch.set_num_threads(args.threads)
    log = REPO / "benchmarks" / "results" / "unseen.jsonl"
    log.parent.mkdir(parents=True, exist_ok=True)
    for run in args.runs:
        row = score(run, args.res, args.radius)
        with log.open("a") as f:
            f.write(json.dumps(row) + "\n")
        plain, filled = row["plain"], row["filled"]
        fmt = lambda r: "no mesh" if r is None else (  # noqa: E731
            f"{r['chamfer']:.4f} (acc {r['accuracy']:.4f}, comp {r['completeness']:.4f})")
        extra = "" if filled is None else (
            f"; {filled['filled_voxels']} voxels filled in {filled['unseen_s']:.1f} s")
        print(f"{run.name} [{row['preset']}]: {fmt(plain)} -> filled {fmt(filled)}{extra}",
              flush=True)


if __name__ == "__main__":
    main()
