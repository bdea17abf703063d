"""benchmarks/run_suite.py: fitting on one machine, scoring on another; its results file."""

from __future__ import annotations

import argparse
import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import TINY_FIT, TINY_SIZE

SUITE = Path(__file__).resolve().parents[1] / "benchmarks" / "run_suite.py"


def _suite_module():
    sys.path.insert(0, str(SUITE.parent))  # the benchmarks import their common module
    spec = importlib.util.spec_from_file_location("run_suite", SUITE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _run(*args: str) -> subprocess.CompletedProcess:
    proc = subprocess.run([sys.executable, str(SUITE), *args], capture_output=True, text=True,
                          timeout=600)
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
              "--test-views", "3", "--res", "24", "--curve", "2", "--allow-dirty"]
    _run("--fit-only", "--scenes", "device", "--assets", str(tmp_path / "no-assets"),
         "--cache", str(cache), "--out-runs", str(tmp_path / "runs"), "--iters", "6",
         "--seeds", "3", "--presets", "fast", "--out", str(tmp_path / "unused.jsonl"),
         *common, *sets)
    assert not (tmp_path / "unused.jsonl").exists()  # --fit-only records nothing
    (run,) = [p for p in (tmp_path / "runs").iterdir() if p.name.startswith(tag)]
    snapshots = sorted((run / "snapshots").glob("t*.pt"))
    assert [int(p.stem.split("-s")[1]) for p in snapshots] == [3, 6]  # halfway, the end

    # Another machine: the dataset path recorded there does not exist here.
    moved = tmp_path / "elsewhere" / run.name
    shutil.copytree(run, moved, ignore=shutil.ignore_patterns("checkpoints", "tb"))
    info = json.loads((moved / "fit.json").read_text())
    info["dataset"] = f"/nonexistent/{tag}"
    (moved / "fit.json").write_text(json.dumps(info))
    results = tmp_path / "suite.jsonl"
    _run("--score-runs", str(moved), "--cache", str(cache), "--out", str(results),
         "--res", "24", "--image-views", "1", "--allow-dirty")

    (line,) = [json.loads(x) for x in results.read_text().splitlines()]
    assert line["bench"] == "suite" and line["scene"] == "device" and line["seed"] == 3
    assert line["preset"] == " ".join(["fast", *sets[1::2]])  # a variant is named apart
    assert [c[1] for c in line["curve"]] == [3, 6] and line["steps"] == 6
    assert (moved / "mesh.ply").is_file() == (line["chamfer"] is not None)
    # scored with and without each mesh clean-up, and stamped
    assert {"chamfer_unfilled", "chamfer_cavities", "chamfer_ungrouped", "commit", "date",
            "machine"} <= set(line)
    # the command that fitted it, beside the one that scored it
    assert "--fit-only" in line["fit_command"] and "--score-runs" in line["command"]
    sys.path.insert(0, str(SUITE.parent))
    import common

    common.git_state.cache_clear()
    commit, dirty = common.git_state()  # a clean clone (CI) or a working tree with edits
    assert line["machine"]["device"] == "cpu"
    assert line["commit"] == commit and line["dirty"] is dirty


def test_the_generated_set_is_drawn_from_its_seed():
    suite = _suite_module()
    from hybridneus.simulate.generated import KINDS, generated_set

    a, b = generated_set(8, 1), generated_set(8, 2)
    assert [k for k, _ in a] == [KINDS[i % len(KINDS)] for i in range(8)]
    assert a == generated_set(8, 1) and a != b  # fresh shapes for a fresh seed
    assert suite.scene_name("generated:box:12") == "gen-box-12"
    assert suite.scene_name("bunny") == "bunny"


def test_another_camera_path_is_simulated_and_named_apart(tmp_path):
    suite = _suite_module()
    args = argparse.Namespace(views=12, width=32, height=24, test_views=0, noise=(0.0, 0.0),
                              cache=tmp_path, spiral="even")
    source = "generated:bowl:3"
    folder = suite.dataset_for(source, {}, args)
    assert folder.name.endswith("-even") and suite.suite_name(source, args) == "gen-bowl-3-even"
    assert json.loads((folder / "scene.json").read_text())["trajectory"] == "even"
    default = argparse.Namespace(**{**vars(args), "spiral": "seiffert"})
    assert suite.dataset_folder("gen-bowl-3", default) != folder
    assert suite.suite_name(source, default) == "gen-bowl-3"


def test_floor_meshes_leave_out_exactly_the_unseen_part():
    _suite_module()
    import bench_floor

    from hybridneus.evaluation.inside import inside_mask
    from hybridneus.simulate.generated import concatenate_parts, generated_parts, generated_scene

    parts = generated_parts("slab", 7)
    assert len(parts) == 2  # body, plate
    whole = concatenate_parts(parts)
    assert np.array_equal(whole.vertices, generated_scene("slab", 7).vertices)
    slab = bench_floor.ideal_meshes("slab", 7)
    body, plate = (p.to_trimesh() for p in parts)
    centre = plate.bounds.mean(axis=0) * np.array([1, 0, 1]) + body.bounds.mean(axis=0) * [0, 1, 0]
    edge = np.array([body.bounds[0, 0] + 1e-3, centre[1], centre[2]])
    assert inside_mask(slab["ring"], np.stack([centre, edge])).tolist() == [False, True]
    assert inside_mask(slab["body"], centre[None]).tolist() == [True]
    cage_parts = generated_parts("cage", 7)
    cage = bench_floor.ideal_meshes("cage", 7)
    rings = [p for p in cage_parts if np.ptp(p.vertices[:, 1]) < 0.05]
    assert 2 <= len(rings) <= 3  # the cage draws 2 or 3 rings
    kept = sum(len(p.faces) for p in cage_parts) - sum(len(p.faces) for p in rings)
    assert len(cage["no rings"].faces) == kept
    assert len(cage["body"].faces) == len(cage_parts[0].faces)
    (bowl,) = (p.to_trimesh() for p in generated_parts("bowl", 7))
    lid = bench_floor.ideal_meshes("bowl", 7)["lid"]
    (x0, y0, z0), (x1, y1, z1) = bowl.bounds
    hollow = np.array([[(x0 + x1) / 2, y1 - 0.02 * (y1 - y0), (z0 + z1) / 2]])  # opens to +y
    assert inside_mask(bowl, hollow).tolist() == [False]
    assert inside_mask(lid, hollow).tolist() == [True]
    assert np.allclose(lid.bounds, bowl.bounds)


