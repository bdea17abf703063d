"""Where a fit's wrong surface lies relative to the free space of the ``hull`` term.

The ``hull`` term (``loss.lambda_hull``) pushes the SDF positive where the events' visual hull
calls the space empty. This bench asks how much of a trained field's error that term could
still reach. For each run it meshes the last snapshot (or checkpoint) as the suite does,
samples points on that mesh and measures their distance to the ground truth (world units).
It then reports, for the free space the trainer builds (the crop box, ``loss.hull_resolution``),
the share of the box called empty, the share of the true surface called empty (what the
term would carve), and, per distance band, the share of the fit's surface called empty, at
the surface and one hull voxel inside it (where a negative SDF would meet the term).
It also reports the trainer's loss log: the mean ``loss/hull`` over the last quarter.

``--close K`` also tries non-convex silhouettes: the firing pixels (noise removed) closed by
a disc of radius K pixels and hole-filled, instead of their convex hull; ``--votes`` sets the
share of the views that must see a point outside (the trainer uses 0.05).

    python benchmarks/bench_free_error.py RUN [RUN ...] [--close 7] [--votes 0.05 0.2 0.4]

Writes one JSON line per run and silhouette form to ``benchmarks/results/free_error.jsonl``.
"""

from __future__ import annotations

import argparse
import csv
import datetime as dt
import json
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
BANDS = ((0.0, 0.005), (0.005, 0.01), (0.01, 0.02), (0.02, np.inf))


def closed_silhouettes(split, radius: int, window: int = 1, dilate: int = 2):
    """(views, masks) as :func:`event_silhouettes`, with the convex hull of the firing
    pixels replaced by their closing with a disc of ``radius`` pixels, holes filled."""
    import cv2

    from hybridneus.data.hull import fired_near, hull_view_step

    w, h = split.width, split.height
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1,) * 2)
    grow = np.ones((2 * dilate + 1,) * 2, np.uint8)
    views, masks = [], []
    for i in range(window, split.n_views - window, hull_view_step(split)):
        fired = fired_near(split, i, window)
        if fired is None or fired.sum() < 3:
            continue
        shut = cv2.morphologyEx(fired.astype(np.uint8), cv2.MORPH_CLOSE, disc,
                                borderType=cv2.BORDER_CONSTANT, borderValue=0)
        # holes: whatever the background flooded in from the border does not reach
        outside = np.pad(shut, 1).copy()
        cv2.floodFill(outside, np.zeros((h + 4, w + 4), np.uint8), (0, 0), 2)
        views.append(i)
        masks.append(cv2.dilate((outside[1:-1, 1:-1] != 2).astype(np.uint8), grow) > 0)
    return views, masks


def hull_loss_tail(run: Path) -> float | None:
    """Mean ``loss/hull`` over the last quarter of the run's metrics (None if not logged)."""
    with open(run / "metrics.csv", newline="") as f:
        rows = list(csv.DictReader(f))  # the run log rewrites the header when a column appears
    values = [float(r["loss/hull"]) for r in rows[3 * len(rows) // 4:] if r.get("loss/hull")]
    return float(np.mean(values)) if values else None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--res", type=int, default=300)
    ap.add_argument("--points", type=int, default=50_000)
    ap.add_argument("--close", type=int, default=0, help="also closed silhouettes (radius px)")
    ap.add_argument("--votes", type=float, nargs="+", default=[0.05])
    ap.add_argument("--threads", type=int, default=2)
    args = ap.parse_args()

    import torch
    import trimesh
    from scipy.spatial import cKDTree

    from hybridneus.config import load_config
    from hybridneus.data import load_dataset
    from hybridneus.data.hull import FreeSpace, event_hull, event_silhouettes, hull_view_step
    from hybridneus.meshing import extract_mesh
    from hybridneus.model.field import crop_aabb
    from hybridneus.training.runs import build_field

    torch.set_num_threads(args.threads)
    out = REPO / "benchmarks" / "results" / "free_error.jsonl"
    for run in args.runs:
        if not (run / "fit.json").is_file():
            raise SystemExit(f"{run}: no fit.json (a run_suite.py run folder is needed)")
        info = json.loads((run / "fit.json").read_text())
        data = Path(info["dataset"])
        cfg = load_config(run / "config.yaml")
        snaps = sorted((run / "snapshots").glob("t*.pt"),
                       key=lambda p: float(p.name[1:].split("-")[0]))
        if not snaps:
            raise SystemExit(f"{run}: no snapshots/ (a run_suite.py run folder is needed)")
        snap = torch.load(snaps[-1], map_location="cpu", weights_only=True)
        field = build_field(cfg, snap["scene"])
        field.load_state_dict(snap["model"])
        field.update_step(int(snap["step"]), int(snap["total_steps"]))
        field.eval()
        box = crop_aabb(field.crop.cpu()).numpy().astype(np.float64)
        gt = trimesh.load(data / "gt_mesh.ply", force="mesh")
        mesh = extract_mesh(field, res=args.res, progress=False)
        fit_pts, faces = trimesh.sample.sample_surface(mesh, args.points, seed=0)
        normals = np.asarray(mesh.face_normals)[faces]
        true_pts, _ = trimesh.sample.sample_surface(gt, 2 * args.points, seed=1)
        dist = cKDTree(true_pts).query(fit_pts)[0]
        split = load_dataset(data)["train"]
        forms = {"convex": event_silhouettes(split, step=hull_view_step(split))}
        if args.close > 0:
            forms[f"closed-{args.close}"] = closed_silhouettes(split, args.close)
        for form, sil in forms.items():
            for votes in args.votes:
                hull = event_hull(split, box[:3], box[3:], cfg.loss.hull_resolution,
                                  min_votes=votes, silhouettes=sil)
                free = FreeSpace(hull)
                called = free.free(torch.tensor(fit_pts, dtype=torch.float32)).numpy()
                # one voxel inside the fit's surface: where the term's relu(-sdf) would act
                inward = fit_pts - hull.voxel * normals
                called_in = free.free(torch.tensor(inward, dtype=torch.float32)).numpy()
                carved = free.free(torch.tensor(true_pts, dtype=torch.float32)).numpy()
                bands = []
                for lo, hi in BANDS:
                    sel = (dist >= lo) & (dist < hi)
                    bands.append({"from": lo, "to": None if np.isinf(hi) else hi,
                                  "share": round(float(sel.mean()), 4),
                                  "free": round(float(called[sel].mean()), 4) if sel.any()
                                  else None,
                                  "free_voxel_inside": round(float(called_in[sel].mean()), 4)
                                  if sel.any() else None})
                line = {"when": dt.datetime.now().isoformat(timespec="seconds"),
                        "run": str(run), "scene": info.get("scene"), "step": int(snap["step"]),
                        "silhouettes": form, "votes": votes, "views": hull.n_views,
                        "box_free": round(free.free_fraction, 4),
                        "true_surface_free": round(float(carved.mean()), 5),
                        "bands": bands, "hull_loss_last_quarter": hull_loss_tail(run)}
                with open(out, "a") as f:
                    f.write(json.dumps(line) + "\n")
                far = bands[-1]
                print(f"{run.name} {form} votes {votes}: box free {line['box_free']:.3f}, "
                      f"true surface free {100 * line['true_surface_free']:.3f}%, fit surface "
                      f">= 0.02 from the truth {far['share']:.3f} (free {far['free']}, "
                      f"a voxel inside {far['free_voxel_inside']}), "
                      f"hull loss {line['hull_loss_last_quarter']}", flush=True)


if __name__ == "__main__":
    main()
