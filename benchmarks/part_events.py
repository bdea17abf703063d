"""Which parts of a generated object the events see: per part, the share of its surface that
lands on a firing pixel.

A part the camera's motion never moves across the pixels fires no events, and no fit can place
it. For each part of a ``generated:<kind>:<seed>`` dataset (in
:func:`hybridneus.simulate.generated.generated_parts`' order, moved into the dataset's frame by
its ``scene.json``), surface samples are projected into every ``--every``-th training view; a
sample counts as seen when a pixel within one pixel of it fired in the window from that view to
the next. There is no occlusion test: a sample behind another part counts too, for every part
alike. Views are split by the camera's elevation (above ``--level`` degrees, and level), since
a part may be seen only from one of them.

One line per dataset to ``benchmarks/results/part_events.jsonl``::

    python benchmarks/part_events.py /tmp/hybridneus-bench/gen-birdcage-35492827-999v-346x260-t8
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import common
import numpy as np


def part_samples(root: Path, n: int) -> tuple[str, list[np.ndarray], list[list[float]]]:
    """(source, world samples (n, 3) of each generated part, each part's extents) of a
    simulated dataset whose mesh was ``generated:<kind>:<seed>``."""
    import trimesh

    from hybridneus.simulate import generated

    scene = json.loads((root / "scene.json").read_text())
    source = str(scene.get("source_mesh", ""))
    if not source.startswith(generated.PREFIX):
        raise SystemExit(f"error: {root / 'scene.json'}: source_mesh {source!r} is not a "
                         "generated object (generated:<kind>:<seed>)")
    kind, seed = generated.parse_source(source)
    transform = scene["transform"]
    samples, extents = [], []
    for i, part in enumerate(generated.generated_parts(kind, seed)):
        # the simulator's own move of the source mesh into the dataset's frame
        mesh = part.transformed(transform["scale"], transform["translation"]).to_trimesh()
        samples.append(trimesh.sample.sample_surface(mesh, n, seed=i)[0])
        extents.append([round(float(e), 4) for e in mesh.extents])
    return source, samples, extents


def seen_shares(split, samples: list[np.ndarray], views: np.ndarray) -> np.ndarray:
    """(len(samples),) mean over ``views`` of the share of each part's samples within one
    pixel of a pixel that fired between the view and the next."""
    import torch
    from scipy.ndimage import binary_dilation

    from hybridneus.data.hull import project_to_pixels
    from hybridneus.data.windows import event_frame

    times = split.view_times
    points = [torch.as_tensor(s, dtype=torch.float32) for s in samples]
    total = np.zeros(len(samples))
    for v in views:
        fired = binary_dilation(event_frame(split, times[v], times[v + 1]) != 0, iterations=1)
        for i, pts in enumerate(points):
            u, row, front = project_to_pixels(split, int(v), pts)
            ok = (front & (u >= 0) & (u < split.width) & (row >= 0) & (row < split.height)).numpy()
            if ok.any():
                total[i] += fired[row.numpy()[ok], u.numpy()[ok]].mean()
    return total / max(len(views), 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dataset", type=Path, help="a dataset simulated from a generated object")
    ap.add_argument("--samples", type=int, default=600, help="surface samples per part")
    ap.add_argument("--every", type=int, default=7, help="use every n-th training view")
    ap.add_argument("--level", type=float, default=5.0,
                    help="views at most this many degrees above the object's centre are level")
    common.add_arguments(ap, "part_events")
    args = ap.parse_args()
    common.check_tree(args)
    common.require_dataset(args.dataset)
    from hybridneus.data import load_dataset

    source, samples, extents = part_samples(args.dataset, args.samples)
    split = load_dataset(args.dataset)["train"]
    centres = split.c2w[:, :3, 3]
    elevation = np.degrees(np.arcsin(centres[:, 1] / np.linalg.norm(centres, axis=1)))
    views = np.arange(0, split.n_views - 1, args.every)
    high, level = views[elevation[views] > args.level], views[elevation[views] <= args.level]
    line = {"bench": "part_events", **common.stamp(None), "dataset": args.dataset.name,
            "source": source, "extents": extents, "level_deg": args.level,
            "views_high": len(high), "views_level": len(level),
            "seen_high": [round(float(s), 3) for s in seen_shares(split, samples, high)],
            "seen_level": [round(float(s), 3) for s in seen_shares(split, samples, level)]}
    common.append(args.out, line)
    for i, e in enumerate(extents):
        print(f"part {i:2d} extents {e}: seen {line['seen_high'][i]:.2f} from {len(high)} high "
              f"views, {line['seen_level'][i]:.2f} from {len(level)} level ones")


if __name__ == "__main__":
    main()
