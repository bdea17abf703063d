"""Event frames, windows (half-open, wrapping), Bayer mask, negative sampling, batches."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_data_builder import H, W, random_events, write_split  # noqa: E402

from hybridneus.data import (  # noqa: E402
    EventCounter,
    EventWindowSampler,
    bayer_mask,
    camera_rays,
    event_frame,
    interpolate_pose,
    load_dataset,
)

SIZE = {"width": W, "height": H}


def _events(x, y, t, p) -> dict:
    return {
        "x": np.asarray(x, dtype=np.int16),
        "y": np.asarray(y, dtype=np.int16),
        "t": np.asarray(t, dtype=np.float64),
        "p": np.asarray(p, dtype=np.int8),
    }


def _split(tmp_path, events, n_views=5, group="real/multimeter", **over):
    root = tmp_path / group
    write_split(root / "train", n_views=n_views, events=events)
    return load_dataset(root, overrides={**SIZE, **over})


def test_event_lands_at_row_y_column_x(tmp_path):
    ds = _split(tmp_path, _events([5, 1], [2, 1], [1.0, 4.0], [1, -1]))
    sp = ds.splits["train"]
    f = event_frame(sp, 0.0, 2.0)
    assert f.shape == (H, W) and f.dtype == np.float32
    assert f[2, 5] == 1.0 and np.count_nonzero(f) == 1
    f = event_frame(sp, 0.0, 2.0, polarity_offset=-0.4)
    assert f[2, 5] == pytest.approx(0.6)


def test_polarity_offset_sum(tmp_path):
    # Three events on one pixel: +1, +1, -1 -> sum(p + off) = 1 + 3 * off.
    ds = _split(tmp_path, _events([3, 3, 3, 0], [4, 4, 4, 0], [0.5, 1, 1.5, 4], [1, 1, -1, 1]))
    f = event_frame(ds.splits["train"], 0.0, 2.0, polarity_offset=-0.25)
    assert f[4, 3] == pytest.approx(1 - 0.75)


def test_window_is_half_open(tmp_path):
    ds = _split(tmp_path, _events([1, 2, 3], [0, 0, 0], [1.0, 2.0, 4.0], [1, 1, 1]))
    f = event_frame(ds.splits["train"], 1.0, 2.0)
    assert f[0, 1] == 1 and f[0, 2] == 0  # t0 included, t1 excluded


def test_cyclic_wrap(tmp_path):
    ev = _events([1, 2, 3, 4], [0, 0, 0, 0], [0.0, 0.5, 3.5, 4.0], [1, 1, 1, -1])
    sp = _split(tmp_path, ev).splits["train"]
    f = event_frame(sp, -1.0, 0.6)  # [3.0, 4.0] and [0, 0.6)
    np.testing.assert_array_equal(f[0, :5], [0, 1, 1, 1, -1])
    f = event_frame(sp, -0.2, 0.4)  # [3.8, 4.0] and [0, 0.4)
    np.testing.assert_array_equal(f[0, :5], [0, 1, 0, 0, -1])


def test_bayer_positions():
    xy = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [4, 2], [5, 3], [7, 2], [2, 5]])
    m = bayer_mask(xy)
    expect = ["R", "G", "G", "B", "R", "B", "G", "G"]
    names = np.array(["R", "G", "B"])[m.argmax(1)]
    assert list(names) == expect
    assert np.all(m.sum(1) == 1) and m.dtype == np.float32


def test_counter_checkpoints_match_plain_bincount(tmp_path):
    ev = random_events(20000, 5, seed=3)
    sp = _split(tmp_path, ev).splits["train"]
    counter = EventCounter(sp.events, W, H, max_bytes=20 * W * H * 2 * 4, min_stride=100)
    assert counter.stride < 2000
    code = sp.events.pixel_code(W)
    rng = np.random.default_rng(0)
    for _ in range(30):
        i0, i1 = np.sort(rng.integers(0, len(code) + 1, 2))
        ref = np.bincount(code[i0:i1], minlength=2 * W * H).reshape(-1, 2)
        np.testing.assert_array_equal(counter.counts(int(i0), int(i1)), ref)
    assert counter._cum is not None  # the checkpoint path was used


def _fixed(sampler, i, t0, t1):
    sampler.draw_window = lambda: (i, t0, t1)


def test_batch_target_rays_and_dtypes(tmp_path):
    ds = _split(tmp_path, random_events(3000, 5, seed=1))
    sp, preset = ds.splits["train"], ds.preset
    s = EventWindowSampler(sp, preset, seed=0)
    _fixed(s, 3, 1.5, 3.0)
    b = s.sample(256)
    assert len(b) == 256
    for name in ("origins0", "dirs0", "origins1", "dirs1"):
        t = getattr(b, name)
        assert t.shape == (256, 3) and t.dtype == torch.float32
    assert b.xy.dtype == torch.int64 and b.bayer.shape == (256, 3)
    frame = event_frame(sp, 1.5, 3.0, preset.polarity_offset)
    xy = b.xy.numpy()
    np.testing.assert_allclose(b.target.numpy(), preset.threshold * frame[xy[:, 1], xy[:, 0]],
                               rtol=1e-6)
    np.testing.assert_array_equal(b.bayer.numpy(), bayer_mask(xy))
    # t1 camera: view 3; t0 camera halfway between views 1 and 2 (t = 1.5, dt = 1).
    o1, d1 = camera_rays(sp.intrinsics[3], sp.distortion[3], sp.c2w[3], xy)
    assert torch.allclose(b.origins1, o1) and torch.allclose(b.dirs1, d1)
    c2w0 = interpolate_pose(sp.c2w[1], sp.c2w[2], 0.5)
    _, d0 = camera_rays(sp.intrinsics[2], sp.distortion[2], c2w0, xy)
    assert torch.allclose(b.origins0[0].double(), torch.from_numpy(c2w0[:3, 3]), atol=1e-6)
    assert torch.allclose(b.dirs0, d0)
    assert b.view0 == pytest.approx(1.5) and b.view1 == 3.0
    assert b.t0 == pytest.approx(1.5 / 4) and b.t1 == pytest.approx(0.75)
    assert b.to("cpu").target.device.type == "cpu"


def test_pose_interpolation_endpoints(tmp_path):
    sp_ds = _split(tmp_path, random_events(500, 5))
    s = EventWindowSampler(sp_ds.splits["train"], sp_ds.preset)
    for k in range(5):
        c2w, nearest = s.pose_at(k * s.dt)
        np.testing.assert_allclose(c2w, sp_ds.splits["train"].c2w[k], atol=1e-12)
        assert nearest == k


def test_cyclic_wrap_in_sampler(tmp_path):
    ev = random_events(2000, 5, seed=2)
    ds = _split(tmp_path, ev)
    sp = ds.splits["train"]
    s = EventWindowSampler(sp, ds.preset, seed=0)
    _fixed(s, 1, -1.5, 1.0)  # starts 1.5 before t=0 -> camera at t = 2.5
    b = s.sample(64)
    assert b.view0 == pytest.approx(2.5)
    c2w0 = interpolate_pose(sp.c2w[2], sp.c2w[3], 0.5)
    np.testing.assert_allclose(b.origins0[0].double().numpy(), c2w0[:3, 3], atol=1e-6)
    frame = event_frame(sp, -1.5, 1.0, ds.preset.polarity_offset)
    t = ev["t"]
    inside = (t >= 2.5) | (t < 1.0)
    assert np.count_nonzero(frame) > 0
    expect = np.zeros((H, W))
    np.add.at(expect, (ev["y"][inside], ev["x"][inside]),
              ev["p"][inside] + ds.preset.polarity_offset)
    np.testing.assert_allclose(frame, expect, atol=1e-4)


def test_per_iteration_window_distribution(tmp_path):
    ds = _split(tmp_path, random_events(500, 21), n_views=21, max_window=5)
    s = EventWindowSampler(ds.splits["train"], ds.preset, seed=0)
    draws = np.array([s.draw_window() for _ in range(3000)])
    views, t0, t1 = draws[:, 0], draws[:, 1], draws[:, 2]
    np.testing.assert_allclose(t1, views * s.dt)
    lengths = t1 - t0
    assert np.all(lengths > 0) and np.all(lengths <= 5 * s.dt + 1e-12)
    # Uniform in [t1 - L_max, t1): mean length L_max / 2.
    assert abs(lengths.mean() - 2.5 * s.dt) < 0.15 * s.dt
    assert np.any(t0 < 0)  # cyclic: early views wrap
    assert set(views.astype(int)) == set(range(21))
