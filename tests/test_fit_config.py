"""Config tree: presets, dotted overrides, YAML round trip, one-line errors."""

from __future__ import annotations

import subprocess
import sys

import pytest

from hybridneus.config import (
    Config,
    apply_overrides,
    config_table,
    load_config,
    preset_config,
    rays_per_step,
    save_config,
)
from hybridneus.errors import ConfigError


def test_presets_differ_where_documented():
    fast, quality, paper = (preset_config(n) for n in ("fast", "quality", "eventneus"))
    assert fast.grid.kind == "hash" and paper.grid.kind == "frequency"
    assert quality.train.iters > fast.train.iters
    assert paper.field.sdf_layers == 8 and paper.field.sdf_skip == [4]
    # curvature is on and fades by default; the paper's preset never has it
    assert 0 < fast.loss.curvature_end < 1
    assert paper.loss.lambda_curvature == 0 and paper.loss.lambda_hull == 0
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
        rays_per_step(apply_overrides(preset_config("fast"), ["train.n_rays=-5"]), "cpu")


def test_overrides_are_typed():
    cfg = apply_overrides(
        Config(),
        ["train.lr=0.005", "train.iters=10", "data.threshold=0.2", "field.learned_background=true",
         "data.background=[0.5, 0.5, 0.5]", "grid.kind=dense"],
    )
    assert cfg.train.lr == 0.005 and cfg.train.iters == 10
    assert cfg.data.overrides() == {"threshold": 0.2, "background": (0.5, 0.5, 0.5)}
    assert cfg.field.learned_background is True and cfg.grid.kind == "dense"
    cfg = apply_overrides(cfg, ["train.lr=1"])  # an int is accepted for a float
    assert isinstance(cfg.train.lr, float)


@pytest.mark.parametrize(
    ("item", "message"),
    [
        ("train.lrr=1", "train.lrr: unknown key 'lrr'"),
        ("trian.lr=1", "trian.lr: unknown key 'trian'"),
        ("train.iters=1.5", "train.iters: expected an integer"),
        ("train.iters=many", "train.iters: expected an integer"),
        ("field.learned_background=3", "expected true or false"),
        ("train", "expected key=value"),
        ("train=3", "is a section"),
    ],
)
def test_bad_overrides_raise_one_line_errors(item, message):
    with pytest.raises(ConfigError) as info:
        apply_overrides(Config(), [item])
    assert message in str(info.value)
    assert "\n" not in str(info.value)


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
    assert {"train.lr", "loss.lambda_eikonal", "render.n_coarse", "data.threshold"} <= keys
    assert all(r[3] for r in rows if r[0] != "preset"), "every key has a comment"


def test_docs_table_lists_every_key():
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "training.md").read_text()
    missing = [key for key, *_ in config_table() if f"| `{key}` |" not in text]
    assert not missing, f"docs/training.md lacks rows for {missing}"


def test_cli_bad_config_exits_2_with_one_line(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "hybridneus.cli.app", "fit", str(tmp_path), "--set",
         "train.lr=fast"],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: train.lr: expected a number")
