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
    python benchmarks/pictures.py gen-slab-384259586 --commit bcf44df 75609bd --seed 2 \\
        --presets fast --out docs/images/slab-before-after.png

``--ungrouped`` puts the same field's mesh with the floater filter judging each component
alone (the clean-up before ``component_gap``; the line's ``chamfer_ungrouped``) above each
block: a before/after of that clean-up step with no training noise between them. The suite
keeps that mesh as ``mesh_ungrouped.ply``; for a run scored before it did, it is made again
from the run's last snapshot, the way the suite made it.
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


def add_line_arguments(ap: argparse.ArgumentParser, example: str) -> None:
    """The arguments that name the suite lines of one scene, seed and commit, one line per
    preset: ``scene``, ``--presets``, ``--commit``, ``--seed``, ``--results``."""
    ap.add_argument("scene", help=f"scene name as in the lines (e.g. {example})")
    ap.add_argument("--presets", nargs="+", required=True)
    ap.add_argument("--commit", default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--results", type=Path, default=common.RESULTS / "suite.jsonl")


def lines_with_meshes(args: argparse.Namespace) -> list[dict]:
    """The lines :func:`add_line_arguments`' ``args`` name (:func:`pick_lines`), each of whose
    run folders holds its ``mesh.ply``.

    Raises:
        SystemExit: a line is missing, or its run folder has no mesh here.
    """
    picked = pick_lines(common.read_lines(args.results), args.scene, args.presets,
                        args.commit, args.seed)
    for line in picked:
        if not (Path(line["run"]) / "mesh.ply").is_file():
            raise SystemExit(f"{Path(line['run']) / 'mesh.ply'}: missing (the run folders "
                             "are on the machine that ran the fits)")
    return picked


def budget_text(line: dict) -> str:
    """A suite line's budget as captions write it: ``15 min`` or ``2000 steps``, and where
    the mesh spans the crop's box (``"volume": "crop"``), ``2000 steps, res 300 over the
    crop``."""
    budget = common.budget_label(line)
    if common.meshed_over_crop(line):
        budget += f", res {line.get('res', 300)} over the crop"
    return budget


def caption(line: dict, ungrouped: bool = False) -> str:
    budget = budget_text(line)
    preset = line["preset"] + (", components judged alone" if ungrouped else "")
    cd = line["chamfer_ungrouped"] if ungrouped else line["chamfer"]
    return (f"{preset} | {line['commit']} | {budget} | seed {line['seed']} | "
            f"Chamfer {cd:.4f}")


def ungrouped_mesh(line: dict) -> Path:
    """The run's mesh with components judged alone (``component_gap`` 0), made again from its
    last snapshot as the suite made it when the run folder does not hold it yet."""
    run = Path(line["run"])
    path = run / "mesh_ungrouped.ply"
    if path.is_file():
        return path
    if "chamfer_ungrouped" not in line:
        raise SystemExit(f"pictures: {run}: its line was scored without chamfer_ungrouped")
    import suite_jobs

    from hybridneus.config import load_config
    from hybridneus.data.dataset import read_camera_centres
    from hybridneus.meshing import DEFAULT_BOUNDS, PostprocessOptions, extract_mesh
    from hybridneus.meshing.convert import save_mesh

    snaps = suite_jobs.snapshots(run)
    if not snaps:
        raise SystemExit(f"pictures: {run}: no snapshots/ to mesh again")
    cfg = load_config(run / "config.yaml")
    field, _ = suite_jobs.load_snapshot(cfg, snaps[-1])
    cameras = read_camera_centres(Path(line["dataset"]) / cfg.data.split)
    # over the volume the line was scored on: lines without "volume" meshed the whole cube
    volume = {} if common.meshed_over_crop(line) else {"bounds": DEFAULT_BOUNDS}
    mesh = extract_mesh(field, res=int(line["res"]), progress=False, cameras=cameras,
                        postprocess=PostprocessOptions(component_gap=0.0), **volume)
    save_mesh(mesh, path)
    return path


def picture(lines: list[dict], vmax: float, size: int, ungrouped: bool = False) -> np.ndarray:
    """The error images of ``lines``' meshes, one block each under its caption (with
    ``ungrouped``, the same field's mesh with components judged alone above each)."""
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
        gt = trimesh.load(gt_path, force="mesh")
        meshes = [(ungrouped_mesh(line), True)] if ungrouped else []
        for path, alone in [*meshes, (mesh_path, False)]:
            image = error_image(trimesh.load(path, force="mesh"), gt, vmax=vmax, size=size)
            title = np.full((26, image.shape[1], 3), 235, np.uint8)
            cv2.putText(title, caption(line, alone), (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                        (0, 0, 0), 1, cv2.LINE_AA)
            blocks += [title, image]
    return np.concatenate(blocks, axis=0)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scene", help="scene name as in the lines (e.g. gen-cage-56731231)")
    ap.add_argument("--presets", nargs="+", required=True, help="one block per preset")
    ap.add_argument("--commit", nargs="+", default=[None],
                    help="only lines of this commit (default: the newest); several: a block "
                    "per commit and preset, commits first (a before and after)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--results", type=Path, default=common.RESULTS / "suite.jsonl")
    ap.add_argument("--vmax", type=float, default=0.02, help="distance drawn in full red")
    ap.add_argument("--size", type=int, default=256, help="pixels per view")
    ap.add_argument("--out", type=Path, required=True, help="PNG to write")
    ap.add_argument("--ungrouped", action="store_true",
                    help="also the same fields' meshes with components judged alone (before)")
    args = ap.parse_args(argv)

    from PIL import Image

    from hybridneus.fileio import atomic_path

    results = common.read_lines(args.results)
    lines = [line for commit in args.commit
             for line in pick_lines(results, args.scene, args.presets, commit, args.seed)]
    image = picture(lines, args.vmax, args.size, args.ungrouped)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(args.out, suffix=".png") as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
    print(f"pictures: {args.out} ({', '.join(caption(r) for r in lines)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
