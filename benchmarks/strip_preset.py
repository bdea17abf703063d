"""Make a copy of simulated datasets that reads like data from elsewhere: no scene.json preset.

A dataset from ``hybridneus simulate`` carries its threshold, tonemap eps and crop in
``scene.json``; data made by another generator carries none, and the reader falls back to
the ``nerf`` group's values. The copy links ``train/``, ``test/`` and ``gt_mesh.ply`` and
rewrites ``scene.json`` without its ``preset`` (the suite still finds the ground truth), so
``run_suite.py --cache DST`` fits what such a user would get::

    python benchmarks/strip_preset.py /tmp/hybridneus-bench /tmp/hb-nopreset bunny xylophone
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

from hybridneus.fileio import atomic_dir


def strip(src: Path, dst: Path) -> None:
    """Write ``dst`` as a linked copy of ``src`` without the preset (an existing ``dst`` is
    replaced only once the copy is complete)."""
    meta = json.loads((src / "scene.json").read_text())
    meta.pop("preset", None)
    with atomic_dir(dst) as tmp:
        for name in ("train", "test", "validation", "gt_mesh.ply"):
            if (src / name).exists():
                os.symlink((src / name).resolve(), tmp / name)
        (tmp / "scene.json").write_text(json.dumps(meta, indent=1))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("src", type=Path, help="the suite's cache (datasets with scene.json)")
    ap.add_argument("dst", type=Path, help="folder for the copies")
    ap.add_argument("scenes", nargs="+", help="scene names, e.g. bunny xylophone")
    ap.add_argument("--tag", default="999v-346x260-t8", help="the cache's dataset suffix")
    args = ap.parse_args()
    for scene in args.scenes:
        name = f"{scene}-{args.tag}"
        if not (args.src / name / "scene.json").is_file():
            print(f"{args.src / name}: no scene.json (simulate it with run_suite.py first)",
                  file=sys.stderr)
            return 1
        strip(args.src / name, args.dst / name)
        print(args.dst / name)
    return 0


if __name__ == "__main__":
    sys.exit(main())
