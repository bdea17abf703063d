"""Presets: every value of the format document's table, path selection, scene.json, overrides."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_data_builder import H, W, random_events, write_split  # noqa: E402

from hybridneus.data import (  # noqa: E402
    apply_overrides,
    load_dataset,
    preset_for_path,
    resolve_preset,
)
from hybridneus.errors import ConfigError, DatasetError  # noqa: E402

BG = 159 / 255

REAL_OFFSETS = {
    "chick": -0.438, "legocube": -0.404, "mic": -0.352, "multimeter": -0.406, "plant": -0.451,
    "ps1": -0.438, "r": -0.389, "sewing": -0.375, "urpils": -0.401, "xbox": -0.385,
}
NNG_YMIN = {
    "bottle": -0.14, "chicken": -0.08, "controller": -0.04, "cube": 0.045, "dragon": -0.15,
    "microphone": -0.14, "multimeter": -0.06, "plant": -0.065, "tapes": -0.12,
}


@pytest.mark.parametrize(
    "scene", ["chair", "drums", "ficus", "hotdog", "lego", "materials", "mic"]
)
def test_nerf_group(tmp_path, scene):
    p = preset_for_path(tmp_path / "data" / "nerf" / scene)
    assert (p.group, p.scene) == ("nerf", scene)
    assert p.threshold == 0.25 and p.polarity_offset == 0.0 and p.max_window == 50
    assert p.cyclic is False and p.neg_ratio == 0.1 and p.tonemap_eps == 0.1
    assert (p.crop_r, p.crop_y_min, p.crop_y_max) == (1.0, -1.0, 1.0)
    assert p.background == (BG, BG, BG)
    assert (p.width, p.height) == (346, 260)


@pytest.mark.parametrize("scene,offset", sorted(REAL_OFFSETS.items()))
def test_real_group(tmp_path, scene, offset):
    p = preset_for_path(tmp_path / "data" / "real" / scene)
    assert (p.group, p.scene) == ("real", scene)
    assert p.polarity_offset == offset
    assert p.threshold == 0.1 and p.max_window == 100 and p.cyclic is True
    assert p.neg_ratio == 0.05 and p.tonemap_eps == 1e-5
    assert (p.crop_r, p.crop_y_min, p.crop_y_max) == (0.25, -0.35, 0.15)
    bg = 200 / 255 if scene == "xbox" else BG
    assert p.background == (bg, bg, bg)


@pytest.mark.parametrize("scene,ymin", sorted(NNG_YMIN.items()))
def test_nextnextgen_group(tmp_path, scene, ymin):
    p = preset_for_path(tmp_path / "data" / "nextnextgen" / scene)
    assert (p.group, p.scene) == ("nextnextgen", scene)
    assert p.threshold == (0.2 if scene == "cube" else 0.1)
    assert p.polarity_offset == 0.0 and p.max_window == 100 and p.cyclic is True
    assert p.neg_ratio == 0.05 and p.tonemap_eps == 1e-5
    assert (p.crop_r, p.crop_y_min, p.crop_y_max) == (0.25, ymin, 0.195)
    assert p.background == (BG, BG, BG)


def test_same_scene_name_in_two_groups(tmp_path):
    real = preset_for_path(tmp_path / "real" / "multimeter")
    nng = preset_for_path(tmp_path / "nextnextgen" / "multimeter")
    assert real.polarity_offset == -0.406 and nng.polarity_offset == 0.0
    assert real.crop_y_min == -0.35 and nng.crop_y_min == -0.06


def test_relative_path_and_trailing_parts(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "data" / "real" / "multimeter").mkdir(parents=True)
    p, src = resolve_preset("data/real/multimeter")
    assert (p.group, p.scene) == ("real", "multimeter") and src == "path (real/multimeter)"
    monkeypatch.chdir(tmp_path / "data" / "real" / "multimeter")
    p, _ = resolve_preset(".")
    assert (p.group, p.scene) == ("real", "multimeter")


def test_unknown_scene_in_known_group(tmp_path):
    p, src = resolve_preset(tmp_path / "real" / "my_toaster")
    assert p.group == "real" and p.scene == "my_toaster" and p.cyclic
    assert "unknown scene" in src


def test_fallback_custom(tmp_path):
    root = tmp_path / "captures" / "toaster"
    write_split(root / "train", n_views=4)
    ds = load_dataset(root, overrides={"width": W, "height": H})
    assert ds.preset.group == "custom" and ds.preset.scene == "toaster"
    assert ds.preset.threshold == 0.25 and ds.preset.max_window == 50
    assert ds.preset_source.startswith("fallback")
    assert any("fallback" in n for n in ds.notes)


def test_scene_json_preset(tmp_path):
    # Even under a real/ path, scene.json wins.
    root = tmp_path / "real" / "sim"
    write_split(root / "train", n_views=4)
    preset = {
        "group": "simulated", "scene": "sim", "threshold": 0.2, "polarity_offset": 0.0,
        "max_window": 20, "cyclic": False, "neg_ratio": 0.1, "tonemap_eps": 1e-3,
        "crop_r": 0.5, "crop_y_min": -0.5, "crop_y_max": 0.5, "background": [0.5, 0.5, 0.5],
        "width": W, "height": H,
    }
    (root / "scene.json").write_text(json.dumps({"preset": preset, "other": 1}))
    ds = load_dataset(root)
    assert ds.preset_source == "scene.json"
    assert ds.preset.group == "simulated" and ds.preset.threshold == 0.2
    assert ds.preset.background == (0.5, 0.5, 0.5) and ds.preset.max_window == 20
    assert (ds.preset.width, ds.preset.height) == (W, H)


def test_scene_json_partial_and_top_level_size(tmp_path):
    root = tmp_path / "sim"
    write_split(root / "train", n_views=4)
    (root / "scene.json").write_text(
        json.dumps({"width": W, "height": H, "preset": {"threshold": 0.3}})
    )
    ds = load_dataset(root)
    assert ds.preset.threshold == 0.3 and ds.preset.max_window == 50
    assert (ds.splits["train"].width, ds.splits["train"].height) == (W, H)


@pytest.mark.parametrize(
    "content", ['{"preset": {"threshold": "high"}}', '{"preset": [1, 2]}', "{not json"]
)
def test_scene_json_bad(tmp_path, content):
    root = tmp_path / "sim"
    write_split(root / "train", n_views=4)
    (root / "scene.json").write_text(content)
    with pytest.raises(DatasetError) as info:
        load_dataset(root)
    assert str(root / "scene.json") in str(info.value)
    assert "\n" not in str(info.value)


def test_overrides_applied_and_recorded(tmp_path):
    root = tmp_path / "real" / "multimeter"
    write_split(root / "train", n_views=4)
    ds = load_dataset(root, overrides={"threshold": 0.2, "width": W, "height": H})
    assert ds.preset.threshold == 0.2 and ds.preset.polarity_offset == -0.406
    assert "threshold=0.2" in ds.preset_source and ds.preset_source.startswith("path")


def test_override_strings_are_parsed(tmp_path):
    p = preset_for_path(tmp_path / "nerf" / "lego")
    o = {"threshold": "0.3", "cyclic": "true", "max_window": "7", "background": "0.2,0.3,0.4"}
    q = apply_overrides(p, o)
    assert q.threshold == 0.3 and q.cyclic is True and q.max_window == 7
    assert q.background == (0.2, 0.3, 0.4)
    assert apply_overrides(p, {"background": 0.5}).background == (0.5, 0.5, 0.5)
    assert apply_overrides(p, {"threshold": 1}).threshold == 1.0


@pytest.mark.parametrize(
    "overrides,key",
    [
        ({"treshold": 0.2}, "treshold"),
        ({"threshold": "abc"}, "threshold"),
        ({"threshold": True}, "threshold"),
        ({"threshold": -1.0}, "threshold"),
        ({"max_window": 2.5}, "max_window"),
        ({"cyclic": "maybe"}, "cyclic"),
        ({"background": [1, 2]}, "background"),
        ({"neg_ratio": 1.5}, "neg_ratio"),
        ({"width": 0}, "width"),
        ({"crop_y_min": 2.0}, "crop_y_min"),
    ],
)
def test_bad_overrides(tmp_path, overrides, key):
    p = preset_for_path(tmp_path / "nerf" / "lego")
    with pytest.raises(ConfigError) as info:
        apply_overrides(p, overrides)
    msg = str(info.value)
    assert msg.startswith(key) and "\n" not in msg


def test_width_height_override_changes_bounds(tmp_path):
    root = tmp_path / "nerf" / "lego"
    ev = random_events(50, 4, width=W, height=H)
    ev["x"][3] = W + 5  # fits 346x260, not W x H
    write_split(root / "train", n_views=4, events=ev)
    ds = load_dataset(root)  # default 346x260: accepted, with a principal point note
    assert ds.splits["train"].width == 346
    assert any("principal point" in n for n in ds.notes)
    with pytest.raises(DatasetError, match="outside the image"):
        load_dataset(root, overrides={"width": W, "height": H})
    assert np.max(ds.splits["train"].events.x) == W + 5
