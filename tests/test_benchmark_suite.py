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
    sys.modules["run_suite"] = module  # its dataclasses look their module up there
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
    (state,) = (tmp_path / "runs").glob("suite-*/batch.json")  # the fits ran as a batch
    assert [r["status"] for r in json.loads(state.read_text())["jobs"].values()] == ["done"]
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
    if line["chamfer"] is not None:  # what Chamfer mixes, apart
        assert {"part_recall", "farthest_part"} <= set(line)
        assert "plane_rms" not in line or [c[1] for c in line["plane_curve"]] == [3, 6]
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


def test_preset_specs_name_a_preset_and_its_overrides():
    _suite_module()
    import suite_jobs

    assert suite_jobs.preset_spec("fast") == ("fast", [])
    assert suite_jobs.preset_spec("quality-rgb") == ("quality", ["train.supervision=rgb"])
    assert suite_jobs.preset_spec("fast+train.lr=0.02+priors.hull.enabled=false") == (
        "fast", ["train.lr=0.02", "priors.hull.enabled=false"])


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
    assert "| gen-box-3 | bbb | 2026-11-26 | 1 | 0.0200 |" in text
    assert "| 9000 | 905 | - |" in text  # the longest wall time; no first-step time given


def test_packed_datasets_hold_what_a_fit_reads(tiny_scene, tmp_path):
    """benchmarks/pack_datasets.py: the packed copy loads as the same dataset (events
    identical, compressed, no frames, no test split)."""
    import numpy as np

    from hybridneus.data import load_dataset

    sys.path.insert(0, str(SUITE.parent))
    spec = importlib.util.spec_from_file_location("pack_datasets",
                                                  SUITE.parent / "pack_datasets.py")
    pack_datasets = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(pack_datasets)

    assert pack_datasets.pack(tiny_scene / "device", tmp_path / "carry") > 0
    packed = tmp_path / "carry" / "device"
    assert not (packed / "train" / "rgb").exists() and not (packed / "test").exists()
    a, b = load_dataset(tiny_scene / "device")["train"], load_dataset(packed)["train"]
    assert a.n_views == b.n_views
    for name in ("x", "y", "t", "p"):
        assert np.array_equal(getattr(a.events, name), getattr(b.events, name))
    np.testing.assert_array_equal(a.c2w, b.c2w)
    with pytest.raises(SystemExit, match="no scene.json"):
        pack_datasets.pack(tmp_path, tmp_path / "carry")


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

    off, spec = "fast priors.hull.enabled=false", "fast+train.lr=0.02"
    lines = [line("fast", "bunny", 0, 0.010), line("fast", "bunny", 1, 0.012),
             line("fast", "gen-cage-1", 0, 0.05), line("fast", "gen-cage-1", 1, 0.06),
             line(off, "bunny", 0, 0.02), line(off, "gen-cage-1", 0, None),
             line(spec, "bunny", 0, 0.0105),
             {**line("fast priors.curvature.enabled=false", "toyTrain", 0, 0.01),
              "commit": "def5678"}]
    text = "\n".join(report.variant_section(lines))
    header = ("| scene | seeds | CD `fast` | range | `priors.hull.enabled=false` "
              "| `train.lr=0.02` |")
    assert header in text
    # seed 0 against seed 0; worse beyond the preset's range of 0.002
    assert "| bunny | 2 | 0.0110 | 0.0100-0.0120 | 0.0200 (+100% ! +) | 0.0105 (+5%) |" in text
    assert "| gen-cage-1 | 2 | 0.0550 | 0.0500-0.0600 | empty | - |" in text
    assert "1 scene; 1 empty fit besides" in text
    # a variant without its preset in the same run is on neither table
    assert "def5678" not in text
    # a variant that sets a key removed from the config is on none, even at its old default
    removed = line("fast+render.empty_share=0", "bunny", 0, 0.011)
    assert "empty_share" not in "\n".join(report.variant_section(lines + [removed]))
    assert "def5678" not in "\n".join(report.suite_section(lines))
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

    es = "fast+train.lr=0.02"
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
    assert ("| **mean, generated, kinds with few events** | | | | **0.0200** | | **0.0100** |"
            in text)
    accuracy = "\n".join(report.suite_section(lines))
    assert "| **mean, generated, kinds with few events** | | | | **0.0100** |" in accuracy
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


