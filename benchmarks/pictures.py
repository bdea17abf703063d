"""Where the error is, as pictures for the docs: a scene's fits under several presets, each
mesh beside its ground truth, coloured by surface distance (:mod:`hybridneus.evaluation.error_map`).

A picture is made from suite result lines, never from loose meshes, so the figures in its
captions have their lines, commit and command: for one scene and seed, the line of each preset
given (in that order) names its run folder, which holds the mesh it was scored on
(``mesh.ply``), and its dataset, which holds the ground truth (``gt_mesh.ply``). The run
folders live where the suite wrote them (``--out-runs``), so make pictures on the machine that
ran the fits.

    python benchmarks/pictures.py gen-cage-56731231 --commit 3bc7531 \\
        --presets fast "fast priors.hull.enabled=false" --out docs/images/cage.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import common
import numpy as np


def pick_lines(lines: list[dict], scene: str, presets: list[str], commit: str | None,
               seed: int) -> list[dict]:
    """The newest clean line of ``scene`` and ``seed`` for each preset, in ``presets``' order.

    Raises:
        SystemExit: a preset has no such line.
    """
    picked = []
    for preset in presets:
        found = [r for r in lines if r.get("scene") == scene and r.get("preset") == preset
                 and r.get("seed") == seed and not r.get("dirty")
                 and (commit is None or r.get("commit") == commit)]
        if not found:
            at = f" at {commit}" if commit else ""
            raise SystemExit(f"pictures: no clean line of {scene} seed {seed} with preset "
                             f"{preset!r}{at}")
        picked.append(max(found, key=lambda r: r.get("date", "")))
    return picked


def caption(line: dict) -> str:
    budget = f"{line['minutes']:g} min" if line.get("minutes") else f"{line['iters']} steps"
    return (f"{line['preset']} | {line['commit']} | {budget} | seed {line['seed']} | "
            f"Chamfer {line['chamfer']:.4f}")


def picture(lines: list[dict], vmax: float, size: int) -> np.ndarray:
    """The error images of ``lines``' meshes, one block each under its caption."""
    import cv2
    import trimesh

    from hybridneus.evaluation.error_map import error_image

    blocks = []
    for line in lines:
        mesh_path = Path(line["run"]) / "mesh.ply"
        gt_path = Path(line["dataset"]) / "gt_mesh.ply"
        for path in (mesh_path, gt_path):
            if not path.is_file():
                raise SystemExit(f"pictures: {path}: missing (make pictures where the suite "
                                 "ran)")
        image = error_image(trimesh.load(mesh_path, force="mesh"),
                            trimesh.load(gt_path, force="mesh"), vmax=vmax, size=size)
        title = np.full((26, image.shape[1], 3), 235, np.uint8)
        cv2.putText(title, caption(line), (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1,
                    cv2.LINE_AA)
        blocks += [title, image]
    return np.concatenate(blocks, axis=0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", help="scene name as in the lines (e.g. gen-cage-56731231)")
    ap.add_argument("--presets", nargs="+", required=True, help="one block per preset")
    ap.add_argument("--commit", help="only lines of this commit (default: the newest)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--results", type=Path, default=common.RESULTS / "suite.jsonl")
    ap.add_argument("--vmax", type=float, default=0.02, help="distance drawn in full red")
    ap.add_argument("--size", type=int, default=256, help="pixels per view")
    ap.add_argument("--out", type=Path, required=True, help="PNG to write")
    args = ap.parse_args(argv)

    from PIL import Image

    from hybridneus.fileio import atomic_path

    lines = pick_lines(common.read_lines(args.results), args.scene, args.presets, args.commit,
                       args.seed)
    image = picture(lines, args.vmax, args.size)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out, suffix=".png") as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
    print(f"pictures: {args.out} ({', '.join(caption(r) for r in lines)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
