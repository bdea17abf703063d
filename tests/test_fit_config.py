"""Config tree: presets, dotted overrides, YAML round trip, one-line errors."""

from __future__ import annotations

import subprocess
import sys

import pytest
import yaml

from hybridneus.config import (
    Config,
    apply_overrides,
    config_table,
    load_config,
    preset_config,
    rays_per_step,
    save_config,
    validate,
)
from hybridneus.errors import ConfigError


def test_presets_differ_where_documented():
    fast, quality, paper = (preset_config(n) for n in ("fast", "quality", "eventneus"))
    assert fast.grid.kind == "hash" and paper.grid.kind == "frequency"
    assert quality.train.iters > fast.train.iters
    assert paper.field.sdf_layers == 8 and paper.field.sdf_skip == [4]
    # curvature is on and fades by default; the paper's preset has neither it nor the hull
    assert fast.priors.curvature.enabled and 0 < fast.priors.curvature.end < 1
    assert not paper.priors.curvature.enabled and not paper.priors.hull.enabled
    assert not paper.priors.sharpness_floor.enabled
    with pytest.raises(ConfigError, match="unknown preset"):
        preset_config("fastest")


def test_pixels_per_step_default_to_the_device():
    fast = preset_config("fast")
    assert fast.train.n_rays == 0
    assert rays_per_step(fast, "cpu") == 256
    assert rays_per_step(fast, "cuda:1") == 1024
    assert rays_per_step(preset_config("quality"), "cuda") == 512  # a preset's own count
    assert rays_per_step(apply_overrides(fast, ["train.n_rays=64"]), "cuda") == 64
    with pytest.raises(ConfigError, match="train.n_rays: expected >= 0"):
        validate(apply_overrides(preset_config("fast"), ["train.n_rays=-5"]))


def test_overrides_are_typed():
    cfg = apply_overrides(
        Config(),
        ["train.lr=0.005", "train.iters=10", "data.threshold=0.2", "render.occupancy=false",
         "data.background=[0.5, 0.5, 0.5]", "grid.kind=dense"],
    )
    assert cfg.train.lr == 0.005 and cfg.train.iters == 10
    assert cfg.data.overrides() == {"threshold": 0.2, "background": (0.5, 0.5, 0.5)}
    assert cfg.render.occupancy is False and cfg.grid.kind == "dense"
    cfg = apply_overrides(cfg, ["train.lr=1"])  # an int is accepted for a float
    assert isinstance(cfg.train.lr, float)
    # YAML reads "1e-8" (no point in the mantissa) as a string; a float key takes it
    cfg = apply_overrides(cfg, ["train.adam_eps=1e-8", "data.threshold=2e-1"])
    assert cfg.train.adam_eps == 1e-8 and cfg.data.threshold == 0.2


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("train.lrr=1", "train.lrr: unknown key 'lrr'"),
        ("trian.lr=1", "trian.lr: unknown key 'trian'"),
        ("train.iters=1.5", "train.iters: expected an integer"),
        ("train.iters=many", "train.iters: expected an integer"),
        ("train.iters=1e3", "train.iters: expected an integer"),
        ("train.lr=fast", "train.lr: expected a number"),
        ("train.lr=nan", "train.lr: expected a number"),
        ("render.occupancy=3", "expected true or false"),
        ("train", "expected key=value"),
        ("train=3", "is a section"),
    ],
)
def test_bad_overrides_raise_one_line_errors(item, message):
    with pytest.raises(ConfigError) as info:
        apply_overrides(Config(), [item])
    assert message in str(info.value)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("train.iters=-5", "train.iters: expected >= 1, got -5"),
        ("train.minutes=-3", "train.minutes: expected >= 0"),
        ("train.lr=-1", "train.lr: expected > 0"),
        ("train.warmup=50", "train.warmup: expected a fraction of training"),
        ("train.supervision=frames", "train.supervision: expected 'events' or 'rgb'"),
        ("loss.lambda_eikonal=-0.1", "loss.lambda_eikonal: expected a weight >= 0"),
        ("priors.hull.weight=-1", "priors.hull.weight: expected a weight >= 0"),
        ("priors.curvature.end=2", "priors.curvature.end: expected a fraction"),
        ("priors.collapse_guard.lr_factor=0", "priors.collapse_guard.lr_factor: expected in"),
        ("grid.kind=octree", "grid.kind: expected hash, dense or frequency"),
        ("render.n_coarse=0", "render.n_coarse: expected >= 1"),
        ("render.chunk=0", "render.chunk: expected >= 1"),
        ("render.occupancy_resolution=1", "render.occupancy_resolution: expected >= 2"),
        ("grid.n_levels=0", "grid.n_levels: expected >= 1"),
        ("train.seed=-1", "train.seed: expected in [0, 2^32)"),
        ("priors.collapse_guard.explode=0.5", "priors.collapse_guard.explode: expected > 1"),
    ],
)
def test_values_out_of_range_are_config_errors(item, message):
    cfg = apply_overrides(preset_config("fast"), [item])  # the type is right
    with pytest.raises(ConfigError) as info:
        validate(cfg)
    assert message in str(info.value) and "\n" not in str(info.value)
    for name in ("fast", "quality", "eventneus"):
        validate(preset_config(name))