def test_readme_results_are_generated_from_their_commits_lines():
    sys.path.insert(0, str(SUITE.parent))
    import common
    import report

    lines = [r for r in common.read_lines(common.RESULTS / "suite.jsonl") if not r.get("dirty")]
    readme = report.README.read_text()
    assert readme == report.readme_text(readme, lines), "rerun benchmarks/report.py --readme"


def test_the_accuracy_pages_table_is_generated_from_its_commits_lines():
    sys.path.insert(0, str(SUITE.parent))
    import common
    import report

    lines = [r for r in common.read_lines(common.RESULTS / "suite.jsonl") if not r.get("dirty")]
    page = report.ACCURACY.read_text()
    assert page == report._block_text(page, report.ACCURACY_START, lines,
                                      report.accuracy_block), \
        "rerun benchmarks/report.py --accuracy"
    base = {"commit": "abc1234", "preset": "fast", "minutes": 15.0, "threads": 2,
            "machine": {"cpu": "X"}, "steps": 100}
    rows = [{**base, "scene": "gen-box-7", "seed": 0, "chamfer": 0.02, "accuracy": 0.01,
             "completeness": 0.03, "fscore": 0.5, "chamfer_eventneus": 0.08},
            {**base, "scene": "bunny", "seed": 0, "chamfer": 0.01, "steps": 200},
            {**base, "scene": "bunny", "seed": 1, "chamfer": 0.03, "steps": 300},
            {**base, "scene": "bunny", "seed": 2, "chamfer": 0.9, "preset": "fast+x=1"}]
    rows.append({**rows[0], "commit": "def5678", "scene": "gen-cage-3"})
    rows.append({**rows[0], "commit": "0000000", "scene": "gen-slab-5"})  # not named
    _, _, bunny, box, cage = report.accuracy_block(rows, ["abc1234", "def5678"])
    assert bunny == ("| bunny | 15 min | X, 2 threads | 2 | 0.0200 | - | - | - | - | 250 | "
                     "abc1234 |")
    assert box == ("| gen-box-7 | 15 min | X, 2 threads | 1 | 0.0200 | 0.0100 | 0.0300 | "
                   "0.500 | 0.0800 | 100 | abc1234 |")
    assert cage.startswith("| gen-cage-3 |") and cage.endswith("| def5678 |")
    page = (f"{report.ACCURACY_START}abc1234 def5678 -->\nold\n{report.README_END}\n")
    assert "gen-cage-3" in report._block_text(page, report.ACCURACY_START, rows,
                                              report.accuracy_block)


def test_readme_block_rows_summarise_assets_and_generated_objects():
    sys.path.insert(0, str(SUITE.parent))
    import report

    base = {"commit": "abc1234", "preset": "fast", "minutes": 15.0, "threads": 2,
            "machine": {"cpu": "X"}, "steps": 100}
    lines = [{**base, "scene": "bunny", "seed": 0, "chamfer": 0.01},
             {**base, "scene": "bunny", "seed": 1, "chamfer": 0.03},
             {**base, "scene": "gen-box-7", "seed": 0, "chamfer": 0.05, "steps": 90},
             {**base, "scene": "bunny", "seed": 0, "chamfer": 0.5, "commit": "other"}]
    _, _, row = report.readme_block(lines, ["abc1234"])
    assert row == ("| `fast` | 15 min | X, 2 threads | 0.0200 (1 asset, 2 seeds) | "
                   "0.0500 (1 object, 1 seed) | 90-100 |")
    # a scene fitted with more seeds does not weigh more: (0.02 + 0.04) / 2, not 0.08 / 3
    lines.append({**base, "scene": "xylophone", "seed": 0, "chamfer": 0.04})
    _, _, row = report.readme_block(lines, ["abc1234"])
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
    assert ("\nCommand: `python benchmarks/compare_commits.py aaa bbb`  \nCommand: `python "
            "benchmarks/run_suite.py --generated 6`\n") in text
    text = "\n".join(report.suite_section(lines[:2]))
    assert text.count("Command: ") == 1
    assert "\nCommand: `python benchmarks/compare_commits.py aaa bbb`\n" in text


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
    column = rows[0].split("|").index(" step time smoothed / given ")
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


