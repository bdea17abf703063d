"""The polarity offset estimated from the events' balance, and where a fit takes it."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from hybridneus.data.balance import (
    MIN_EVENTS,
    MIN_PIXELS,
    balance_offset,
    polarity_balance,
)
from hybridneus.data.dataset import SplitData
from hybridneus.data.events import EventStream

W, H = 64, 48


def _split(x, y, t, p, n_views: int) -> SplitData:
    order = np.argsort(t, kind="stable")
    ev = EventStream(np.asarray(x, np.int16)[order], np.asarray(y, np.int16)[order],
                     np.asarray(t, np.float64)[order], np.asarray(p, np.int8)[order])
    return SplitData(
        name="train", path=Path("train"), c2w=np.tile(np.eye(4), (n_views, 1, 1)),
        intrinsics=np.tile(np.eye(3), (n_views, 1, 1)), distortion=np.zeros((n_views, 2)),
        width=W, height=H, view_names=[f"{i:04d}" for i in range(n_views)], events=ev,
    )


def _bar_and_back(offset: float, noise_rate: float, seed: int = 0,
                  threshold: float = 0.1) -> SplitData:
    """A bright bar, 6 columns wide, sweeps right over columns 8..39 and back (a closed loop
    of 1,000 views, a column every 12 views). Each pixel of rows 12..27 rises by its own step as
    the bar arrives and falls by the same step as it leaves; a sensor with polarity offset
    ``offset`` fires a positive event per ``C (1 + offset)`` of rise and a negative one per
    ``C (1 - offset)`` of fall. Balanced background activity of ``noise_rate`` events per
    pixel and view and two hot pixels (one polarity each) come on top."""
    rng = np.random.default_rng(seed)
    c_pos, c_neg = threshold * (1 + offset), threshold * (1 - offset)
    step = rng.uniform(0.5, 1.5, (W, H))
    n_up, n_down = (step // c_pos).astype(int), (step // c_neg).astype(int)
    xs, ys, ts, ps = [], [], [], []
    for col in range(8, 40):
        for arrive, leave in ((col - 8, col - 2), (80 - col, 86 - col)):
            for t_edge, n, sign in ((arrive, n_up, 1), (leave, n_down, -1)):
                count = n[col, 12:28]
                xs.append(np.full(count.sum(), col))
                ys.append(np.repeat(np.arange(12, 28), count))
                ts.append(12 * (t_edge + rng.uniform(-0.3, 0.3, count.sum())))
                ps.append(np.full(count.sum(), sign))
    n_views = 1000
    n_noise = rng.poisson(noise_rate * W * H * (n_views - 1))
    xs.append(rng.integers(0, W, n_noise))
    ys.append(rng.integers(0, H, n_noise))
    ts.append(rng.random(n_noise) * (n_views - 1))
    ps.append(rng.choice([-1, 1], n_noise))
    hot_t = np.arange(0.0, n_views - 1, 0.5)
    for hx, sign in ((2, 1), (W - 2, -1)):
        xs.append(np.full(hot_t.size, hx))
        ys.append(np.full(hot_t.size, 45))
        ts.append(hot_t)
        ps.append(np.full(hot_t.size, sign))
    t = np.clip(np.concatenate(ts), 0.0, n_views - 1)
    t[0] = n_views - 1
    return _split(np.concatenate(xs), np.concatenate(ys), t, np.concatenate(ps), n_views)


@pytest.mark.parametrize("offset", [-0.4, -0.2, 0.25])
def test_a_closed_loop_gives_its_offset_back_through_noise_and_hot_pixels(offset):
    # 5 background events per pixel: many pixels away from the bar pass MIN_EVENTS on noise
    split = _bar_and_back(offset, noise_rate=0.005)
    found = polarity_balance(split)
    assert found.offset == pytest.approx(offset, abs=0.02) and not found.dense_noise
    assert found.suggested() == round(found.offset, 3)
    assert "imply an offset" in found.line() and "after the noise filter" in found.line()
    # without the filter those pixels pull the median towards 0
    raw = balance_offset(split.events, W, H)
    assert abs(raw.offset - offset) > abs(found.offset - offset) + 0.015
    assert abs(raw.offset) < abs(offset)
    # the event-weighted mean, which the median replaces, leans to 0 more
    assert abs(-split.events.p.mean() - offset) > 0.05


def test_balanced_events_read_as_offset_zero():
    found = polarity_balance(_bar_and_back(0.0, noise_rate=0.005))
    assert found.balanced and found.suggested() == 0.0
    assert "balanced" in found.line()


def test_noise_too_dense_to_filter_is_said():
    found = polarity_balance(_bar_and_back(-0.4, noise_rate=0.008))
    assert found.dense_noise and "too dense to filter" in found.line()
    assert -0.4 < found.offset < -0.05  # pulled towards 0, not past it


def test_too_few_busy_pixels_give_no_estimate():
    rng = np.random.default_rng(1)
    n = MIN_EVENTS * (MIN_PIXELS - 1)  # MIN_PIXELS - 1 pixels with MIN_EVENTS events each
    pix = np.repeat(np.arange(MIN_PIXELS - 1) * 7, MIN_EVENTS)
    split = _split(pix % W, pix // W, np.sort(rng.random(n) * 10), np.ones(n), 11)
    found = balance_offset(split.events, W, H)
    assert found.offset is None and found.suggested() is None and found.pixels == MIN_PIXELS - 1
    assert "too few pixels" in found.line()
    empty = EventStream(*(a[:0] for a in (split.events.x, split.events.y, split.events.t,
                                          split.events.p)))
    assert balance_offset(empty, W, H).offset is None


@pytest.fixture(scope="module")
def lopsided(tmp_path_factory):
    """The built-in scene on one circle (a closed loop) seen by a sensor with polarity offset
    -0.4, written twice: at a path that names no group and with its scene.json preset (which
    states the offset) removed, and under ``real/`` as an unpublished scene."""
    from hybridneus.simulate import EventModel, SimulationConfig, simulate_dataset

    root = tmp_path_factory.mktemp("balance")
    cfg = SimulationConfig(n_views=60, width=64, height=48, val_views=0, test_views=0,
                           spiral="circle", revolutions=1.0, supersample=1,
                           events=EventModel(threshold=0.1, polarity_offset=-0.4))
    custom = root / "device"
    simulate_dataset("builtin:device", custom, cfg)
    scene = json.loads((custom / "scene.json").read_text())
    scene.pop("preset", None)
    (custom / "scene.json").write_text(json.dumps(scene))
    real = root / "real" / "device"
    real.parent.mkdir()
    shutil.copytree(custom, real)
    return custom, real


def _config(*overrides: str):
    from hybridneus.config import apply_overrides, preset_config

    # the crop from the events is not what these tests are about, and it takes the time
    return apply_overrides(preset_config("fast"), ["estimate.crop=false", *overrides])


def _estimated(cfg, root):
    """The dataset a fit of ``root`` with ``cfg`` trains on: read, then estimated."""
    from hybridneus.api import load_training_data
    from hybridneus.data.estimate import estimate_scene

    return estimate_scene(load_training_data(cfg, root), cfg.estimate, cfg.data)


def test_a_fit_takes_the_offset_from_the_events_when_nothing_states_one(lopsided):
    from hybridneus.data import load_dataset

    custom, real = lopsided
    assert load_dataset(custom).preset.polarity_offset == 0.0  # the fallback's
    cfg = _config()
    found = _estimated(cfg, custom)
    assert found.dataset.preset.polarity_offset == pytest.approx(-0.4, abs=0.05)
    assert cfg.data.polarity_offset is None  # the config is not written to
    assert "from the events' balance" in found.taken["polarity_offset"]
    # an unpublished scene of the real group: the group's -0.404 is a guess, replaced too
    data = _estimated(_config(), real).dataset
    assert data.preset.group == "real"
    assert data.preset.polarity_offset == pytest.approx(-0.4, abs=0.05)
    assert data.preset.polarity_offset != -0.404
    # off: the fallback's 0 stays
    off = _config("estimate.polarity_offset=false")
    assert _estimated(off, custom).dataset.preset.polarity_offset == 0.0
    # the config states one: it is kept
    given = _config("data.polarity_offset=-0.1")
    assert _estimated(given, custom).dataset.preset.polarity_offset == -0.1


def test_a_stated_offset_is_kept_with_a_warning_when_the_events_disagree(lopsided, tmp_path,
                                                                          caplog):
    custom, _ = lopsided
    published = tmp_path / "nerf" / "lego"  # a published scene: its preset states 0
    shutil.copytree(custom, published)
    with caplog.at_level("WARNING", logger="hybridneus"):
        found = _estimated(_config(), published)
    assert found.dataset.preset.polarity_offset == 0.0
    assert any("but the events imply -0." in r.getMessage() for r in caplog.records)
    assert any("--set data.polarity_offset=" in w for w in found.warnings)


def _orbit(n_views: int, turns: float) -> np.ndarray:
    angles = np.linspace(0.0, 2 * np.pi * turns, n_views, endpoint=False)
    c2w = np.tile(np.eye(4), (n_views, 1, 1))
    c2w[:, 0, 3], c2w[:, 2, 3] = np.cos(angles), np.sin(angles)
    return c2w


def test_a_path_is_closed_when_its_cameras_come_back_to_their_start():
    from hybridneus.data.balance import closed_path

    assert closed_path(_orbit(100, 1.0))[0]  # ends one step short of its start
    assert closed_path(_orbit(100, 3.0))[0]
    still = closed_path(np.tile(np.eye(4), (5, 1, 1)))
    assert still == (True, 0.0)
    closed, gap = closed_path(_orbit(100, 0.5))  # half a turn: the far side of the circle
    chord = np.sin(99 * np.pi / 200) / np.sin(np.pi / 200)  # chords of 99 and of 1 step
    assert not closed and gap == pytest.approx(chord, rel=1e-6)
    spiral = _orbit(100, 1.0)
    spiral[:, 1, 3] = np.linspace(1.0, 0.0, 100)  # a turn that also comes down
    assert not closed_path(spiral)[0]


def test_over_an_open_path_the_balance_sets_no_offset_and_warns_of_none(lopsided, tmp_path):
    from hybridneus.data import load_dataset

    custom, _ = lopsided
    opened = tmp_path / "device"
    shutil.copytree(custom, opened)
    poses = sorted((opened / "train" / "pose").iterdir())
    for path in poses[len(poses) // 2:]:  # the second half of the orbit, lifted by 1
        m = np.loadtxt(path).reshape(4, 4)
        m[1, 3] += 1.0
        np.savetxt(path, m)
    assert load_dataset(opened).preset.polarity_offset == 0.0
    found = _estimated(_config(), opened)
    assert found.dataset.preset.polarity_offset == 0.0 and "polarity_offset" not in found.taken
    assert any("an open path" in line for line in found.lines)
    published = tmp_path / "nerf" / "lego"  # a stated 0: no warning either
    shutil.copytree(opened, published)
    assert not _estimated(_config(), published).warnings


def test_a_path_that_closes_after_its_first_views_gives_its_offset_over_the_loop(tmp_path):
    from hybridneus.data.balance import closed_span
    from hybridneus.simulate import EventModel, SimulationConfig, simulate_dataset

    # a turn and a quarter: the cameras are back where they began after 60 of 75 views
    root = tmp_path / "device"
    simulate_dataset("builtin:device", root, SimulationConfig(
        n_views=75, width=64, height=48, val_views=0, test_views=0, spiral="circle",
        revolutions=1.25, supersample=1,
        events=EventModel(threshold=0.1, polarity_offset=-0.4)))
    scene = json.loads((root / "scene.json").read_text())
    scene.pop("preset", None)
    (root / "scene.json").write_text(json.dumps(scene))
    found = _estimated(_config(), root)
    first, last = closed_span(found.dataset["train"].c2w)
    assert 60 <= last - first <= 63  # within 3 steps of where they began
    assert found.dataset.preset.polarity_offset == pytest.approx(-0.4, abs=0.05)
    assert "polarity_offset" in found.taken
    assert any(f"over views {first} .. {last}" in line for line in found.lines)
    assert closed_span(_orbit(100, 0.5)) is None  # half a turn never comes back
    spiral = _orbit(100, 2.0)
    spiral[:, 1, 3] = np.linspace(1.0, 0.0, 100)  # two turns that also come down
    assert closed_span(spiral) is None


def test_each_pixel_gets_its_own_offset_where_its_events_can_say_it():
    from hybridneus.data.balance import pixel_offsets
    from hybridneus.data.windows import event_frame

    rng = np.random.default_rng(3)
    scene, threshold = -0.2, 0.1
    own = scene + rng.normal(0.0, 0.1, (H, W))  # the sensor's threshold mismatch
    rise = np.where(np.arange(W) < W // 2, 30.0, 0.3)  # busy left half, a quiet right one
    xs, ys, ps = [], [], []
    for y in range(H):
        for x in range(W):
            n_pos = int(round(rise[x] / (threshold * (1 + own[y, x]))))
            n_neg = int(round(rise[x] / (threshold * (1 - own[y, x]))))
            xs += [x] * (n_pos + n_neg)
            ys += [y] * (n_pos + n_neg)
            ps += [1] * n_pos + [-1] * n_neg
    split = _split(xs, ys, rng.random(len(xs)), ps, n_views=10)
    found = pixel_offsets(split.events, W, H, scene).reshape(H, W)
    busy, quiet = found[:, : W // 2], found[:, W // 2:]
    error, spread = np.abs(busy - own[:, : W // 2]), np.abs(own[:, : W // 2] - scene)
    assert error.max() < 0.06 and error.mean() < 0.25 * spread.mean()
    assert np.abs(quiet - scene).max() < 0.05
    # the busy pixels' loops sum to no change with their own offsets, not with the scene's
    frame = event_frame(split, 0.0, 2.0, found.reshape(-1))[:, : W // 2]
    one = event_frame(split, 0.0, 2.0, scene)[:, : W // 2]
    assert np.abs(frame).mean() < 0.25 * np.abs(one).mean()


def test_a_fit_with_pixel_offsets_keeps_them_for_its_resume(lopsided, tmp_path):
    from conftest import TINY_FIT

    from hybridneus.api import fit, prepare
    from hybridneus.errors import RunError
    from hybridneus.training.scene import PIXEL_OFFSETS, SceneRecord

    custom, _ = lopsided
    cfg = _config(*TINY_FIT, "train.iters=2", "estimate.pixel_offsets=true")
    run = fit(custom, cfg, out=tmp_path / "runs", device="cpu", report=False).run_dir
    assert SceneRecord.load(run / "scene.yaml").pixel_offsets == PIXEL_OFFSETS
    saved = np.load(run / PIXEL_OFFSETS)
    # a simulated sensor with no threshold mismatch: its pixels' balances spread no more
    # than their counts explain, and each keeps the scene's offset
    assert saved.shape == (W * H,) and np.ptp(saved) < 1e-6
    assert saved.mean() == pytest.approx(-0.4, abs=0.05)
    trainer, _ = prepare(None, None, overrides=["train.iters=3"], resume=run, device="cpu")
    assert np.array_equal(trainer.windows.split.pixel_offset, saved)
    # a stated offset: no pixel of its own
    stated = _config("data.polarity_offset=-0.1", "estimate.pixel_offsets=true")
    assert _estimated(stated, custom).dataset["train"].pixel_offset is None
    (run / PIXEL_OFFSETS).write_bytes(b"not numpy")
    with pytest.raises(RunError, match=f"{PIXEL_OFFSETS}: cannot read"):
        prepare(None, None, overrides=["train.iters=3"], resume=run, device="cpu")
