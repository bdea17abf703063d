"""What a mesh that lacks a part few views show can score at best: Chamfer floors.

A part that fires (almost) no event along the capture's path can hardly be told from empty
space by the event loss, and a fit that leaves it out is (nearly) as consistent with the data
as one that keeps it. This scores ideal meshes
that are exact but for such a part, built from the generator's own parts and scored against
the dataset's ground truth exactly as the suite scores a fit (the Chamfer of
``suite_jobs.score_field``):

- ``slab``: ``ring``, the body with the plate's footprint cut through it (what the fits keep:
  the band around the plate), and ``body``, the body without the plate (the plate only);
- ``cage``: ``no rings``, every part but the horizontal rings, and ``body``, the body alone;
- ``bowl``: ``lid``, the bowl's convex hull: its outer wall closed by a flat lid across the
  rim, which the views near the equator (most of the path) hardly tell from the hollow.

``exact`` scores the ground truth's parts themselves (the sampling's own floor).

With ``--meshed RES``, for any simulated dataset (assets too), the ground truth's own signed
distance goes through mesh extraction (marching cubes at ``RES`` points along the longest
side, the default clean-up) and is scored the same way: once over the whole cube [-1, 1]^3
and once over the ground truth's box grown by 2% (a crop's box is grown so, and is never
smaller). What the first loses and the second keeps is lost by the voxel size alone: a fit
meshed so cannot score below it, however exact its field.

    python benchmarks/bench_floor.py /tmp/hybridneus-bench/gen-slab-384259586-999v-346x260-t8
    python benchmarks/bench_floor.py /tmp/hybridneus-bench/gen-cage-56731231-999v-346x260-t8 \
        /tmp/hybridneus-bench/bunny-999v-346x260-t8 --meshed 300
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
    elif kind == "bowl":
        (bowl,) = parts
        out["lid"] = bowl.convex_hull
    else:
        raise SystemExit(f"error: bench_floor knows the slab, the cage and the bowl, not {kind}")
    return out


def in_world(meshes: list, tf: dict) -> list:
    """``meshes``, moved in place from the generator's units into the dataset's world by its
    ``scene.json`` transform (``world = source * scale + translation``)."""
    for mesh in meshes:
        mesh.apply_scale(tf["scale"])
        mesh.apply_translation(tf["translation"])
    return meshes


class TruthField:
    """The ground truth's signed distance as a field (``sdf`` only, what meshing reads).

    ``parts``: closed meshes in world units whose union is the object. Each part's distance
    is signed on its own and the union takes the least: parts overlap (a cage's rings cross
    its wires), where the ray parity of one concatenated mesh would call a point inside two
    parts outside.
    """

    def __init__(self, parts: list) -> None:
        import torch

        self.parts = parts
        self.device = torch.device("cpu")

    def sdf(self, points):
        import torch

        from hybridneus.evaluation.inside import signed_distance

        x = points.detach().cpu().numpy().astype(np.float64)
        d = np.min([signed_distance(m, x) for m in self.parts], axis=0)
        return torch.from_numpy(d.astype(np.float32))


def meshed_floors(field: TruthField, gt, res: int) -> dict:
    """``field`` meshed at ``res`` over the whole cube and over ``gt``'s box grown by 2%."""
    from hybridneus.meshing import DEFAULT_BOUNDS, extract_mesh

    lo, hi = (np.asarray(b, dtype=np.float64) for b in gt.bounds)
    pad = 0.02 * float((hi - lo).max())
    truth_box = (tuple(lo - pad), tuple(hi + pad))
    out = {}
    for name, bounds in ((f"meshed at res {res}, whole cube", DEFAULT_BOUNDS),
                         (f"meshed at res {res}, the truth's box", truth_box)):
        out[name] = extract_mesh(field, res=res, bounds=bounds, progress=False)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", type=Path, nargs="+", help="simulated dataset folders "
                    "(generated:slab, generated:cage and generated:bowl for the ideal meshes)")
    ap.add_argument("--meshed", type=int, metavar="RES", help="score the ground truth meshed "
                    "at this resolution instead of the ideal meshes")
    common.add_arguments(ap, "floor")
    args = ap.parse_args()
    common.check_tree(args)
    import trimesh

    from hybridneus.evaluation.geometry import chamfer_distance
    from hybridneus.simulate.generated import generated_parts, parse_source

    for folder in args.datasets:
        try:
            scene = json.loads((folder / "scene.json").read_text())
            tf = scene["transform"]
            source = str(scene.get("source_mesh", ""))
        except (OSError, ValueError, KeyError) as e:
            raise SystemExit(f"error: {folder / 'scene.json'}: not a simulated dataset ({e})"
                             ) from None
        if not (folder / "gt_mesh.ply").is_file():
            raise SystemExit(f"error: {folder}: no gt_mesh.ply")
        gt = trimesh.load(folder / "gt_mesh.ply", force="mesh")
        kind, seed = (parse_source(source) if source.startswith("generated:")
                      else (None, None))
        if args.meshed:
            parts = ([gt] if kind is None else
                     in_world([p.to_trimesh() for p in generated_parts(kind, seed)], tf))
            meshes = meshed_floors(TruthField(parts), gt, args.meshed)
        elif kind is None:
            raise SystemExit(f"error: {folder}: ideal meshes need a generated object; "
                             "--meshed RES scores any dataset")
        else:
            meshes = ideal_meshes(kind, seed)
            in_world(list(meshes.values()), tf)
        for name, mesh in meshes.items():
            cd = chamfer_distance(mesh, gt)
            print(f"{folder.name} {name}: Chamfer {cd.chamfer:.4f} (accuracy {cd.accuracy:.4f}, "
                  f"completeness {cd.completeness:.4f})", flush=True)
            common.append(args.out, {
                "bench": "floor", "dataset": folder.name, "kind": kind or "asset",
                "seed": seed, "mesh": name, "chamfer": round(cd.chamfer, 5),
                "accuracy": round(cd.accuracy, 5), "completeness": round(cd.completeness, 5),
                **common.stamp(None)})


if __name__ == "__main__":
    main()
