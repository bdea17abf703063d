"""Where a mesh's accuracy error lies: the share of its surface far from the ground truth, and
at which heights.

Samples ``--points`` points on each predicted mesh and ``4 * --points`` on the ground truth,
measures each predicted point's distance to the nearest ground-truth sample, and prints the
mean of those distances, the share farther than ``--far``, that share's contribution to the
mean, the mesh's largest components, and a histogram of the far points' y (up) coordinate next
to the ground truth's y range. Distances are in the dataset's world units, not the unit cube
of the Chamfer distance (``hybridneus.evaluation.geometry``). Used to tell a filled underside
(far points below the object) from floaters or an envelope around thin parts.

    python benchmarks/error_by_height.py GT_MESH MESH [MESH ...] [--points 50000 --far 0.03]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from hybridneus.errors import MeshError
from hybridneus.evaluation.geometry import as_mesh, sample_surface


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("gt", type=Path)
    ap.add_argument("meshes", type=Path, nargs="+")
    ap.add_argument("--points", type=int, default=50000)
    ap.add_argument("--far", type=float, default=0.03)
    ap.add_argument("--bins", type=int, default=8)
    args = ap.parse_args()

    g = sample_surface(as_mesh(args.gt), 4 * args.points, seed=0)
    tree = cKDTree(g)
    lo, hi = float(g[:, 1].min()), float(g[:, 1].max())
    print(f"ground truth y in [{lo:.3f}, {hi:.3f}]")
    for path in args.meshes:
        mesh = as_mesh(path)
        p = sample_surface(mesh, args.points, seed=1)
        d, _ = tree.query(p)
        far = d > args.far
        parts = sorted((len(c.faces) for c in mesh.split(only_watertight=False)), reverse=True)
        print(f"{path}: mean {d.mean():.4f}, far {far.mean():.3f} "
              f"(adds {float((d * far).sum()) / len(d):.4f} to the mean), "
              f"components {len(parts)} {parts[:5]}")
        if far.any():
            counts, edges = np.histogram(p[far, 1], bins=args.bins, range=(-0.4, 0.4))
            rows = ", ".join(f"[{a:+.1f},{b:+.1f}) {c}"
                             for a, b, c in zip(edges[:-1], edges[1:], counts, strict=True) if c)
            print(f"  far points by y: {rows}")


if __name__ == "__main__":
    try:
        main()
    except MeshError as exc:
        raise SystemExit(f"error: {exc}") from None