def test_lines_of_removed_experiments_stay_out_of_the_page(tmp_path, monkeypatch):
    """A line made with a key removed from the config, at another value than the default it
    had, cannot be repeated today: the report leaves it out (the results file keeps it); at
    that default the setting is today's behaviour and the line stays."""
    sys.path.insert(0, str(SUITE.parent))
    import common
    import report

    assert common.settings_of({"preset": "fast+train.lr=0.02+grid.n_levels=8",
                               "overrides": ["train.seed=1"]}) == [
        "train.lr=0.02", "grid.n_levels=8", "train.seed=1"]
    assert common.settings_of({"preset": "fast priors.hull.enabled=false"}) == [
        "priors.hull.enabled=false"]
    assert not common.reruns_today({"preset": "fast+train.lr_sdf_head=0.1"})
    assert common.reruns_today({"preset": "fast+train.lr_sdf_head=1.0"})
    assert not common.reruns_today({"refine_sets": ["refine.pose_knots=21"]})
    assert common.reruns_today({"refine_sets": ["refine.poses=false",
                                                "refine.pose_smoothing=41"]})

    def line(preset, cd, commit="aaa", date="2026-01-01T00:00:00+00:00"):
        return {"bench": "suite", "commit": commit, "dirty": False, "date": date,
                "scene": "bunny", "seed": 0, "preset": preset, "minutes": 15.0, "steps": 9000,
                "chamfer": cd, "fit_wall_s": 900, "machine": {"cpu": "cpu x"}, "threads": 2,
                "command": "python benchmarks/run_suite.py"}

    lines = [line("fast", 0.0120), line("fast+train.lr_sdf_head=0.1", 0.0110),
             line("fast+priors.hull.enabled=false", 0.0150)]
    monkeypatch.setattr(common, "RESULTS", tmp_path)
    (tmp_path / "suite.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    text = report.build([])
    assert "lr_sdf_head" not in text and "0.0110" not in text
    assert "`priors.hull.enabled=false`" in text and "0.0150" in text


def test_the_page_shows_the_newest_commit_of_each_group_with_both_protocols(tmp_path,
                                                                             monkeypatch):
    sys.path.insert(0, str(SUITE.parent))
    import common
    import report

    def line(commit, date, cd, **extra):
        return {"bench": "suite", "commit": commit, "dirty": False, "date": date,
                "scene": "bunny", "seed": 0, "preset": "fast", "minutes": 15.0, "steps": 9000,
                "chamfer": cd, "fit_wall_s": 900, "machine": {"cpu": "cpu x"}, "threads": 2,
                "command": "python benchmarks/run_suite.py", **extra}

    lines = [line("old", "2026-01-01T00:00:00+00:00", 0.0200),
             line("new", "2026-02-01T00:00:00+00:00", 0.0120, floor=0.0010,
                  chamfer_eventneus=0.0450, floor_eventneus=0.0040)]
    monkeypatch.setattr(common, "RESULTS", tmp_path)
    (tmp_path / "suite.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    text = report.build([])
    assert "| old |" not in text and "0.0200" not in text  # the older commit's fit
    assert ("| scene | commit | date | seeds | CD mean | CD range | F@1% | floor | CD eventneus "
            "| floor eventneus |") in text
    assert ("| bunny | new | 2026-02-01 | 1 | 0.0120 | - | - | 0.0010 | 0.0450 | 0.0040 | 9000 "
            "| 900 | - |") in text
    # a comparison names its commits and pairs them, whatever is newest
    assert "| bunny | fast | 15 min | 1 | 0.0200 | - | 0.0120 |" in report.build(
        [("old", "new")])


def test_a_budget_on_a_busy_machine_is_recorded_with_its_replans(tiny_scene, tmp_path):
    """bench_budget.py: a --minutes fit with a spinning process beside it for its start, and
    one alone; each line names the steps, re-plans, paces, wall time and the share used."""
    out = tmp_path / "budget.jsonl"
    proc = subprocess.run([sys.executable, str(SUITE.with_name("bench_budget.py")),
                           str(tiny_scene / "device"), "--minutes", "0.25", "--busy", "0.05",
                           "--hogs", "1", "--threads", "1", "--quiet-too", "--allow-dirty",
                           "--out", str(out)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    quiet, busy = (json.loads(x) for x in out.read_text().splitlines())
    assert (quiet["busy_minutes"], quiet["hogs"]) == (0.0, 0)
    assert (busy["busy_minutes"], busy["hogs"]) == (0.05, 1)
    for line in (quiet, busy):
        # a 15 s budget on a loaded machine may end before its first step: the line must
        # still say so truthfully
        assert line["bench"] == "budget" and 0 <= line["steps"] <= line["planned"]
        assert isinstance(line["replans"], int) and line["wall_s"] > 0
        assert line["used"] == pytest.approx(line["wall_s"] / 15.0, rel=0.01)
    sys.path.insert(0, str(SUITE.parent))
    import report

    table = report.budget_section([quiet, busy])
    assert any("| 0.05 min, 1 processes |" in row for row in table)
    proc = subprocess.run([sys.executable, str(SUITE.with_name("bench_budget.py")),
                           str(tmp_path), "--allow-dirty"], capture_output=True, text=True)
    assert proc.returncode != 0 and "no scene.json" in proc.stderr


def test_a_budget_that_loading_uses_up_is_recorded_as_refused(tiny_scene, tmp_path):
    """bench_budget.py: a budget too short for a single step (as on a machine so busy that
    loading takes it all) is refused by the fit; the bench writes that as its line."""
    out = tmp_path / "budget.jsonl"
    proc = subprocess.run([sys.executable, str(SUITE.with_name("bench_budget.py")),
                           str(tiny_scene / "device"), "--minutes", "0.001", "--busy", "0",
                           "--threads", "1", "--allow-dirty", "--out", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    (line,) = (json.loads(x) for x in out.read_text().splitlines())
    assert line["steps"] == line["planned"] == 0 and "train.minutes" in line["refused"]
    sys.path.insert(0, str(SUITE.parent))
    import report

    assert any("| refused: loading left no time |" in row for row in report.budget_section([line]))


def test_a_busy_test_run_is_counted_from_pytests_summary():
    """bench_busy_tests.py reads pytest's closing line; the report shows the newest run."""
    sys.path.insert(0, str(SUITE.parent))
    import bench_busy_tests
    import report

    assert bench_busy_tests.counts("610 passed, 7 deselected, 3 warnings in 1301.45s") == {
        "passed": 610, "failed": 0, "errors": 0, "skipped": 0, "deselected": 7}
    assert bench_busy_tests.counts("2 failed, 5 passed, 1 error in 3.0s") == {
        "passed": 5, "failed": 2, "errors": 1, "skipped": 0, "deselected": 0}
    line = {"hogs": 2, "passed": 610, "failed": 0, "errors": 0, "wall_s": 1301.4,
            "commit": "abc1234", "machine": {"cpu": "X"}, "threads": None,
            "date": "2026-12-06T00:00:00+00:00", "command": "python bench_busy_tests.py"}
    assert "| 2 | 610 | 0 | 0 | 1301 | abc1234 | X, all threads | 2026-12-06 |" in \
        report.busy_tests_section([line])


def test_part_events_scores_each_generated_part_and_refuses_other_meshes(tmp_path, tiny_scene):
    suite = _suite_module()
    import part_events

    from hybridneus.data import load_dataset
    from hybridneus.simulate.generated import generated_parts

    args = argparse.Namespace(views=12, width=48, height=36, test_views=0, noise=(0.0, 0.0),
                              cache=tmp_path, spiral="seiffert")
    folder = suite.dataset_for("generated:box:5", {}, args)
    source, samples, extents = part_events.part_samples(folder, 200)
    assert source == "generated:box:5" and len(samples) == len(generated_parts("box", 5))
    split = load_dataset(folder)["train"]
    views = np.arange(split.n_views - 1)
    far = samples[0] + 50.0  # far behind every camera: no view sees it
    shares = part_events.seen_shares(split, [samples[0], far], views)
    assert shares[0] > 0.2 and shares[1] == 0.0

    out = tmp_path / "part_events.jsonl"
    script = SUITE.parent / "part_events.py"
    proc = subprocess.run([sys.executable, str(script), str(folder), "--every", "2",
                           "--out", str(out), "--allow-dirty"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-2000:]
    line = json.loads(out.read_text().splitlines()[-1])
    assert len(line["seen_level"]) == len(line["seen_high"]) == len(extents)
    assert line["views_high"] + line["views_level"] == len(range(0, split.n_views - 1, 2))
    proc = subprocess.run([sys.executable, str(script), str(tiny_scene / "device"), "--out",
                           str(out), "--allow-dirty"], capture_output=True, text=True)
    assert proc.returncode != 0 and "is not a generated object" in proc.stderr
    assert "Traceback" not in proc.stderr