def test_keys_of_hybridneus_0_1_name_their_successor(tmp_path):
    with pytest.raises(ConfigError, match=r"loss.lambda_hull: unknown key \(now priors.hull"):
        apply_overrides(Config(), ["loss.lambda_hull=1"])
    with pytest.raises(ConfigError, match="data.denoise: unknown key .removed in hybridneus"):
        apply_overrides(Config(), ["data.denoise=true"])
    # a 0.1 run's config.yaml still loads: moved keys move, gone ones are dropped
    old = ("preset: fast\nloss:\n  lambda_hull: 0.0\n  lambda_curvature: 0.1\n"
           "  hull_ramp: 300\ntrain:\n  warmup: 50\n  inv_s_floor: 150.0\n"
           "  collapse_window: 10\ndata:\n  crop_from_events: false\n  crop_r: 0.3\n")
    (tmp_path / "old.yaml").write_text(old)
    cfg = load_config(tmp_path / "old.yaml")
    assert not cfg.priors.hull.enabled and cfg.priors.curvature.weight == 0.1
    assert cfg.priors.sharpness_floor.floor == 150.0 and cfg.priors.collapse_guard.window == 10
    assert cfg.train.warmup == preset_config("fast").train.warmup  # steps: dropped
    assert cfg.estimate.crop is False and cfg.data.crop_r == 0.3


def test_a_saved_run_keeps_what_it_was_trained_with(tmp_path, monkeypatch):
    from hybridneus.config.overrides import RUN_KEY_ORIGINS
    from hybridneus.training.runs import load_run_config

    # a key whose default has moved since: a run that lacks it gets its origin, a
    # hand-written config today's default
    (tmp_path / "config.yaml").write_text("preset: fast\nrender:\n  n_coarse: 24\n")
    monkeypatch.setitem(RUN_KEY_ORIGINS, "render.n_importance", 8)
    assert load_run_config(tmp_path).render.n_importance == 8
    assert load_config(tmp_path / "config.yaml").render.n_importance == \
        Config().render.n_importance != 8
    # a run that saved the key keeps its value
    (tmp_path / "config.yaml").write_text("preset: fast\nrender:\n  n_importance: 12\n")
    assert load_run_config(tmp_path).render.n_importance == 12


