"""How much of the object's solid the field holds in a fit's first steps, and where.

A fit starts from a sphere and carves it. A part no event shows (a plate of the background's
brightness, the inside of a thin slab) is carved with the empty space around it or kept,
depending on what the field does in its opening steps. This runs the first steps of a
``--iters`` schedule (deterministic on a CPU) and, at each of ``--at``, records the share of
the ground truth's solid interior where the field's SDF is negative (``held``) and the share
of the space around the object, within the ground truth's box grown by a fifth, where it is
negative outside the solid (``extra``). It draws a picture per variant: for each step a slice
through the ground truth's centre across its thinnest axis (top) and one along it (bottom),
the ground truth's solid in light grey, the field's inside in black.

    python benchmarks/bench_carving.py /tmp/hybridneus-bench/gen-slab-384259586-999v-346x260-t8 \\
        --at 150 300 600 1000 --variants train.warmup=0.1 \\
        train.warmup=0.1+priors.hull.enabled=false --image /tmp/carving.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import common
import numpy as np


def _slices(lo: np.ndarray, hi: np.ndarray, n: int = 160) -> tuple[np.ndarray, ...]:
    """Two (h, w, 3) point grids through the box's centre: across its thinnest axis (a plane
    spanned by the other two) and along it (spanned by the thinnest and the longest)."""
    c, ext = (lo + hi) / 2, hi - lo
    thin, long_ = int(np.argmin(ext)), int(np.argmax(ext))
    other = 3 - thin - long_

    def plane(a: int, b: int) -> np.ndarray:
        half = 0.6 * ext.max()  # a margin around the object
        ua = np.linspace(c[a] - half, c[a] + half, n)
        ub = np.linspace(c[b] - half, c[b] + half, n)
        B, A = np.meshgrid(ub, ua, indexing="ij")
        pts = np.broadcast_to(c, (n, n, 3)).copy()
        pts[..., a], pts[..., b] = A, B
        return pts[::-1]  # rows from the top

    return plane(long_, other), plane(long_, thin)


def opening(dataset: Path, seed: int, at: list[int], iters: int, overrides: list[str],
            threads: int) -> tuple[list[dict], list[np.ndarray]]:
    """Run the opening of a ``fast`` fit; per step in ``at`` what it held, and its slices."""
    import torch
    import trimesh
    from bench_early import opening_config, run_opening

    from hybridneus.evaluation.inside import inside_mask

    gt = trimesh.load(dataset / "gt_mesh.ply", force="mesh")
    lo, hi = gt.bounds
    grow = (hi - lo) * 0.1
    rng = np.random.default_rng(0)
    probe = rng.uniform(lo - grow, hi + grow, size=(100_000, 3))
    solid = inside_mask(gt, probe)
    planes = _slices(lo, hi)
    plane_solid = [inside_mask(gt, p.reshape(-1, 3)).reshape(p.shape[:2]) for p in planes]
    rows, pictures = [], []

    def record(trainer, logs) -> None:
        if trainer.step in at:
            with torch.no_grad():
                sdf = trainer.field.sdf(torch.as_tensor(probe, dtype=torch.float32)).numpy()
                inside = [trainer.field.sdf(torch.as_tensor(p.reshape(-1, 3),
                                                            dtype=torch.float32)).numpy() < 0
                          for p in planes]
            rows.append({"step": trainer.step, "held": round(float((sdf[solid] < 0).mean()), 4),
                         "extra": round(float((sdf[~solid] < 0).mean()), 4),
                         "inv_s": round(float(logs["inv_s"]), 1),
                         "restores": int(logs.get("restores", 0))})
            column = []
            for mask, gt_in in zip(inside, plane_solid, strict=True):
                img = np.full(gt_in.shape, 255, np.uint8)
                img[gt_in] = 200
                img[mask.reshape(gt_in.shape)] = 0
                column += [img, np.full((4, img.shape[1]), 128, np.uint8)]
            pictures.append(np.concatenate(column[:-1], 0))

    run_opening(dataset, opening_config(seed, iters, threads, overrides), max(at), record)
    return rows, pictures


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dataset", type=Path)
    ap.add_argument("--at", type=int, nargs="+", default=[150, 300, 600, 1000],
                    help="steps at which to look")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--iters", type=int, default=4500,
                    help="the schedule's length (about a 15-minute fit on a 2-core CPU)")
    ap.add_argument("--variants", nargs="+", default=[""],
                    help="config overrides, KEY=VALUE[+KEY=VALUE...]; '' is the preset")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--image", type=Path, help="PNG of the slices, one row per variant")
    common.add_arguments(ap, "carving")
    args = ap.parse_args()
    common.check_tree(args)
    if not (args.dataset / "gt_mesh.ply").is_file():
        raise SystemExit(f"error: {args.dataset}: no gt_mesh.ply (a simulated dataset needed)")
    at = sorted(set(args.at))
    strips = []
    for variant in args.variants:
        overrides = [o for o in variant.split("+") if o]
        rows, pictures = opening(args.dataset, args.seed, at, args.iters, overrides,
                                 args.threads)
        print(f"{variant or 'fast'}: " + ", ".join(
            f"step {r['step']} held {r['held']:.2f} extra {r['extra']:.3f}" for r in rows))
        common.append(args.out, {
            "bench": "carving", "dataset": args.dataset.name, "variant": variant or "fast",
            "seed": args.seed, "iters": args.iters,
            **{key: [r[key] for r in rows] for key in ("step", "held", "extra", "inv_s",
                                                        "restores")},
            **common.stamp(args.threads)})
        gap = [np.full((pictures[0].shape[0], 6), 128, np.uint8)]
        strips.append(np.concatenate(sum(([p] + gap for p in pictures), [])[:-1], 1))
    if args.image is not None and strips:
        from PIL import Image

        width = max(s.shape[1] for s in strips)
        rows = [np.pad(s, ((0, 10), (0, width - s.shape[1])), constant_values=128)
                for s in strips]
        Image.fromarray(np.concatenate(rows, 0)).save(args.image)


if __name__ == "__main__":
    main()
