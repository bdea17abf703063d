"""Where a mesh misses the flat faces of its ground truth: per face direction, how far the
ground truth's surface lies from the mesh, and on which side.

For one scene and seed, the suite line of each preset given (as :mod:`pictures` picks them)
names its run folder (``mesh.ply``) and its dataset (``gt_mesh.ply``). The ground truth is
sampled; each sample whose normal lies within 25 degrees of one of the six axis directions
counts for that face direction. Its distance is to the nearest of dense samples of the mesh,
signed along the ground truth's normal: negative where the mesh lies inside (a caved face),
positive outside (a bulged or thickened one). In the dataset's units; meant for the box-like
generated objects, whose faces are the axis directions.

    python benchmarks/face_errors.py gen-box-1829338325 --commit 89b9b42 --seed 1 \\
        --presets fast fast+priors.curvature.end=0
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from pictures import add_line_arguments, lines_with_meshes

AXES = "xyz"
#: A ground-truth sample counts for an axis direction within this angle of it.
MAX_DEG = 25.0


def face_errors(mesh, gt, n_gt: int = 20000, n_mesh: int = 400000,
                seed: int = 0) -> list[dict]:
    """Per axis direction with samples: their share, mean distance, median signed distance
    and 90th percentile of distance (see the module docstring)."""
    import trimesh
    from scipy.spatial import cKDTree

    pts, faces = trimesh.sample.sample_surface(gt, n_gt, seed=seed)
    normals = gt.face_normals[faces]
    near, _ = trimesh.sample.sample_surface(mesh, n_mesh, seed=seed)
    dist, idx = cKDTree(near).query(pts)
    signed = ((near[idx] - pts) * normals).sum(1)
    rows = []
    for axis in range(3):
        for sign in (1, -1):
            sel = normals[:, axis] * sign > np.cos(np.radians(MAX_DEG))
            if sel.sum() < 50:
                continue
            rows.append({"face": f"{'+' if sign > 0 else '-'}{AXES[axis]}",
                         "share": round(float(sel.mean()), 3),
                         "mean": round(float(dist[sel].mean()), 5),
                         "median_signed": round(float(np.median(signed[sel])), 5),
                         "p90": round(float(np.percentile(dist[sel], 90)), 5)})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    add_line_arguments(ap, "gen-box-1829338325")
    args = ap.parse_args()
    import trimesh

    picked = lines_with_meshes(args)
    print("| preset | Chamfer | face | share of the surface | mean distance | median signed "
          "| 90th percentile |")
    print("|---|---|---|---|---|---|---|")
    for line in picked:
        mesh = trimesh.load(Path(line["run"]) / "mesh.ply", process=False)
        gt = trimesh.load(Path(line["dataset"]) / "gt_mesh.ply", process=False)
        for r in face_errors(mesh, gt):
            print(f"| {line['preset']} | {line['chamfer']:.4f} | {r['face']} | {r['share']:.2f} "
                  f"| {r['mean']:.4f} | {r['median_signed']:+.4f} | {r['p90']:.4f} |")


if __name__ == "__main__":
    main()