def test_a_meshed_floor_loses_a_wire_thinner_than_the_whole_cube_voxel_only():
    """bench_floor --meshed: a wire 1.3 voxels of the whole cube wide (res 48) is lost there
    and kept over the truth's box, 4.5 times finer; a thick box is kept by both."""
    _suite_module()
    import bench_floor
    import trimesh

    voxel = 2.0 / 47
    wire = trimesh.creation.cylinder(radius=0.65 * voxel, height=0.4, sections=16)
    wire.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
    block = trimesh.creation.box(extents=(0.3, 0.1, 0.3))
    block.apply_translation((0.0, -0.25, 0.0))
    gt = trimesh.util.concatenate([wire, block])
    meshes = bench_floor.meshed_floors(bench_floor.TruthField([wire, block]), gt, 48)
    cube, box = (meshes[f"meshed at res 48, {v}"] for v in ("whole cube", "the truth's box"))
    assert box.bounds[1, 1] > 0.19 and cube.bounds[1, 1] < 0.0  # the wire's top, y = 0.2
    assert abs(cube.area - block.area) < 0.2 * block.area
    assert box.area > cube.area + 0.5 * wire.area


def test_preset_specs_name_a_preset_and_its_overrides():
    _suite_module()
    import suite_jobs

    assert suite_jobs.preset_spec("fast") == ("fast", [])
    assert suite_jobs.preset_spec("quality-rgb") == ("quality", ["train.supervision=rgb"])
    assert suite_jobs.preset_spec("fast+train.view_balance=1+priors.hull.enabled=false") == (
        "fast", ["train.view_balance=1", "priors.hull.enabled=false"])


def test_a_dirty_tree_is_refused_unless_told(monkeypatch):
    import argparse

    import pytest

    sys.path.insert(0, str(SUITE.parent))
    import common

    real = common.git_state
    monkeypatch.setenv(common.COMMIT_VARIABLE, "def5678")  # a copy without git history
    real.cache_clear()
    assert real() == ("def5678", False)
    monkeypatch.delenv(common.COMMIT_VARIABLE)
    real.cache_clear()
    monkeypatch.setattr(common, "git_state", lambda: ("abc1234", True))
    with pytest.raises(SystemExit, match="uncommitted changes"):
        common.check_tree(argparse.Namespace(allow_dirty=False))
    common.check_tree(argparse.Namespace(allow_dirty=True))


def test_commits_to_compare_are_named_by_git_or_refused_in_one_line():
    import pytest

    sys.path.insert(0, str(SUITE.parent))
    import common

    head = subprocess.run(["git", "-C", str(common.REPO), "rev-parse", "--short", "HEAD"],
                          capture_output=True, text=True)
    if head.returncode != 0:
        pytest.skip("not a git checkout")
    assert common.short_commit("HEAD") == head.stdout.strip()
    with pytest.raises(SystemExit, match="no-such-commit: not a commit"):
        common.short_commit("no-such-commit")


