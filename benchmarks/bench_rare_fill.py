"""What meshing would gain by also filling space that few of the training views see.

``hybridneus mesh`` fills the empty space hidden from every camera inside the closing of
matter (docs/meshing.md, "Unseen pockets"). The slab's plate, of about the background's
brightness, leaves a hole that the views from above do see, but only those: about one view in
twenty. This benchmark measures, on finished runs, what a fill of the space seen by at most a
share ``--share`` of the views (every ``--stride``-th training view, so a share counts time
along the capture, not directions) inside the closing of matter by ``--close`` (a fraction of
the box's longest side) would do, joined to the default fill. It meshes each run as the
suite does (res 300, default clean-up, the run's cameras) with the default fill, then with
each share, and scores it against the dataset's ground truth; ``added_inside_truth`` is the
share of the voxels the fill adds that lie inside the ground truth.

It is a measurement, not a meshing option: the fill is made here and handed to
``extract_mesh`` through :class:`hybridneus.meshing.unseen.FilledField`.

    python benchmarks/bench_rare_fill.py RUN [RUN ...] --share 0.05 0.1
"""

from __future__ import annotations

import argparse
from pathlib import Path

import common
import numpy as np


def seen_share(sdf: np.ndarray, grid, cameras: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Share (n,) of ``cameras`` whose line of sight to each of ``points`` (n, 3) does not
    meet the zero level of ``sdf`` (on ``grid``)."""
    import open3d as o3d

    from hybridneus.meshing.unseen import occluder

    scene = occluder(sdf, grid)
    origins = points.astype(np.float32)
    seen = np.zeros(len(points))
    for centre in cameras:
        dirs = centre.astype(np.float32) - origins
        dist = np.linalg.norm(dirs, axis=1)
        dirs /= np.maximum(dist, 1e-12)[:, None]
        hit = scene.cast_rays(o3d.core.Tensor(np.hstack([origins, dirs])))["t_hit"].numpy()
        seen += hit >= dist
    return seen / max(len(cameras), 1)


def rare_fill(field, cameras: np.ndarray, base, share: float, close: float, stride: int):
    """``base`` (the default :class:`UnseenSpace`) joined by the empty space inside the
    closing of matter that at most ``share`` of every ``stride``-th camera sees."""
    from hybridneus.meshing.unseen import _closing, region_space
    from hybridneus.meshing.volume import evaluate_sdf

    grid = base.grid
    shape = tuple(grid.shape)
    ix, iy, iz = np.indices(shape).reshape(3, -1)
    points = grid.points(ix, iy, iz)
    sdf = evaluate_sdf(field, points, 2**18).reshape(shape)
    solid = sdf <= 0
    near = np.flatnonzero(_closing(solid, close * (max(shape) - 1)) & ~solid)
    fill = base.distance < 0
    if near.size and solid.any():
        rare = seen_share(sdf, grid, np.asarray(cameras)[::stride], points[near]) <= share
        fill.flat[near[rare]] = True
    return region_space(fill, grid, base.hidden, base.cameras)


def inside_share(added: np.ndarray, grid, truth) -> float | None:
    """Share of the voxels ``added`` (bool, on ``grid``) inside the mesh of ``truth`` (its
    :func:`hybridneus.evaluation.inside.raycasting_scene`)."""
    import open3d as o3d

    idx = np.argwhere(added)
    if len(idx) == 0:
        return None
    pts = grid.points(*idx.T).astype(np.float32)
    return float((truth.compute_occupancy(o3d.core.Tensor(pts), nsamples=3).numpy() > 0.5)
                 .mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+", help="suite run folders")
    ap.add_argument("--share", type=float, nargs="+", default=[0.05, 0.1])
    ap.add_argument("--close", type=float, default=0.25)
    ap.add_argument("--stride", type=int, default=5)
    ap.add_argument("--res", type=int, default=300)
    common.add_arguments(ap, "rare_fill")
    args = ap.parse_args()
    common.check_tree(args)
    import trimesh
    import yaml

    from hybridneus.evaluation.geometry import chamfer_distance
    from hybridneus.evaluation.inside import raycasting_scene
    from hybridneus.meshing import extract_mesh
    from hybridneus.meshing import unseen as U
    from hybridneus.meshing.extract import _examined_box
    from hybridneus.training.runs import load_cameras, load_field

    for run in args.runs:
        config = yaml.safe_load((run / "config.yaml").read_text())
        dataset = Path(config["data"]["path"])
        gt = trimesh.load(dataset / "gt_mesh.ply", force="mesh")
        truth = raycasting_scene(gt)
        field = load_field(run, device="cpu")
        cameras = load_cameras(run)
        base = U.unseen_space(field, cameras, _examined_box(field, None, None))
        for share in [None, *args.share]:
            unseen = base if share is None else rare_fill(field, cameras, base, share,
                                                          args.close, args.stride)
            source = U.FilledField(field, unseen) if unseen.filled else field
            mesh = extract_mesh(source, res=args.res, progress=False)
            cd = chamfer_distance(mesh, gt)
            added = (unseen.distance < 0) & ~(base.distance < 0)
            inside = inside_share(added, base.grid, truth)
            line = {"bench": "rare_fill", "run": run.name, "share": share,
                    "close": None if share is None else args.close,
                    "filled_voxels": unseen.filled, "added_voxels": int(added.sum()),
                    "added_inside_truth": None if inside is None else round(inside, 3),
                    "chamfer": round(cd.chamfer, 5),
                    "accuracy": round(cd.accuracy, 5), "completeness": round(cd.completeness, 5),
                    **common.stamp(None)}
            common.append(args.out, line)
            print(f"{run.name}: share {share}: CD {cd.chamfer:.4f} (filled {unseen.filled})",
                  flush=True)


if __name__ == "__main__":
    main()
