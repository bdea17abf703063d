"""Which parts of the ground truth a fit misses, and when: completeness per connected part.

For one scene and seed, the suite line of each preset given (as :mod:`pictures` picks them)
names its run folder and its dataset. Each ground-truth part (a connected component: a rod,
a wire, a base) is scored against the run's mesh with
:func:`hybridneus.evaluation.parts.part_completeness` (recall within 0.01 and mean distance,
in the ground truth's unit cube, as ``hybridneus eval --parts`` reports them). With
``--snapshots`` every snapshot the suite kept in the run (``snapshots/``, the points of its
Chamfer curve) is meshed as the suite meshes it and scored the same way, so a part that is
formed and then lost, or smooth and then lumpy, shows when.

    python benchmarks/part_errors.py gen-rods-1003451250 --commit 87a4086 --seed 1 \\
        --presets fast fast+grid.log2_table_size=19 --snapshots
"""

from __future__ import annotations

import argparse
from pathlib import Path

from pictures import add_line_arguments, lines_with_meshes


def run_meshes(line: dict, snapshots: bool, res: int) -> list[tuple[int, float, object]]:
    """(step, Chamfer, mesh) of the run's final mesh and, with ``snapshots``, of every
    snapshot before it, meshed and scored as the suite does (:mod:`suite_jobs`)."""
    import trimesh

    run = Path(line["run"])
    out = []
    if snapshots:
        import suite_jobs

        from hybridneus.config import load_config
        from hybridneus.data.dataset import read_camera_centres

        cfg = load_config(run / "config.yaml")
        dataset = Path(line["dataset"])
        gt = trimesh.load(dataset / "gt_mesh.ply", process=False)
        cameras = read_camera_centres(dataset / cfg.data.split)
        for path in suite_jobs.snapshots(run)[:-1]:
            field, snap = suite_jobs.load_snapshot(cfg, path)
            score, mesh = suite_jobs.score_field(field, gt, res, cameras)
            out.append((int(snap["step"]), score["chamfer"], mesh))
    final = trimesh.load(run / "mesh.ply", process=False)
    out.append((int(line.get("steps") or line.get("iters") or 0), line["chamfer"], final))
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    add_line_arguments(ap, "gen-rods-1003451250")
    ap.add_argument("--parts", type=int, default=12, help="the largest parts shown")
    ap.add_argument("--snapshots", action="store_true",
                    help="also score the run's snapshots (the points of its Chamfer curve)")
    args = ap.parse_args(argv)
    import trimesh

    from hybridneus.evaluation.parts import part_completeness

    picked = lines_with_meshes(args)
    print("| preset | step | Chamfer | part | extents | recall | mean distance |")
    print("|---|---|---|---|---|---|---|")
    for line in picked:
        gt = trimesh.load(Path(line["dataset"]) / "gt_mesh.ply", process=False)
        for step, chamfer, mesh in run_meshes(line, args.snapshots, line.get("res", 300)):
            for part in part_completeness(mesh, gt)[:args.parts]:
                extents = " x ".join(f"{e:.3f}" for e in part.extents)
                print(f"| {line['preset']} | {step} | {chamfer:.4f} | {part.index} | {extents} "
                      f"| {part.recall:.2f} | {part.completeness:.4f} |", flush=True)


if __name__ == "__main__":
    main()
