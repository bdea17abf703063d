"""Pack simulated datasets small enough to travel to a lent GPU machine (64 MiB in all).

A fit needs a dataset's ``scene.json`` and its training split's poses, intrinsics and events;
not the RGB frames, the test split or the ground-truth mesh (scoring happens back here, with
``run_suite.py --score-runs``, which finds the full dataset in the cache by name). Events are
re-saved with ``np.savez_compressed`` (the same arrays; about a third of the size), so two
full-size datasets fit one transfer.

    python benchmarks/gpu_pack.py --out gpu_carry /tmp/hybridneus-bench/bunny-999v-346x260-t8 \
        /tmp/hybridneus-bench/xylophone-999v-346x260-t8

Then, on the GPU machine, ``bash benchmarks/gpu_check.sh gpu_carry`` (``gpu_carry`` is
ignored by git and named in the run's ``carry``). What comes back (per run a tar of its small
files and its snapshots, flat, and the benchmarks' lines in ``gpu.jsonl``) is made run folders
again, scored, and added to ``benchmarks/results/`` with

    python benchmarks/gpu_pack.py --unpack FILES_AT --out RUNS
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
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


def unpack(files: Path, out: Path) -> list[Path]:
    """Run folders from ``gpu_check.sh``'s flat output: ``NAME.tar`` holds the small files,
    ``NAME.<snapshot>.pt`` the snapshots. Returns the run folders made under ``out``."""
    import tarfile

    runs = []
    for archive in sorted(files.glob("*.tar")):
        run = out / archive.stem
        (run / "snapshots").mkdir(parents=True, exist_ok=True)
        with tarfile.open(archive) as tar:
            tar.extractall(run, filter="data")
        for snap in files.glob(f"{archive.stem}.*.pt"):
            shutil.copy2(snap, run / "snapshots" / snap.name[len(archive.stem) + 1:])
        runs.append(run)
    return runs


def merge_lines(files: Path) -> int:
    """Add the returned ``gpu.jsonl`` lines to ``benchmarks/results/<bench>.jsonl``."""
    n = 0
    for line in common.read_lines(files / "gpu.jsonl"):
        common.append(common.RESULTS / f"{line['bench']}.jsonl", line)
        n += 1
    return n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("datasets", nargs="*", type=Path)
    ap.add_argument("--out", type=Path, default=Path("gpu_carry"))
    ap.add_argument("--unpack", type=Path, metavar="FILES",
                    help="make run folders under --out from gpu_check.sh's returned files, "
                    "score them and add every returned line to benchmarks/results/")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench"),
                    help="where the full datasets are (scoring needs their ground truth)")
    args = ap.parse_args()
    if args.unpack:
        runs = unpack(args.unpack, args.out)
        print(f"{merge_lines(args.unpack)} lines added to {common.RESULTS}")
        if runs:
            score = [sys.executable, str(Path(__file__).with_name("run_suite.py")),
                     "--score-runs", *map(str, runs), "--cache", str(args.cache)]
            if subprocess.run(score).returncode != 0:
                # run_suite has said why (a dirty tree, say); the runs stay for a second try
                raise SystemExit(f"error: {args.out}: runs unpacked but not scored; score them "
                                 f"with: python {' '.join(score[1:])}")
        return
    commit, dirty = common.git_state()
    if dirty:
        raise SystemExit(f"{common.REPO}: uncommitted changes; the GPU machine's lines must "
                         "name a commit")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "COMMIT").write_text(commit + "\n")
    total = 0
    for dataset in args.datasets:
        size = pack(dataset, args.out)
        total += size
        print(f"{args.out / dataset.name}: {size / 2**20:.1f} MiB")
    total += test_scenes(args.out / "test-scenes")
    print(f"total {total / 2**20:.1f} MiB (the transfer limit is 64 MiB with the working tree)")


def test_scenes(out: Path) -> int:
    """Simulate the GPU tests' scene here: the GPU machine has no Open3D to simulate it (the
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
