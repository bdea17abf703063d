"""What a mesh that lacks a part no event shows can score at best: Chamfer floors.

A part that fires no event cannot be told from empty space by the event loss, and a fit that
leaves it out is as consistent with the data as one that keeps it. This scores ideal meshes
that are exact but for such a part, built from the generator's own parts and scored against
the dataset's ground truth exactly as the suite scores a fit (``suite_jobs.score``'s Chamfer):

- ``slab``: ``ring``, the body with the plate's footprint cut through it (what the fits keep:
  the band around the plate), and ``body``, the body without the plate (the plate only);
- ``cage``: ``no rings``, every part but the horizontal rings, and ``body``, the body alone.

``exact`` scores the ground truth's parts themselves (the sampling's own floor).

    python benchmarks/bench_floor.py /tmp/hybridneus-bench/gen-slab-384259586-999v-346x260-t8
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import common
import numpy as np


def ideal_meshes(kind: str, seed: int) -> dict:
    """Named ideal meshes (trimesh, in the generator's units) for ``kind`` and ``seed``."""
    import trimesh

    from hybridneus.simulate.generated import generated_parts

    parts = [p.to_trimesh() for p in generated_parts(kind, seed)]
    out = {"exact": trimesh.util.concatenate(parts)}
    if kind == "slab":
        body, plate = parts
        (x0, y0, z0), (x1, y1, z1) = body.bounds
        (px0, _, pz0), (px1, _, pz1) = plate.bounds
        out["body"] = body
        out["ring"] = trimesh.util.concatenate([trimesh.creation.box(bounds=b) for b in (
            ((x0, y0, z0), (x1, y1, pz0)), ((x0, y0, pz1), (x1, y1, z1)),
            ((x0, y0, pz0), (px0, y1, pz1)), ((px1, y0, pz0), (x1, y1, pz1)))])
    elif kind == "cage":
        # rings lie flat: as wide as the cage along x and z, a wire's thickness along y
        upright = [p for p in parts
                   if float(np.ptp(p.vertices[:, 1])) >= 0.1 * float(np.ptp(p.vertices[:, 0]))]
        out["no rings"] = trimesh.util.concatenate(upright)
        out["body"] = parts[0]
    else:
        raise SystemExit(f"error: bench_floor knows the slab and the cage, not {kind}")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", type=Path, nargs="+", help="simulated generated:slab or "
                    "generated:cage dataset folders")
    common.add_arguments(ap, "floor")
    args = ap.parse_args()
    common.check_tree(args)
    import trimesh

    from hybridneus.evaluation.geometry import chamfer_distance
    from hybridneus.simulate.generated import parse_source

    for folder in args.datasets:
        try:
            scene = json.loads((folder / "scene.json").read_text())
            kind, seed = parse_source(scene.get("source_mesh", ""))
            tf = scene["transform"]
        except (OSError, ValueError, KeyError) as e:  # MeshError is a ValueError
            raise SystemExit(f"error: {folder / 'scene.json'}: not a simulated generated "
                             f"object ({e})") from None
        if not (folder / "gt_mesh.ply").is_file():
            raise SystemExit(f"error: {folder}: no gt_mesh.ply")
        gt = trimesh.load(folder / "gt_mesh.ply", force="mesh")
        for name, mesh in ideal_meshes(kind, seed).items():
            mesh.apply_scale(tf["scale"])
            mesh.apply_translation(tf["translation"])
            cd = chamfer_distance(mesh, gt)
            print(f"{folder.name} {name}: Chamfer {cd.chamfer:.4f} (accuracy {cd.accuracy:.4f}, "
                  f"completeness {cd.completeness:.4f})")
            common.append(args.out, {
                "bench": "floor", "dataset": folder.name, "kind": kind, "seed": seed,
                "mesh": name, "chamfer": round(cd.chamfer, 5),
                "accuracy": round(cd.accuracy, 5), "completeness": round(cd.completeness, 5),
                **common.stamp(None)})


if __name__ == "__main__":
    main()
