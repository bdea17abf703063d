"""benchmarks/run_suite.py: fitting on one machine, scoring on another; its results file."""

from __future__ import annotations

import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

from conftest import TINY_FIT, TINY_SIZE

SUITE = Path(__file__).resolve().parents[1] / "benchmarks" / "run_suite.py"


def _suite_module():
    spec = importlib.util.spec_from_file_location("run_suite", SUITE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run(*args: str) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, str(SUITE), *args], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc


def test_fit_only_then_score_runs_elsewhere(tiny_scene, tmp_path):
    """A run fitted with --fit-only is scored from its own files after moving machines."""
    width, height = TINY_SIZE
    cache = tmp_path / "cache"
    tag = f"device-8v-{width}x{height}-t3"
    shutil.copytree(tiny_scene / "device", cache / tag)
    sets = [a for o in TINY_FIT if not o.startswith("train.iters") for a in ("--set", o)]
    common = ["--views", "8", "--width", str(width), "--height", str(height),
              "--test-views", "3", "--res", "24", "--curve", "2"]
    _run("--fit-only", "--scenes", "device", "--assets", str(tmp_path / "no-assets"),
         "--cache", str(cache), "--out-runs", str(tmp_path / "runs"), "--minutes", "0.02",
         "--presets", "fast", "--out", str(tmp_path / "unused.jsonl"), *common, *sets)
    assert not (tmp_path / "unused.jsonl").exists()  # --fit-only records nothing
    (run,) = [p for p in (tmp_path / "runs").iterdir() if p.name.startswith(tag)]
    # The end, and the middle of the budget unless one step outlasted it (a loaded machine).
    snapshots = sorted((run / "snapshots").glob("t*.pt"))
    assert 1 <= len(snapshots) <= 2

    # Another machine: the dataset path recorded there does not exist here.
    moved = tmp_path / "elsewhere" / run.name
    shutil.copytree(run, moved, ignore=shutil.ignore_patterns("checkpoints", "tb"))
    info = json.loads((moved / "fit.json").read_text())
    info["dataset"] = f"/nonexistent/{tag}"
    (moved / "fit.json").write_text(json.dumps(info))
    results = tmp_path / "suite.jsonl"
    proc = _run("--score-runs", str(moved), "--cache", str(cache), "--out", str(results),
                "--plots", str(tmp_path / "plots"), "--res", "24", "--image-views", "1")

    (line,) = [json.loads(x) for x in results.read_text().splitlines()]
    assert line["device"] == "cpu" and line["scene"] == "device"
    assert line["preset"] == " ".join(["fast", *sets[1::2]])  # a variant is named apart
    assert line["curve"][0][:2] == [0.0, 0] and len(line["curve"]) == 1 + len(snapshots)
    assert line["curve"][-1][1] == line["steps"] > 0
    assert line["curve"][0][2] is not None  # the untrained sphere meshes and scores
    assert (moved / "mesh.ply").is_file() == (line["chamfer"] is not None)
    assert "chamfer_unfilled" in line  # scored with and without the unseen pockets filled
    assert "| device | fast" in proc.stdout  # the report table follows the scoring


def test_results_keep_devices_and_variants_apart(tmp_path):
    suite = _suite_module()
    base = {"scene": "s", "minutes": 2.0, "noise": [0.0, 0.0], "steps": 10, "chamfer": 0.02,
            "fit_s": 120.0, "curve": [[0.0, 0, 0.2], [120.0, 10, 0.02]]}
    lines = [
        {**base, "preset": "fast", "device": "cpu"},
        {**base, "preset": "fast", "device": "cuda", "chamfer": 0.015},
        {**base, "preset": "fast train.n_rays=1024", "device": "cuda"},
        {**base, "preset": "fast", "device": "cpu", "chamfer": 0.01},  # a later cpu run
    ]
    path = tmp_path / "r.jsonl"
    path.write_text("".join(json.dumps(x) + "\n" for x in lines))
    got = {(r["preset"], r["device"]): r["chamfer"] for r in suite.read_results(path)}
    assert got == {("fast", "cpu"): 0.01, ("fast", "cuda"): 0.015,
                   ("fast train.n_rays=1024", "cuda"): 0.02}
    assert suite.preset_spec("fast-rgb") == ("fast", ["train.supervision=rgb"])


def test_gpu_pack_carries_what_a_fit_reads_and_unpacks_returned_runs(tiny_scene, tmp_path):
    """benchmarks/gpu_pack.py: the packed copy loads as the same dataset (events identical,
    compressed, no frames); the flat files a GPU session returns become a run folder again."""
    import tarfile

    import numpy as np

    from hybridneus.data import load_dataset

    spec = importlib.util.spec_from_file_location("gpu_pack", SUITE.parent / "gpu_pack.py")
    gpu_pack = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gpu_pack)

    assert gpu_pack.pack(tiny_scene / "device", tmp_path / "carry") > 0
    packed = tmp_path / "carry" / "device"
    assert not (packed / "train" / "rgb").exists() and not (packed / "test").exists()
    a, b = load_dataset(tiny_scene / "device")["train"], load_dataset(packed)["train"]
    assert a.n_views == b.n_views
    for name in ("x", "y", "t", "p"):
        assert np.array_equal(getattr(a.events, name), getattr(b.events, name))
    np.testing.assert_array_equal(a.c2w, b.c2w)

    flat = tmp_path / "returned"
    flat.mkdir()
    small = tmp_path / "small"
    small.mkdir()
    for name in ("fit.json", "config.yaml", "metrics.csv"):
        (small / name).write_text(name)
    with tarfile.open(flat / "scene-1.tar", "w") as tar:
        for name in ("fit.json", "config.yaml", "metrics.csv"):
            tar.add(small / name, arcname=name)
    (flat / "scene-1.t00060.0-s9.pt").write_bytes(b"snapshot")
    (run,) = gpu_pack.unpack(flat, tmp_path / "runs")
    assert (run / "fit.json").read_text() == "fit.json"
    assert (run / "snapshots" / "t00060.0-s9.pt").read_bytes() == b"snapshot"
