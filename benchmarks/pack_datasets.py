"""Copy what a fit reads of datasets, small, to a machine without network or without the
simulator's Open3D (a GPU host, a cluster node).

A fit needs a dataset's ``scene.json`` and its training split's poses, intrinsics and events;
not the RGB frames, the test split or the ground-truth mesh: scoring happens where the full
dataset is (``python benchmarks/run_suite.py --score-runs RUN... --cache CACHE`` finds it by
name). Events are re-saved with ``np.savez_compressed`` (the same arrays, about a third of
the size). ``--test-scenes`` also simulates the scene of the GPU tests, which read it from
``$HYBRIDNEUS_TEST_SCENES`` where they cannot simulate it. ``COMMIT`` names the commit, for
a copy of the tree without its git history (``HYBRIDNEUS_BENCH_COMMIT``).

    python benchmarks/pack_datasets.py --out carry --test-scenes \
        /tmp/hybridneus-bench/bunny-999v-346x260-t8
    # on the other machine, from a copy of this commit's tree:
    HYBRIDNEUS_BENCH_COMMIT=$(cat carry/COMMIT) HYBRIDNEUS_TEST_SCENES=$PWD/carry/test-scenes \
        bash benchmarks/gpu_check.sh carry/bunny-999v-346x260-t8
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

import common
import numpy as np

from hybridneus.fileio import atomic_dir


def pack(dataset: Path, out: Path) -> int:
    """Copy what a fit reads from ``dataset`` into ``out / dataset.name``; return its bytes."""
    if not (dataset / "scene.json").is_file():
        raise SystemExit(f"{dataset}: no scene.json (not a simulated dataset folder)")
    dst = out / dataset.name
    with atomic_dir(dst) as tmp:
        (tmp / "train" / "events").mkdir(parents=True)
        shutil.copy2(dataset / "scene.json", tmp / "scene.json")
        for sub in ("pose", "intrinsics"):
            shutil.copytree(dataset / "train" / sub, tmp / "train" / sub)
        for src in sorted((dataset / "train" / "events").iterdir()):
            dst_file = tmp / "train" / "events" / src.name
            if src.suffix == ".npz":
                with np.load(src) as z:
                    np.savez_compressed(dst_file, **{k: z[k] for k in z})
            else:
                shutil.copy2(src, dst_file)
    return sum(p.stat().st_size for p in dst.rglob("*") if p.is_file())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", nargs="*", type=Path)
    ap.add_argument("--out", type=Path, default=Path("carry"))
    ap.add_argument("--test-scenes", action="store_true",
                    help="also simulate the GPU tests' scene into OUT/test-scenes")
    args = ap.parse_args()
    commit, dirty = common.git_state()
    if dirty:
        raise SystemExit(f"error: {common.REPO}: uncommitted changes; the copied datasets "
                         "must name the commit that fits them")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "COMMIT").write_text(commit + "\n")
    total = 0
    for dataset in args.datasets:
        size = pack(dataset, args.out)
        total += size
        print(f"{args.out / dataset.name}: {size / 2**20:.1f} MiB")
    if args.test_scenes:
        total += test_scenes(args.out / "test-scenes")
    print(f"{args.out}: {total / 2**20:.1f} MiB in all")


def test_scenes(out: Path) -> int:
    """Simulate the GPU tests' scene here, for a machine without Open3D to simulate it (the
    tests copy it from ``$HYBRIDNEUS_TEST_SCENES``). Returns its bytes."""
    sys.path.insert(0, str(common.REPO / "tests"))
    from conftest import device_scene_name, simulate_device

    args = (40, 48, 36, 1.5)  # the ``scene`` fixture's
    dst = out / device_scene_name(*args)
    if not dst.is_dir():
        with atomic_dir(dst) as tmp:
            tmp.rmdir()
            simulate_device(tmp, *args)
    return sum(f.stat().st_size for f in dst.rglob("*") if f.is_file())


if __name__ == "__main__":
    main()