def test_yaml_round_trip_and_bad_yaml(tmp_path):
    cfg = apply_overrides(preset_config("eventneus"), ["train.seed=7", "data.crop_r=0.3"])
    save_config(cfg, tmp_path / "c.yaml")
    back = load_config(tmp_path / "c.yaml")
    assert back == cfg
    (tmp_path / "bad.yaml").write_text("train:\n  speed: 3\n")
    with pytest.raises(ConfigError, match=r"bad.yaml: train.speed: unknown key"):
        load_config(tmp_path / "bad.yaml")


def test_config_table_lists_every_key():
    rows = config_table()
    keys = {r[0] for r in rows}
    assert {"train.lr", "loss.lambda_eikonal", "render.n_coarse", "data.threshold",
            "priors.hull.enabled", "priors.collapse_guard.window", "estimate.crop"} <= keys
    assert all(r[3] for r in rows if r[0] != "preset"), "every key has a comment"


def test_docs_table_is_the_generated_one():
    from pathlib import Path

    from hybridneus.config import config_markdown

    text = (Path(__file__).parents[1] / "docs" / "training.md").read_text()
    start = "<!-- config table: python -m hybridneus.config.table -->\n"
    block = text.split(start, 1)[1].split("<!-- end of config table -->", 1)[0]
    assert block == config_markdown(), "rerun python -m hybridneus.config.table"


def test_cli_bad_config_exits_2_with_one_line(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "hybridneus.cli.app", "fit", str(tmp_path), "--set",
         "train.lr=fast"],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: train.lr: expected a number")


def test_checking_the_runs_folder_creates_nothing(tmp_path):
    from hybridneus.errors import RunError
    from hybridneus.training.runs import check_runs_root

    check_runs_root(tmp_path / "a" / "runs")  # a fit failing on its data leaves no folder
    assert not (tmp_path / "a").exists()
    (tmp_path / "file").write_text("x")
    with pytest.raises(RunError, match="file/runs: cannot create the runs folder"):
        check_runs_root(tmp_path / "file" / "runs")
    with pytest.raises(RunError, match="not a folder"):
        check_runs_root(tmp_path / "file")


def test_keys_removed_in_0_3_are_named_and_old_runs_still_load(tmp_path, caplog):
    """An experiment that did not become a default leaves no key: --set names it as removed;
    a 0.2 run's config.yaml loads without it, unless the field it made had a part this
    version cannot build."""
    from hybridneus.config.overrides import REMOVED_KEYS

    with pytest.raises(ConfigError, match=r"train.lr_sdf_head: unknown key \(removed in "
                       "hybridneus 0.3"):
        apply_overrides(Config(), ["train.lr_sdf_head=0.1"])
    for key in REMOVED_KEYS:
        section, *rest = key.split(".")
        node = Config().to_dict()[section]
        for part in rest[:-1]:
            node = node.get(part, {})  # a removed prior leaves no section
        assert rest[-1] not in node, key
    # a 0.2 run: every removed key saved at its default, one training switch at another
    saved = Config().to_dict()
    saved["render"].update(empty_share=0.25, empty_share_until=1.0)
    saved["train"].update(replan_at=[0.05, 0.15, 0.3, 0.5, 0.7], lr_sdf_head=1.0)
    saved["field"].update(shading_degree=0, learned_background=False)
    saved["refine"].update(poses=False, pose_knots=0)
    saved["priors"]["silent_lines"] = {"enabled": True, "weight": 1.0, "lines": 32}
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(saved))
    with caplog.at_level("INFO", logger="hybridneus"):
        cfg = load_config(tmp_path / "config.yaml")
    assert cfg.to_dict() == Config().to_dict()
    assert "render.empty_share=0.25 dropped" in caplog.text
    assert "priors.silent_lines.enabled=True dropped" in caplog.text
    assert "lr_sdf_head" not in caplog.text  # at its default: nothing to say
    saved["field"]["shading_degree"] = 3
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(saved))
    with pytest.raises(ConfigError, match=r"field.shading_degree=3 was removed in hybridneus "
                       r"0.3 \(only 0 remains\); fit the scene again"):
        load_config(tmp_path / "config.yaml")
