"""Sensor mosaics: every Bayer layout, and monochrome sensors that train a grey field."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from hybridneus.data.mosaic import MOSAICS, channel_image, check_mosaic, mosaic_weights
from hybridneus.errors import ConfigError, DatasetError


@pytest.mark.parametrize("mosaic, red_at", [("RGGB", (0, 0)), ("BGGR", (1, 1)),
                                            ("GRBG", (0, 1)), ("GBRG", (1, 0))])
def test_each_bayer_layout_puts_red_where_its_name_says(mosaic, red_at):
    image = channel_image(4, 6, mosaic)
    assert image[red_at] == 0 and image[1 - red_at[0], 1 - red_at[1]] == 2
    assert (image == 1).sum() == 12  # two greens per 2x2 cell
    rows, cols = np.mgrid[0:4, 0:6]
    xy = np.stack([cols.ravel(), rows.ravel()], 1)
    np.testing.assert_array_equal(mosaic_weights(xy, mosaic).argmax(1), image.ravel())


def test_mono_weights_every_channel_alike_and_names_are_checked():
    np.testing.assert_allclose(mosaic_weights(np.zeros((3, 2), int), "mono"), 1 / 3)
    assert check_mosaic("rggb") == "RGGB" and check_mosaic("Monochrome") == "mono"
    with pytest.raises(ConfigError, match="unknown sensor mosaic"):
        check_mosaic("RGBW")
    assert set(MOSAICS) == {"RGGB", "BGGR", "GRBG", "GBRG", "mono"}


def _events_for_a_red_change(mosaic: str) -> np.ndarray:
    from hybridneus.simulate import EventModel
    from hybridneus.simulate.events import EventSimulator

    first = np.full((4, 6, 3), 0.5)
    second = first.copy()
    second[..., 0] = 0.9  # only the red channel brightens
    sim = EventSimulator(first, EventModel(threshold=0.2, mosaic=mosaic))
    chunk = sim.step(second)
    fired = np.zeros((4, 6), bool)
    fired[chunk.y, chunk.x] = True
    return fired


def test_a_colour_sensor_fires_at_its_red_pixels_and_a_mono_one_at_all():
    for mosaic in ("RGGB", "BGGR", "GRBG", "GBRG"):
        np.testing.assert_array_equal(_events_for_a_red_change(mosaic),
                                      channel_image(4, 6, mosaic) == 0)
    assert _events_for_a_red_change("mono").all()


def test_a_grey_field_renders_equal_channels_and_a_grey_background():
    from hybridneus.config import FieldConfig, GridConfig
    from hybridneus.model.field import HybridField

    grid = GridConfig(n_levels=2, max_resolution=16, base_resolution=8)
    field = HybridField(grid, FieldConfig(), background=(0.2, 0.5, 0.8), grey=True)
    rgb = field.color(torch.rand(16, 3) - 0.5, torch.nn.functional.normalize(torch.randn(16, 3)))
    rgb = torch.as_tensor(rgb)
    torch.testing.assert_close(rgb[:, 0], rgb[:, 2])
    torch.testing.assert_close(field.background(), torch.full((3,), 0.5))
    colour = HybridField(grid, FieldConfig(), background=(0.2, 0.5, 0.8))
    assert not torch.allclose(colour.background(), torch.full((3,), 0.5))


def test_a_mono_dataset_trains_a_grey_field(tmp_path):
    from hybridneus.api import fit
    from hybridneus.config import apply_overrides, preset_config
    from hybridneus.data import load_dataset
    from hybridneus.simulate import EventModel, SimulationConfig, simulate_dataset
    from hybridneus.training.runs import latest_run, load_field
    from tests.conftest import TINY_FIT

    cfg = SimulationConfig(n_views=8, width=24, height=18, val_views=0, test_views=0,
                           revolutions=1.0, supersample=1, events=EventModel(mosaic="mono"))
    simulate_dataset("builtin:device", tmp_path / "mono", cfg, progress=False)
    assert load_dataset(tmp_path / "mono").preset.mosaic == "mono"
    fit(tmp_path / "mono", apply_overrides(preset_config("fast"), TINY_FIT),
        out=tmp_path / "runs", device="cpu")
    field = load_field(latest_run(tmp_path / "runs"), device="cpu")
    assert field.grey
    rgb = torch.as_tensor(field.color(np.zeros((4, 3), np.float32),
                                      np.tile([[0.0, 0.0, 1.0]], (4, 1)).astype(np.float32)))
    torch.testing.assert_close(rgb[:, 0], rgb[:, 1])


def test_a_scene_json_with_an_unknown_mosaic_is_refused(tmp_path):
    from hybridneus.data.presets import resolve_preset

    (tmp_path / "scene.json").write_text(json.dumps({"preset": {"mosaic": "RGBW"}}))
    with pytest.raises(DatasetError, match="mosaic"):
        resolve_preset(tmp_path)
