"""How much of a fit's error lies outside the visual hull of the event silhouettes.

An experiment: with :func:`hybridneus.data.hull.event_hull` (per training view, the filled
convex hull of the pixels that fired within ``--window`` views, grown by ``--dilate`` pixels)
it carves every voxel of the run's crop box that projects outside that hull in any view (the
strictest form; ``data.crop_from_events`` only takes a bounding cylinder of a voted hull). The
trained field is then meshed as the suite does (``extract_mesh(field, res)``) three ways: as
it is; with the crop's cap trimmed (``PostprocessOptions(trim_crop=True)``, the same grid);
and cut by the hull (``max(sdf, hull_sdf)``). All are scored against the ground truth. It
also reports the share of ground-truth surface points that fall outside the hull, i.e. how
much true surface such a cut would remove.

    python benchmarks/bench_hull.py RUN [RUN ...] [--window 1 --dilate 1 --step 3]

Writes one JSON line per run to ``benchmarks/results/hull.jsonl`` and a cross-section image
(ground truth black, fit red, fit cut by the hull blue) to ``docs/benchmarks/hull-<scene>.png``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import subprocess
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def hull_sdf_grid(split, lo: np.ndarray, hi: np.ndarray, args):
    """Signed distance (world units, negative inside) to the event hull on a grid over
    [lo, hi] with ``args.hull_res`` points on the longest side -> (grid (nx, ny, nz), voxel).
    A voxel is carved when any view sees it outside its silhouette (the strictest hull)."""
    from scipy import ndimage

    from hybridneus.data.hull import event_hull

    hull = event_hull(split, lo, hi, args.hull_res, window=args.window, dilate=args.dilate,
                      step=args.step, min_seen=0.0, min_votes=1e-9)
    inside, voxel = hull.occupied, hull.voxel
    out = ndimage.distance_transform_edt(~inside) * voxel
    into = ndimage.distance_transform_edt(inside) * voxel
    sdf = np.where(inside, 0.5 * voxel - into, out - 0.5 * voxel).astype(np.float32)
    return sdf, voxel, hull.n_views


class HullCutField:
    """A field cut by a hull SDF grid: ``max(field.sdf, hull)`` (trilinear in the grid)."""

    def __init__(self, field, grid: np.ndarray, lo: np.ndarray, voxel: float) -> None:
        import torch

        self.field = field
        # grid_sample wants (N, C, D, H, W) with the last grid coordinate indexing D = z
        self.grid = torch.from_numpy(grid)[None, None].permute(0, 1, 4, 3, 2).contiguous()
        self.lo = torch.tensor(lo, dtype=torch.float32)
        self.extent = torch.tensor((np.array(grid.shape) - 1) * voxel, dtype=torch.float32)

    def hull(self, points):
        import torch.nn.functional as F

        q = ((points.cpu() - self.lo) / self.extent * 2.0 - 1.0).view(1, -1, 1, 1, 3)
        h = F.grid_sample(self.grid, q, align_corners=True, padding_mode="border")
        return h.view(-1).to(points.device)

    def sdf(self, points):
        import torch

        return torch.maximum(self.field.sdf(points), self.hull(points))

    def __getattr__(self, name):
        return getattr(self.field, name)


def section_image(meshes, colors, gt_bounds: np.ndarray, path: Path, width: int = 1100) -> None:
    """Cross-sections at three depths (z planes) through the ground truth's box, stacked."""
    import cv2

    lo, hi = gt_bounds
    pad = 0.08 * float((hi - lo)[:2].max())
    x0, y1 = lo[0] - pad, hi[1] + pad
    scale = width / float(hi[0] - lo[0] + 2 * pad)
    height = int((hi[1] - lo[1] + 2 * pad) * scale) + 1
    rows = []
    for z in lo[2] + (hi[2] - lo[2]) * np.array([0.3, 0.5, 0.7]):
        img = np.full((height, width, 3), 255, np.uint8)
        for mesh, color in zip(meshes, colors, strict=True):
            section = mesh.section(plane_origin=[0.0, 0.0, float(z)], plane_normal=[0, 0, 1])
            if section is None:
                continue
            for entity in section.entities:
                xy = section.vertices[entity.points][:, :2]
                px = np.stack([(xy[:, 0] - x0) * scale, (y1 - xy[:, 1]) * scale], 1)
                cv2.polylines(img, [px.astype(np.int32)], False, color, 1, cv2.LINE_AA)
        cv2.putText(img, f"z = {z:+.3f}", (8, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (80, 80, 80))
        rows.append(img)
        rows.append(np.full((4, width, 3), 200, np.uint8))
    tmp = path.with_name(path.stem + ".tmp.png")
    cv2.imwrite(str(tmp), np.concatenate(rows[:-1], 0))
    tmp.replace(path)


def score_run(run: Path, args) -> dict:
    import torch
    import trimesh

    from hybridneus.config import load_config
    from hybridneus.data import load_dataset
    from hybridneus.evaluation.geometry import chamfer_distance
    from hybridneus.meshing import CropVolume, PostprocessOptions, extract_mesh
    from hybridneus.meshing.volume import DEFAULT_BOUNDS
    from hybridneus.training.runs import load_field

    data = Path(args.data or load_config(run / "config.yaml").data.path)
    split = load_dataset(data)["train"]
    gt = trimesh.load(data / "gt_mesh.ply", force="mesh")
    t0 = time.perf_counter()
    field = load_field(run, device="cpu")
    r, y0, y1 = (float(v) for v in field.crop)
    lo = np.array([-r, y0, -r]) - 0.02
    hi = np.array([r, y1, r]) + 0.02
    grid, voxel, n_views = hull_sdf_grid(split, lo, hi, args)
    cut = HullCutField(field, grid, lo, voxel)
    hull_s = time.perf_counter() - t0

    out = {"run": str(run), "scene": data.name.split("-")[0], "window": args.window,
           "dilate": args.dilate, "step": args.step, "hull_res": args.hull_res,
           "hull_views": n_views, "hull_s": round(hull_s, 1)}
    meshes = []
    trim = {"bounds": DEFAULT_BOUNDS, "crop": CropVolume(r, y0, y1),
            "postprocess": PostprocessOptions(trim_crop=True)}
    for name, f, kwargs in (("plain", field, {}), ("trim", field, trim), ("hull", cut, {})):
        with torch.no_grad():
            mesh = extract_mesh(f, res=args.res, progress=False, **kwargs)
        cd = chamfer_distance(mesh, gt)
        below = mesh.area_faces[mesh.triangles_center[:, 1] < gt.bounds[0, 1] - 0.01].sum()
        out[name] = {"chamfer": cd.chamfer, "accuracy": cd.accuracy,
                     "completeness": cd.completeness, "faces": int(len(mesh.faces)),
                     "below": float(below / max(mesh.area, 1e-12))}
        if name != "trim":
            meshes.append(mesh)
    samples = torch.tensor(gt.sample(20000), dtype=torch.float32)
    h = cut.hull(samples).numpy()
    out["gt_outside"] = float((h > 0).mean())
    out["gt_outside_1vox"] = float((h > voxel).mean())
    args.plots.mkdir(parents=True, exist_ok=True)
    section_image([gt, meshes[0], meshes[1]], [(0, 0, 0), (40, 40, 230), (230, 120, 20)],
                  np.asarray(gt.bounds), args.plots / f"hull-{out['scene']}.png")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path, help="run folders (trained fields)")
    ap.add_argument("--data", type=Path, help="dataset folder (default: the run's config)")
    ap.add_argument("--window", type=int, default=1, help="views either side of each view")
    ap.add_argument("--dilate", type=int, default=1, help="pixels added around each hull")
    ap.add_argument("--step", type=int, default=3, help="use every step-th training view")
    ap.add_argument("--hull-res", type=int, default=160, help="hull grid points, longest side")
    ap.add_argument("--res", type=int, default=300, help="marching-cubes resolution")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "hull.jsonl")
    ap.add_argument("--plots", type=Path, default=REPO / "docs" / "benchmarks")
    args = ap.parse_args()

    import torch

    torch.set_num_threads(args.threads)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO,
                            capture_output=True, text=True).stdout.strip()
    for run in args.runs:
        out = score_run(run, args)
        out["date"] = dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds")
        out["commit"] = commit
        p, c = out["plain"], out["hull"]
        print(f"{out['scene']}: CD {p['chamfer']:.4f}; crop cap trimmed "
              f"{out['trim']['chamfer']:.4f}; {c['chamfer']:.4f} with the hull "
              f"(accuracy {p['accuracy']:.4f} -> {c['accuracy']:.4f}, completeness "
              f"{p['completeness']:.4f} -> {c['completeness']:.4f}; surface >0.01 below the "
              f"bottom {p['below']:.3f} -> {c['below']:.3f}); ground truth outside the hull "
              f"{out['gt_outside']:.4f} (> 1 voxel {out['gt_outside_1vox']:.4f})", flush=True)
        args.out.parent.mkdir(parents=True, exist_ok=True)
        with args.out.open("a") as fh:
            fh.write(json.dumps(out) + "\n")


if __name__ == "__main__":
    main()
