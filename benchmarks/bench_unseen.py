"""What filling the space no camera saw does to the Chamfer distance of trained runs.

For each run folder made by ``run_suite.py`` (its ``fit.json`` names the dataset and so the
ground truth), the trained field is meshed at ``--res`` as the suite meshes it, once as it
is and once with the unseen pockets filled (``extract_mesh(..., cameras=...)``, the default
of ``hybridneus mesh``), and both meshes are scored against the ground truth.

    python benchmarks/bench_unseen.py RUN [RUN ...] [--res 300] [--radius 0.1] [--thickness 4]
        [--slices DIR]

Writes one JSON line per run to ``benchmarks/results/unseen.jsonl``; with ``--slices``, also
``DIR/unseen-<run>.png``: five slices across z, the ground truth in green and the mesh in
red, as it is (top row) and filled (bottom row).
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def slice_rows(gt, meshes, size: int = 260) -> np.ndarray:
    """An image: one row per mesh of five z-slices, ``gt`` green and the mesh red."""
    import cv2
    import trimesh

    lo, hi = gt.bounds
    span = float((hi - lo)[:2].max()) * 1.15
    mid = (lo + hi) / 2
    rows = []
    for mesh in meshes:
        tiles = []
        for z in np.linspace(lo[2], hi[2], 7)[1:-1]:
            img = np.full((size, size, 3), 255, np.uint8)
            for m, colour in ((gt, (0, 150, 0)), (mesh, (0, 0, 230))):
                segments = trimesh.intersections.mesh_plane(m, [0, 0, 1], [0, 0, z])
                if len(segments) == 0:
                    continue
                uv = (segments[:, :, :2] - mid[:2]) / span * size + size / 2
                uv[:, :, 1] = size - 1 - uv[:, :, 1]
                cv2.polylines(img, np.round(uv).astype(np.int32), False, colour, 1, cv2.LINE_AA)
            cv2.putText(img, f"z={z:+.2f}", (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0))
            tiles.append(img)
        rows.append(np.hstack(tiles))
    return np.vstack(rows)


def score(run: Path, res: int, radius: float, thickness: float,
          slices: Path | None = None) -> dict:
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
           "radius": radius, "thickness": thickness,
           "date": dt.datetime.now().isoformat(timespec="seconds")}
    meshes = []
    for name, cams in (("plain", None), ("filled", cameras)):
        stats = ExtractionStats()
        t0 = time.perf_counter()
        mesh = extract_mesh(field, res=res, cameras=cams, fill_radius=radius, progress=False,
                            fill_thickness=thickness, stats=stats)
        seconds = time.perf_counter() - t0
        meshes.append(mesh)
        if len(mesh.faces) == 0:
            out[name] = None
            continue
        cd = chamfer_distance(mesh, gt)
        out[name] = {"chamfer": round(cd.chamfer, 5), "accuracy": round(cd.accuracy, 5),
                     "completeness": round(cd.completeness, 5), "faces": len(mesh.faces),
                     "mesh_s": round(seconds, 2), "filled_voxels": stats.filled_voxels,
                     "unseen_s": round(stats.times.get("unseen", 0.0), 2)}
    if slices is not None and all(len(m.faces) for m in meshes):
        import cv2

        from hybridneus.fileio import atomic_path

        slices.mkdir(parents=True, exist_ok=True)
        with atomic_path(slices / f"unseen-{run.name}.png") as tmp:
            cv2.imwrite(str(tmp), slice_rows(gt, meshes))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--res", type=int, default=300)
    ap.add_argument("--radius", type=float, default=0.1, help="fill_radius (box fraction)")
    ap.add_argument("--thickness", type=float, default=4.0,
                    help="fill_thickness (voxels of the fill's grid)")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--slices", type=Path, help="write a slice figure per run here")
    args = ap.parse_args()
    import torch

    torch.set_num_threads(args.threads)
    log = REPO / "benchmarks" / "results" / "unseen.jsonl"
    log.parent.mkdir(parents=True, exist_ok=True)
    for run in args.runs:
        row = score(run, args.res, args.radius, args.thickness, args.slices)
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