def test_the_report_pairs_two_commits_and_leaves_dirty_lines_out(tmp_path, monkeypatch):
    sys.path.insert(0, str(SUITE.parent))
    import common
    import report

    def line(commit, scene, seed, cd, dirty=False):
        return {"bench": "suite", "commit": commit, "dirty": dirty, "scene": scene, "seed": seed,
                "preset": "fast", "minutes": 15.0, "chamfer": cd, "fscore": 0.5, "steps": 9000,
                "fit_wall_s": 905.0, "date": "2026-11-26T10:00:00+00:00", "threads": 2,
                "machine": {"cpu": "cpu x"}, "command": "python benchmarks/run_suite.py"}

    lines = [line("aaa", "bunny", 0, 0.012), line("aaa", "bunny", 1, 0.014),
             line("bbb", "bunny", 0, 0.011), line("bbb", "bunny", 1, 0.013),
             line("bbb", "gen-box-3", 0, 0.02), line("ccc", "bunny", 0, 0.5, dirty=True)]
    monkeypatch.setattr(common, "RESULTS", tmp_path)
    (tmp_path / "suite.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    text = report.build([("aaa", "bbb")])
    assert "| bunny | fast | 15 min | 2 | 0.0130 | 0.0120-0.0140 | 0.0120 |" in text
    assert "-7.7%" in text and "commit ccc" not in text and "0.5000" not in text
    assert "| gen-box-3 | 1 | 0.0200 |" in text
    assert "| 9000 | 905 | - |" in text  # the longest wall time; no first-step time given


def test_gpu_pack_carries_what_a_fit_reads_and_unpacks_returned_runs(tiny_scene, tmp_path):
    """benchmarks/gpu_pack.py: the packed copy loads as the same dataset (events identical,
    compressed, no frames); the flat files a GPU check returns become a run folder again."""
    import tarfile

    import numpy as np

    from hybridneus.data import load_dataset

    sys.path.insert(0, str(SUITE.parent))
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
    for name in ("fit.json", "config.yaml", "scene.yaml", "metrics.csv"):
        (small / name).write_text(name)
    with tarfile.open(flat / "scene-1.tar", "w") as tar:
        for name in ("fit.json", "config.yaml", "scene.yaml", "metrics.csv"):
            tar.add(small / name, arcname=name)
    (flat / "scene-1.t00060.0-s9.pt").write_bytes(b"snapshot")
    (run,) = gpu_pack.unpack(flat, tmp_path / "runs")
    assert (run / "fit.json").read_text() == "fit.json"
    assert (run / "snapshots" / "t00060.0-s9.pt").read_bytes() == b"snapshot"


def test_docs_benchmarks_is_generated_from_the_result_lines():
    """Every figure in docs/benchmarks.md has its line: the page is the report's output."""
    sys.path.insert(0, str(SUITE.parent))
    import report

    flags = report.DOC.read_text().split("`python benchmarks/report.py", 1)[1].split("`", 1)[0]
    words = flags.split()
    pairs = {flag: [(words[i + 1], words[i + 2]) for i, w in enumerate(words) if w == flag]
             for flag in ("--compare", "--same-as")}
    assert report.DOC.read_text() == report.build(pairs["--compare"], pairs["--same-as"]), \
        "rerun python benchmarks/report.py"


def test_a_comparison_started_again_skips_the_fits_it_has(tmp_path):
    import argparse

    sys.path.insert(0, str(SUITE.parent))
    import common
    import compare_commits

    out = tmp_path / "suite.jsonl"
    args = argparse.Namespace(out=out, minutes=15.0, iters=None)
    assert compare_commits.done(args) == set()
    ours = {"bench": "suite", "commit": "abc1234", "scene": "bunny", "seed": 1, "minutes": 15.0,
            "volume": "crop",
            "command": "python benchmarks/compare_commits.py abc1234 def5678 (fits ...)"}
    common.append(out, ours)
    old_ruler = {**ours, "seed": 5}
    del old_ruler["volume"]  # meshed over the whole cube: not this comparison's score
    common.append(out, old_ruler)
    common.append(out, {**ours, "seed": 2, "minutes": 1.0})  # another comparison's length
    common.append(out, {**ours, "seed": 0, "command": "python benchmarks/run_suite.py"})
    assert compare_commits.done(args) == {("abc1234", "bunny", 1)}
    # a fixed schedule's comparison counts only the fits of its own length
    fixed = argparse.Namespace(out=out, minutes=15.0, iters=2000)
    assert compare_commits.done(fixed) == set()
    common.append(out, {**ours, "seed": 3, "minutes": None, "iters": 2000})
    common.append(out, {**ours, "seed": 4, "minutes": None, "iters": 4500})
    assert compare_commits.done(fixed) == {("abc1234", "bunny", 3)}
    assert compare_commits.done(args) == {("abc1234", "bunny", 1)}


def test_variants_are_set_beside_their_preset_on_the_same_seeds():
    sys.path.insert(0, str(SUITE.parent))
    import report

    base = {"commit": "abc1234", "iters": 2000, "threads": 1, "machine": {"cpu": "X"},
            "steps": 2000, "date": "2026-11-26T10:00:00+00:00", "command": "run_suite.py"}

    def line(preset, scene, seed, cd):
        return {**base, "preset": preset, "scene": scene, "seed": seed, "chamfer": cd}

    off, spec = "fast priors.hull.enabled=false", "fast+train.view_balance=1"
    lines = [line("fast", "bunny", 0, 0.010), line("fast", "bunny", 1, 0.012),
             line("fast", "gen-cage-1", 0, 0.05), line("fast", "gen-cage-1", 1, 0.06),
             line(off, "bunny", 0, 0.02), line(off, "gen-cage-1", 0, None),
             line(spec, "bunny", 0, 0.0105),
             {**line("fast priors.curvature.enabled=false", "toyTrain", 0, 0.01),
              "commit": "def5678"}]
    text = "\n".join(report.variant_section(lines))
    header = ("| scene | seeds | CD `fast` | range | `priors.hull.enabled=false` "
              "| `train.view_balance=1` |")
    assert header in text
    # seed 0 against seed 0; worse beyond the preset's range of 0.002
    assert "| bunny | 2 | 0.0110 | 0.0100-0.0120 | 0.0200 (+100% ! +) | 0.0105 (+5%) |" in text
    assert "| gen-cage-1 | 2 | 0.0550 | 0.0500-0.0600 | empty | - |" in text
    assert "1 scene; 1 empty fit besides" in text
    # a variant without its preset in the same run stays in the accuracy section
    assert "def5678" not in text
    assert "def5678" in "\n".join(report.suite_section(lines))
    assert "priors.hull" not in "\n".join(report.suite_section(lines))
    # a table of two suite calls (one per seed) names both
    lines += [{**line("fast", "slab", 5, 0.09), "command": "run_suite.py --seeds 5"},
              {**line(spec, "slab", 5, 0.03), "command": "run_suite.py --seeds 5"}]
    text = "\n".join(report.variant_section(lines))
    assert "Commands: `run_suite.py`; `run_suite.py --seeds 5`" in text


def test_an_older_commit_stands_in_only_where_it_fits_alike():
    sys.path.insert(0, str(SUITE.parent))
    import report

    base = {"iters": 2000, "threads": 1, "machine": {"cpu": "X"}, "steps": 2000,
            "date": "2026-11-26T10:00:00+00:00", "command": "run_suite.py"}

    def line(commit, preset, seed, cd):
        return {**base, "commit": commit, "preset": preset, "scene": "bunny", "seed": seed,
                "chamfer": cd}

    es = "fast+render.empty_share=0.25"
    lines = [line("old1234", "fast", 1, 0.010), line("old1234", "fast", 2, 0.012),
             line("old1234", "fast priors.hull.enabled=false", 2, 0.5),
             line("new5678", "fast", 1, 0.010), line("new5678", es, 1, 0.009),
             line("new5678", es, 2, 0.006)]
    # alone, the new commit's variant meets its preset on seed 1 only
    assert "| bunny | 1 | 0.0100 | - | 0.0090 (-10%) |" in "\n".join(
        report.variant_section(lines))
    text = "\n".join(report.variant_section(lines, [("old1234", "new5678")]))
    # the old preset fit of seed 2 joins (its variant fits do not), and the table says so
    assert "| bunny | 2 | 0.0110 | 0.0100-0.0120 | 0.0075 (-32% ! -) |" in text
    assert "`fast` fits of old1234 stand in where new5678 has none" in text
    assert "every fit made at both commits, 1 of them," in text
    # the old commit's variants stay in its own table
    ours = text.split("commit new5678")[1].split("###")[0]
    assert "priors.hull" not in ours and "priors.hull" in text
    # a fit both made that scores differently refuses the claim
    lines[3] = line("new5678", "fast", 1, 0.0101)
    with pytest.raises(SystemExit, match="do not fit alike"):
        report.variant_section(lines, [("old1234", "new5678")])
    with pytest.raises(SystemExit, match="no fit made at both"):
        report.variant_section(lines[:3] + lines[4:], [("old1234", "new5678")])


def test_the_kinds_with_few_events_get_their_own_mean():
    sys.path.insert(0, str(SUITE.parent))
    import report

    base = {"preset": "fast", "minutes": 15.0, "threads": 2, "machine": {"cpu": "X"},
            "steps": 100, "seed": 0, "fit_wall_s": 900.0, "date": "2026-11-26T10:00:00+00:00",
            "command": "run_suite.py"}
    lines = [{**base, "commit": c, "scene": s, "chamfer": cd}
             for c, s, cd in (("aaa", "gen-box-1", 0.02), ("bbb", "gen-box-1", 0.01),
                              ("aaa", "gen-blob-2", 0.01), ("bbb", "gen-blob-2", 0.01))]
    text = "\n".join(report.compare_section(lines, "aaa", "bbb"))
    assert "| **mean, generated** | | | | **0.0150** | | **0.0100** |" in text
    assert "| **mean, generated, box/slab/cage/rods** | | | | **0.0200** | | **0.0100** |" in text
    accuracy = "\n".join(report.suite_section(lines))
    assert "| **mean, generated, box/slab/cage/rods** | | **0.0100** |" in accuracy
    # the same fits scored over the crop: a budget, and means, of their own
    lines += [{**r, "volume": "crop", "chamfer": r["chamfer"] / 2} for r in lines]
    text = "\n".join(report.compare_section(lines, "aaa", "bbb"))
    assert "| gen-box-1 | fast | 15 min, meshed over the crop | 1 | 0.0100 |" in text
    assert "| **mean, generated, 15 min** | | | | **0.0150** | | **0.0100** |" in text
    assert ("| **mean, generated, 15 min, meshed over the crop** | | | | **0.0075** | | "
            "**0.0050** |") in text


def test_speed_tables_give_each_field_a_column():
    sys.path.insert(0, str(SUITE.parent))
    import report

    rows = [{"bench": "grids", "commit": "abc1234", "mode": "fwd", "rate": {"a": 1.5, "b": 2.0},
             "ok": True},
            {"bench": "grids", "commit": "abc1234", "mode": "eikonal", "rate": {"a": 0.25}}]
    header, _, first, second = report._table(rows)
    assert header == "| mode | rate a | rate b | ok |"
    assert first == "| fwd | 1.5 | 2 | yes |" and second == "| eikonal | 0.25 | - | - |"


def test_floors_of_several_runs_are_shown_together_the_newest_per_mesh():
    sys.path.insert(0, str(SUITE.parent))
    import report

    base = {"bench": "floor", "machine": {"cpu": "X"}, "threads": None, "kind": "cage",
            "seed": 1, "date": "2026-12-02T03:00:00+00:00"}
    rows = [{**base, "commit": "aaa", "command": "one", "dataset": "cage", "mesh": "cube",
             "chamfer": 0.03},
            {**base, "commit": "bbb", "command": "two", "dataset": "cage", "mesh": "cube",
             "chamfer": 0.025},
            {**base, "commit": "bbb", "command": "three", "dataset": "bunny", "mesh": "cube",
             "chamfer": 0.008}]
    text = "\n".join(report.speed_section({"floor": rows}))
    assert "commit bbb," in text and "| cage | 1 | cage | cube | 0.025 |" in text
    assert "0.03 |" not in text and "| cage | 1 | bunny | cube | 0.008 |" in text
    assert "Command: `two`" in text and "Command: `three`" in text


def test_readme_results_are_generated_from_one_commits_lines():
    sys.path.insert(0, str(SUITE.parent))
    import common
    import report

    lines = [r for r in common.read_lines(common.RESULTS / "suite.jsonl") if not r.get("dirty")]
    readme = report.README.read_text()
    assert readme == report.readme_text(readme, lines), "rerun benchmarks/report.py --readme"


def test_readme_block_rows_summarise_assets_and_generated_objects():
    sys.path.insert(0, str(SUITE.parent))
    import report

    base = {"commit": "abc1234", "preset": "fast", "minutes": 15.0, "threads": 2,
            "machine": {"cpu": "X"}, "steps": 100}
    lines = [{**base, "scene": "bunny", "seed": 0, "chamfer": 0.01},
             {**base, "scene": "bunny", "seed": 1, "chamfer": 0.03},
             {**base, "scene": "gen-box-7", "seed": 0, "chamfer": 0.05, "steps": 90},
             {**base, "scene": "bunny", "seed": 0, "chamfer": 0.5, "commit": "other"}]
    _, _, row = report.readme_block(lines, "abc1234")
    assert row == ("| `fast` | 15 min | X, 2 threads | 0.0200 (1 asset, 2 seeds) | "
                   "0.0500 (1 object, 1 seed) | 90-100 |")
    # a scene fitted with more seeds does not weigh more: (0.02 + 0.04) / 2, not 0.08 / 3
    lines.append({**base, "scene": "xylophone", "seed": 0, "chamfer": 0.04})
    _, _, row = report.readme_block(lines, "abc1234")
    assert "| 0.0300 (2 assets, 1-2 seeds) |" in row


def test_pictures_come_from_suite_lines(tmp_path):
    """benchmarks/pictures.py: one block per preset's line, in order, with its Chamfer."""
    import pytest
    import trimesh

    sys.path.insert(0, str(SUITE.parent))
    spec = importlib.util.spec_from_file_location("pictures", SUITE.parent / "pictures.py")
    pictures = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(pictures)
    data = tmp_path / "data"
    data.mkdir()
    trimesh.creation.box(extents=(0.5, 0.1, 0.4)).export(data / "gt_mesh.ply")
    lines = []
    for i, (preset, extents) in enumerate((("fast", (0.5, 0.16, 0.4)),
                                           ("fast+x=1", (0.5, 0.1, 0.4)))):
        run = tmp_path / f"run{i}"
        run.mkdir()
        trimesh.creation.box(extents=extents).export(run / "mesh.ply")
        lines.append({"scene": "slab", "preset": preset, "seed": 0, "commit": "abc1234",
                      "dirty": False, "date": f"2026-01-0{i + 1}", "iters": 100, "minutes": 0,
                      "chamfer": 0.02 - 0.01 * i, "run": str(run), "dataset": str(data)})
    stale = dict(lines[0], commit="0000000", chamfer=0.5)
    results = tmp_path / "suite.jsonl"
    results.write_text("".join(json.dumps(r) + "\n" for r in [stale, *lines]))
    picked = pictures.pick_lines(pictures.common.read_lines(results), "slab",
                                 ["fast+x=1", "fast"], "abc1234", 0)
    assert [r["preset"] for r in picked] == ["fast+x=1", "fast"]
    out = tmp_path / "pic.png"
    assert pictures.main(["slab", "--presets", "fast", "fast+x=1", "--commit", "abc1234",
                          "--results", str(results), "--size", "64", "--out", str(out)]) == 0
    from PIL import Image

    image = np.asarray(Image.open(out))
    single = pictures.picture(picked[:1], 0.02, 64)
    assert image.shape[0] == 2 * single.shape[0] and image.shape[1] == single.shape[1]
    # the thick slab's block shows error colours; the exact one's mesh row stays grey
    thick, exact = image[:single.shape[0]], image[single.shape[0]:]
    red = lambda im: int(((im[..., 0] > 150) & (im[..., 2] < 80)).sum())  # noqa: E731
    assert red(thick) > red(exact)
    # several commits: a block per commit (a before and after of one preset)
    older = dict(lines[1], commit="def5678", run=lines[0]["run"], date="2026-01-03")
    results.write_text("".join(json.dumps(r) + "\n" for r in [*lines, older]))
    assert pictures.main(["slab", "--presets", "fast+x=1", "--commit", "def5678", "abc1234",
                          "--results", str(results), "--size", "64", "--out", str(out)]) == 0
    image = np.asarray(Image.open(out))
    assert image.shape[0] == 2 * single.shape[0]
    assert red(image[:single.shape[0]]) > red(image[single.shape[0]:])
    with pytest.raises(SystemExit, match="no clean line of slab seed 0 with preset 'quality'"):
        pictures.pick_lines(lines, "slab", ["quality"], None, 0)
    # --ungrouped: the same field's mesh with components judged alone, above the default's
    trimesh.creation.box(extents=(0.5, 0.16, 0.4)).export(Path(lines[1]["run"])
                                                           / "mesh_ungrouped.ply")
    lines[1]["chamfer_ungrouped"] = 0.03
    both = pictures.picture(lines[1:], 0.02, 64, ungrouped=True)
    assert both.shape[0] == 2 * single.shape[0]
    assert red(both[:single.shape[0]]) > red(both[single.shape[0]:])
    assert pictures.caption(lines[1], True).endswith("judged alone | abc1234 | 100 steps | "
                                                     "seed 0 | Chamfer 0.0300")
    with pytest.raises(SystemExit, match="scored without chamfer_ungrouped"):
        pictures.picture(lines[:1], 0.02, 64, ungrouped=True)


def test_a_section_names_every_command_that_made_its_fits_once():
    sys.path.insert(0, str(SUITE.parent))
    import report

    base = {"preset": "fast", "minutes": 15.0, "threads": 2, "machine": {"cpu": "X"},
            "steps": 100, "fit_wall_s": 900.0, "date": "2026-11-26T10:00:00+00:00",
            "commit": "bbb", "chamfer": 0.01}
    compare = ("python benchmarks/compare_commits.py aaa bbb (fits with the commit's "
               "run_suite.py --scenes {} --seeds {})")
    lines = [{**base, "scene": s, "seed": k, "command": compare.format(s, k)}
             for s in ("bunny", "oakChair") for k in (0, 1)]
    lines.append({**base, "scene": "gen-box-1", "seed": 0,
                  "command": "python benchmarks/run_suite.py --generated 6"})
    text = "\n".join(report.suite_section(lines))
    assert ("5 fits, 2026-11-26 to 2026-11-26; commands: `python benchmarks/compare_commits.py "
            "aaa bbb`; `python benchmarks/run_suite.py --generated 6`") in text
    text = "\n".join(report.suite_section(lines[:2]))
    assert "; command: `python benchmarks/compare_commits.py aaa bbb`\n" in text


def test_clean_up_steps_are_set_beside_the_default_mesh_of_the_same_fits():
    sys.path.insert(0, str(SUITE.parent))
    import report

    base = {"preset": "fast", "minutes": 15.0, "threads": 2, "machine": {"cpu": "X"},
            "steps": 100, "fit_wall_s": 900.0, "date": "2026-11-26T10:00:00+00:00",
            "commit": "bbb", "command": "run_suite.py", "chamfer_unfilled": 0.02,
            "chamfer_cavities": 0.01}
    lines = [{**base, "scene": "gen-cage-1", "seed": k, "chamfer": 0.01,
              "chamfer_ungrouped": u} for k, u in ((0, 0.02), (1, 0.04))]
    lines.append({**base, "scene": "bunny", "seed": 0, "chamfer": 0.01})  # scored before
    text = "\n".join(report.cleanup_section(lines))
    assert "| gen-cage-1 | 2 | 0.0100 | 0.0300 | 0.0200 | 0.0100 |" in text
    assert "bunny" not in text  # its line lacks one of the steps
    assert report.cleanup_section(lines[2:]) == []


def test_curves_come_from_suite_lines_of_several_commits(tmp_path):
    """benchmarks/curves.py: one curve per COMMIT:PRESET line, side by side, from the run's
    metrics.csv; a spec without a line is refused by name."""
    import pytest

    sys.path.insert(0, str(SUITE.parent))
    spec = importlib.util.spec_from_file_location("curves", SUITE.parent / "curves.py")
    curves = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(curves)
    lines = []
    for i, commit in enumerate(("aaa1111", "bbb2222")):
        run = tmp_path / f"run{i}"
        run.mkdir()
        rows = ["step,loss/total,loss/event,inv_s,opacity"]
        rows += [f"{s},{1 / s},{0.5 / s},{20 * (1 + s) ** (2 + i)},0.8" for s in range(1, 60)]
        (run / "metrics.csv").write_text("\n".join(rows) + "\n")
        lines.append({"scene": "blob", "preset": "fast", "seed": 1, "commit": commit,
                      "dirty": False, "date": "2026-01-01", "minutes": 15, "steps": 59,
                      "total_steps": 59, "restores": i, "chamfer": 0.01 + i,
                      "run": str(run)})
    results = tmp_path / "suite.jsonl"
    results.write_text("".join(json.dumps(r) + "\n" for r in lines))
    out = tmp_path / "curves.png"
    assert curves.main(["blob", "--seed", "1", "bbb2222:fast", "aaa1111:fast", "--results",
                        str(results), "--out", str(out)]) == 0
    import cv2

    image = cv2.imread(str(out))
    one = curves.figure(lines[:1])
    assert image.shape[0] == one.shape[0] and image.shape[1] == 2 * one.shape[1]
    assert "1 restores | Chamfer 1.0100" in curves.caption(lines[1])
    with pytest.raises(SystemExit, match="no clean line of blob seed 1 with preset 'fast' at c"):
        curves.pick(lines, "blob", 1, "c:fast")
    with pytest.raises(SystemExit, match="expected COMMIT:PRESET"):
        curves.pick(lines, "blob", 1, "fast")


def test_a_trained_step_is_timed_on_a_copy_of_a_finished_run(tiny_scene):
    sys.path.insert(0, str(SUITE.parent))
    import bench_trained_step

    run = next(p for p in (tiny_scene / "runs").iterdir() if (p / "checkpoints").is_dir())
    before = sorted(str(p.relative_to(run)) for p in run.rglob("*"))
    threads, seconds, share = bench_trained_step.step_seconds(run, 2, None)
    assert threads >= 1 and 0 < seconds < 60 and 0.0 <= share < 0.01
    assert sorted(str(p.relative_to(run)) for p in run.rglob("*")) == before  # run untouched


def test_the_opening_of_a_fit_is_recorded_per_seed(tiny_scene, tmp_path):
    out = tmp_path / "early.jsonl"
    proc = subprocess.run([sys.executable, str(SUITE.with_name("bench_early.py")),
                           str(tiny_scene / "device"),
                           "--seeds", "0", "1", "--steps", "3", "--iters", "40", "--variants", "",
                           "priors.collapse_guard.enabled=false", "--allow-dirty", "--out",
                           str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert [line["variant"] for line in lines] == ["fast", "priors.collapse_guard.enabled=false"]
    for line in lines:
        assert line["seeds"] == 2 and len(line["restores"]) == 2 and line["steps"] == 3
        assert all(0.0 <= o <= 1.0 for o in line["occupied"])


def test_the_collapse_blames_the_part_whose_parameters_moved(tiny_scene, tmp_path):
    sys.path.insert(0, str(SUITE.parent))
    import bench_collapse
    import torch

    from hybridneus.api import prepare

    field = prepare(tiny_scene / "device", "fast", ["train.iters=2"], device="cpu")[0].field
    a = {k: v.clone() for k, v in field.state_dict().items()}
    b = {k: v.clone() for k, v in a.items()}
    last = max(k for k in b if k.startswith("sdf_net.") and k.endswith(".bias"))
    b[last][0] += 0.5  # the head's output bias lifts the whole SDF by 0.5
    points = bench_collapse.crop_points(tuple(float(v) for v in field.crop), 4000)
    base = bench_collapse.mixed(field, a, a, points)
    head = bench_collapse.mixed(field, a, b, points)
    grid = bench_collapse.mixed(field, b, a, points)
    assert torch.allclose(head - base, torch.full_like(base, 0.5), atol=1e-5)
    assert torch.equal(grid, base)
    out = tmp_path / "collapse.jsonl"
    proc = subprocess.run([sys.executable, str(SUITE.with_name("bench_collapse.py")),
                           str(tiny_scene / "device"), "--seed", "0", "--iters", "40",
                           "--at", "2", "4", "--allow-dirty", "--out", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    (line,) = [json.loads(x) for x in out.read_text().splitlines()]
    assert line["at"] == [2, 4] and 0.0 <= line["inside_at_a"] <= 1.0
    assert {"shift_head_from_b", "shift_grid_from_b", "inside_both_from_b"} <= line.keys()


def test_the_carving_of_a_fit_is_recorded_with_its_slices(tiny_scene, tmp_path):
    out, image = tmp_path / "carving.jsonl", tmp_path / "carving.png"
    proc = subprocess.run([sys.executable, str(SUITE.with_name("bench_carving.py")),
                           str(tiny_scene / "device"), "--at", "2", "4", "--iters", "40",
                           "--variants", "", "priors.hull.enabled=false", "--image", str(image),
                           "--allow-dirty", "--out", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert [line["variant"] for line in lines] == ["fast", "priors.hull.enabled=false"]
    for line in lines:
        assert line["step"] == [2, 4]
        assert all(0.0 <= v <= 1.0 for v in line["held"] + line["extra"])
    from PIL import Image

    # per variant a strip of two steps, each two 160-pixel slices with 4- and 6-pixel rules
    assert Image.open(image).size == (2 * 160 + 6, 2 * (2 * 160 + 4 + 10))


def test_face_errors_find_a_caved_face_and_its_side():
    import trimesh

    sys.path.insert(0, str(SUITE.parent))
    spec = importlib.util.spec_from_file_location("face_errors", SUITE.parent / "face_errors.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    gt = trimesh.creation.box((0.4, 0.4, 0.2))
    caved = trimesh.creation.box((0.4, 0.4, 0.2 - 0.03))  # the -z face 0.03 inside
    caved.apply_translation((0, 0, 0.015))
    rows = {r["face"]: r for r in module.face_errors(caved, gt, n_gt=4000, n_mesh=100000)}
    assert set(rows) == {"+x", "-x", "+y", "-y", "+z", "-z"}
    assert abs(rows["-z"]["median_signed"] + 0.03) < 0.003, rows["-z"]
    assert abs(rows["+z"]["median_signed"]) < 0.003, rows["+z"]


def test_the_rare_fill_closes_a_hole_that_only_few_views_see():
    from hybridneus.meshing import unseen as U
    from hybridneus.model.analytic import TorusField

    sys.path.insert(0, str(SUITE.parent))
    spec = importlib.util.spec_from_file_location("bench_rare_fill",
                                                  SUITE.parent / "bench_rare_fill.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    torus = TorusField(0.3, 0.12)  # lying flat: its hole looks up the y axis
    angles = np.linspace(0, 2 * np.pi, 95, endpoint=False)
    ring = np.stack([2 * np.cos(angles), np.zeros(95), 2 * np.sin(angles)], axis=1)
    above = np.array([[0.1 * i, 2.0, 0.05] for i in range(5)])
    cameras = np.concatenate([ring, above])  # 5% of the views look down into the hole
    bounds = ((-0.6, -0.6, -0.6), (0.6, 0.6, 0.6))
    base = U.unseen_space(torus, cameras, bounds, res=40)
    grid = base.grid

    def filled_at(unseen, point) -> bool:
        i = np.round((np.asarray(point) - grid.origin) / grid.voxel).astype(int)
        return bool(unseen.distance[tuple(i)] < 0)

    assert not filled_at(base, (0, 0, 0))  # the views from above see the hole
    fill = module.rare_fill(torus, cameras, base, share=0.1, close=0.25, stride=1)
    assert filled_at(fill, (0, 0, 0)) and not filled_at(fill, (0.55, 0, 0))
    none = module.rare_fill(torus, cameras, base, share=0.01, close=0.25, stride=1)
    assert not filled_at(none, (0, 0, 0))


def test_track_smoothing_is_scored_per_window_against_the_true_path(tmp_path):
    out = tmp_path / "track.jsonl"
    proc = subprocess.run([sys.executable, str(SUITE.with_name("bench_track.py")),
                           "--paths", "even", "--views", "300", "--levels", "0.5:0.01",
                           "--windows", "0", "21", "-1", "--noise-seeds", "0", "1",
                           "--allow-dirty", "--out", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = {line["window"]: line for line in map(json.loads, out.read_text().splitlines())}
    assert sorted(lines) == [-1, 0, 21]
    given, chosen = lines[0], lines[-1]
    assert given["chosen"] == [0, 0] and len(chosen["chosen"]) == 2
    assert all(w > 7 for w in chosen["chosen"])  # the jitter asks for more than the shortest
    # the per-view errors of the given track are what the capture drew, and smoothing
    # takes most of them out
    assert 0.3 < given["rot_deg_mean"] < 0.6 and 0.6 < given["centre_pct_mean"] < 1.2
    assert chosen["rot_deg_mean"] < given["rot_deg_mean"] / 2
    assert chosen["centre_pct_mean"] < given["centre_pct_mean"] / 2
    sys.path.insert(0, str(SUITE.parent))
    import report

    table = report.track_section(list(lines.values()))
    assert any(f"| -1 | {chosen['chosen'][0]}, {chosen['chosen'][1]} |" in row for row in table)


def test_pose_lines_run_beside_other_work_show_no_step_time():
    """bench_poses --shared-machine leaves the step-time ratios out; the table says '-'."""
    sys.path.insert(0, str(SUITE.parent))
    import report

    results = SUITE.parent / "results" / "poses.jsonl"
    line = json.loads(results.read_text().splitlines()[-1])
    alone = dict(line, alone=True, step_time_ratio=1.02, exact_step_time_ratio=0.88)
    shared = dict(line, alone=False, step_time_ratio=None, exact_step_time_ratio=None)
    rows = [row for row in report.poses_section([alone, shared]) if row.startswith("| ")]
    cells = [[c.strip() for c in row.split("|")] for row in rows[-2:]]
    column = rows[0].split("|").index(" step time refined / given ")
    assert cells[0][column] == "1.02" and cells[0][column + 1] == "0.88"
    assert cells[1][column] == "-" and cells[1][column + 1] == "-"


def test_a_simulated_variant_is_named_by_its_settings_and_made_once(tmp_path):
    """bench_poses and bench_threshold simulate their scenes through one cached helper."""
    sys.path.insert(0, str(SUITE.parent))
    import bench_poses

    width, height = TINY_SIZE
    args = argparse.Namespace(scene="builtin:device", views=8, width=width, height=height,
                              rotation=0.5, translation=0.01, clock=0.01, noise_seed=0,
                              drift=0.0, cache=tmp_path, assets=tmp_path / "no-assets")
    folder = bench_poses.noisy_dataset(args)
    assert folder == tmp_path / f"builtin-device-8v-{width}x{height}-pose0.5-0.01-0.01-s0"
    truth = bench_poses._poses(folder / "train" / "pose_true")
    given = bench_poses._poses(folder / "train" / "pose")
    assert truth.shape == given.shape and not np.allclose(truth, given)  # errors went in
    stamp = (folder / "scene.json").stat().st_mtime_ns
    assert bench_poses.noisy_dataset(args) == folder
    assert (folder / "scene.json").stat().st_mtime_ns == stamp  # the cached copy is kept


def test_the_probe_is_repeated_per_count_of_timed_steps(tiny_scene, tmp_path):
    out = tmp_path / "probe.jsonl"
    proc = subprocess.run([sys.executable, str(SUITE.with_name("bench_probe.py")),
                           str(tiny_scene / "device"), "--repeats", "2", "--steps", "1", "5",
                           "--threads", "1", "--allow-dirty", "--out", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert [line["steps_per_point"] for line in lines] == [1, 5]
    assert [line["default"] for line in lines] == [False, True]
    for line in lines:
        assert line["repeats"] == 2 and 0 < line["min_ms"] <= line["mean_step_ms"]
        assert line["mean_step_ms"] <= line["max_ms"] and line["variation"] >= 0


def test_part_errors_name_the_part_a_mesh_lacks(tmp_path, capsys):
    """benchmarks/part_errors.py: a mesh with the base and without the rod recalls the base
    whole and none of the rod; a run folder without its mesh is named."""
    import trimesh

    sys.path.insert(0, str(SUITE.parent))
    spec = importlib.util.spec_from_file_location("part_errors", SUITE.parent / "part_errors.py")
    part_errors = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(part_errors)
    base = trimesh.creation.box(extents=(0.8, 0.1, 0.5))
    rod = trimesh.creation.box(extents=(0.03, 0.6, 0.03))
    rod.apply_translation((0.2, 0.4, 0.0))
    data, run = tmp_path / "data", tmp_path / "run"
    data.mkdir()
    run.mkdir()
    trimesh.util.concatenate([base, rod]).export(data / "gt_mesh.ply")
    base.export(run / "mesh.ply")
    line = {"scene": "rods", "preset": "fast", "seed": 1, "commit": "abc1234", "dirty": False,
            "date": "2026-01-01", "iters": 100, "steps": 100, "minutes": 0, "chamfer": 0.05,
            "run": str(run), "dataset": str(data)}
    results = tmp_path / "suite.jsonl"
    results.write_text(json.dumps(line) + "\n")
    part_errors.main(["rods", "--presets", "fast", "--seed", "1", "--results", str(results)])
    rows = [r.split("|")[1:-1] for r in capsys.readouterr().out.splitlines()[2:]]
    assert [(int(r[3]), float(r[5])) for r in rows] == [(0, 1.0), (1, 0.0)]  # base, rod
    assert float(rows[1][6]) > 0.1  # the rod's samples lie far from the base
    (run / "mesh.ply").unlink()
    with pytest.raises(SystemExit, match=r"run/mesh.ply: missing"):
        part_errors.main(["rods", "--presets", "fast", "--seed", "1", "--results", str(results)])
