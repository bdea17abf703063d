"""The tonemap eps of the loss: at most estimate.eps_max, and lower where the events need it."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from hybridneus.data import load_dataset
from hybridneus.data.contrast import event_extent, loss_eps, reachable_eps

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_data_builder import write_split  # noqa: E402

N_VIEWS = 60


def _dark_patch_events(count: int) -> dict:
    """``count`` negative events on each pixel of a 4x4 patch between views 10 and 20 (a
    dark object edge passing), nothing elsewhere but the stream's last event."""
    xs, ys = np.meshgrid(np.arange(4, 8), np.arange(5, 9))
    xs, ys = np.repeat(xs.ravel(), count), np.repeat(ys.ravel(), count)
    t = np.sort(np.random.default_rng(0).uniform(10, 20, size=xs.size))
    t[-1] = N_VIEWS - 1  # the stream ends at the last view
    p = -np.ones(xs.size, dtype=np.int8)
    p[-1] = 1  # a stream of one polarity is refused; this one is outside views 10..20
    return {"x": xs.astype(np.int16), "y": ys.astype(np.int16), "t": t, "p": p}


@pytest.fixture
def scene(tmp_path):
    """A dataset with no scene.json under an unknown path: the nerf group's eps = 0.1."""
    def make(count: int):
        root = tmp_path / f"patch{count}"
        write_split(root / "train", n_views=N_VIEWS, events=_dark_patch_events(count))
        return root
    return make


def test_extent_is_threshold_times_the_window_count(scene):
    ds = load_dataset(scene(30))
    p = ds.preset
    assert (p.threshold, p.tonemap_eps) == (0.25, 0.1)
    assert event_extent(ds.splits["train"], p) == pytest.approx(0.25 * 30)
    from hybridneus.data import apply_overrides

    shifted = apply_overrides(p, {"polarity_offset": -0.4})  # each event counts -1.4
    assert event_extent(ds.splits["train"], shifted) == pytest.approx(0.25 * 30 * 1.4)


def test_loss_eps_takes_the_lowest_bound_and_says_which():
    assert loss_eps(0.1, 1.0, 1e-3) == (1e-3, "capped at estimate.eps_max 0.001")
    eps, why = loss_eps(0.1, 7.5, 1e-3)
    assert eps == float(f"{reachable_eps(7.5):.2g}") and "up to 7.50" in why
    assert loss_eps(1e-5, 7.5, 1e-3)[0] == 1e-5  # a preset below both is kept
    assert loss_eps(0.1, None, 0)[0] == 0.1  # no bound at all
    assert loss_eps(0.1, None, 1e-3)[0] == 1e-3


def test_reachable_eps_gives_the_range_asked_for():
    for change in (0.5, 2.0, 7.5):
        eps = reachable_eps(change, margin=1.2)
        assert math.log((1 + eps) / eps) == pytest.approx(1.2 * change)
    assert reachable_eps(1.0, margin=1.0) > reachable_eps(1.0, margin=2.0)


def _estimated(cfg, root):
    from hybridneus.api import load_training_data
    from hybridneus.data.estimate import estimate_scene

    return estimate_scene(load_training_data(cfg, root), cfg.estimate, cfg.data)


def _config(*overrides: str):
    from hybridneus.config import apply_overrides, preset_config

    return apply_overrides(preset_config("fast"), ["estimate.crop=false", *overrides])


def test_fit_lowers_eps_to_the_cap_and_further_where_the_events_need_it(scene):
    dark = scene(30)  # 7.5 log units: beyond what eps = 0.1 (+-2.4) or 0.001 (+-6.9) renders
    found = _estimated(_config(), dark)
    eps = found.dataset.preset.tonemap_eps
    assert math.log1p(1 / eps) >= 7.5 and 1e-5 < eps < 1e-3
    assert "up to 7.50 in one window" in found.taken["tonemap_eps"]
    assert found.eps_start == 0.1  # training eases in from the preset's eps

    faint = scene(4)  # 1.0 log units: within range, only the cap applies
    found = _estimated(_config(), faint)
    assert found.dataset.preset.tonemap_eps == 1e-3
    assert "estimate.eps_max 0.001" in found.taken["tonemap_eps"]
    nocap = _config("estimate.eps_max=0")  # no cap: the preset's is kept
    assert _estimated(nocap, faint).dataset.preset.tonemap_eps == 0.1
    assert 1e-5 < _estimated(nocap, dark).dataset.preset.tonemap_eps < 1e-3  # need alone

    off = _config("estimate.tonemap_eps=false")
    assert _estimated(off, dark).dataset.preset.tonemap_eps == 0.1
    given = _config("data.tonemap_eps=0.05")  # the user's wins
    assert _estimated(given, dark).dataset.preset.tonemap_eps == 0.05


def test_a_preset_eps_below_the_cap_is_kept(scene):
    root = scene(4)
    (root / "scene.json").write_text('{"preset": {"tonemap_eps": 1e-5}}')  # the real groups'
    found = _estimated(_config(), root)
    assert found.dataset.preset.tonemap_eps == 1e-5
    assert "tonemap_eps" not in found.taken
    assert found.eps_start is None  # nothing lowered, nothing to ease in


def test_training_eases_eps_from_the_preset_into_the_lowered_one(scene):
    import sys

    from hybridneus.api import prepare

    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from fitting import tiny

    root = scene(30)
    trainer, _ = prepare(root, tiny("train.iters=100", "estimate.eps_ease=0.5",
                                    "estimate.crop=false"), device="cpu")
    end = trainer.scene["tonemap_eps"]
    assert trainer.record.eps_start == 0.1 and end < 1e-3
    at = {}
    for step in (0, 25, 50, 90):
        trainer.step = step
        at[step] = trainer.tonemap_eps()
    assert at[0] == pytest.approx(0.1) and at[25] == pytest.approx(math.sqrt(0.1 * end))
    assert at[50] == at[90] == end
