"""Event frames, windows (half-open, wrapping), Bayer mask, negative sampling, batches."""

from __future__ import annotations

import sys
from dataclasses import replace
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
from hybridneus.errors import ConfigError, DatasetError  # noqa: E402

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


def test_a_steps_pixels_are_shared_among_windows_and_joined_in_order(tmp_path):
    from hybridneus.data.windows import concat_batches

    ds = _split(tmp_path, random_events(3000, 5, seed=1))
    s = EventWindowSampler(ds.splits["train"], ds.preset, seed=0)
    parts = s.sample_windows(10, 3)
    assert [len(b) for b in parts] == [4, 3, 3]
    assert len({(b.view0, b.view1) for b in parts}) > 1  # windows of their own
    joined = concat_batches(parts)
    assert len(joined) == 10 and joined.view1 == parts[0].view1
    for name in ("origins0", "dirs1", "target", "bayer", "xy"):
        torch.testing.assert_close(getattr(joined, name),
                                   torch.cat([getattr(b, name) for b in parts]))
    assert concat_batches(parts[:1]) is parts[0]
    # one window per step is the plain batch, drawn with the same random numbers
    again = EventWindowSampler(ds.splits["train"], ds.preset, seed=0)
    one = EventWindowSampler(ds.splits["train"], ds.preset, seed=0).sample_windows(8, 1)
    torch.testing.assert_close(one[0].target, again.sample(8).target)
    assert [len(b) for b in s.sample_windows(2, 5)] == [1, 1]  # never a window without pixels


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


def _looking_from(directions: np.ndarray) -> np.ndarray:
    """(n, 4, 4) poses whose forward axes are ``-directions`` (only the axes matter here)."""
    c2w = np.tile(np.eye(4), (len(directions), 1, 1))
    c2w[:, :3, 2] = -directions / np.linalg.norm(directions, axis=1, keepdims=True)
    return c2w


def test_direction_weights_even_out_a_bunched_path():
    from hybridneus.data.windows import direction_weights

    rng = np.random.default_rng(0)
    bunched = np.array([1.0, 0.0, 0.0]) + 0.005 * rng.normal(size=(90, 3))  # within a degree
    angles = np.deg2rad(20.0 * np.arange(1, 11))
    spread = np.stack([np.cos(angles), np.sin(angles), np.zeros(10)], axis=1)  # 20 deg apart
    w = direction_weights(_looking_from(np.concatenate([bunched, spread])))
    assert w.sum() == pytest.approx(1.0) and (w > 0).all()
    assert w[:90].sum() == pytest.approx(1 / 11) and w[90:] == pytest.approx([1 / 11] * 10)


def test_view_balance_draws_end_views_by_direction(tmp_path):
    from hybridneus.data.windows import direction_weights

    ds = _split(tmp_path, random_events(500, 21), n_views=21, max_window=5)
    sp = ds.splits["train"]
    directions = np.zeros((21, 3))
    directions[:16] = [1.0, 0.0, 0.0]  # views 0..15 look alike
    angles = np.deg2rad(30.0 * np.arange(1, 6))
    directions[16:] = np.stack([np.cos(angles), np.sin(angles), np.zeros(5)], axis=1)
    sp = replace(sp, c2w=_looking_from(directions))
    uniform = EventWindowSampler(sp, ds.preset, seed=0)
    assert uniform.view_p is None  # the default draws as before: every view alike
    half = EventWindowSampler(sp, ds.preset, seed=0, view_balance=0.5)
    assert ds.preset.cyclic and list(half.views) == list(range(21))  # every view is drawn
    np.testing.assert_allclose(half.view_p, 0.5 / 21 + 0.5 * direction_weights(sp.c2w))
    draws = np.array([half.draw_window()[0] for _ in range(4000)])
    lone = np.isin(draws, np.arange(16, 21)).mean()  # 5 views of 21, each its own direction
    expected = 0.5 * 5 / 21 + 0.5 * 5 / 6
    assert abs(lone - expected) < 0.03 and expected > 2 * 5 / 21


def test_non_cyclic_windows_clamped(tmp_path):
    ds = _split(tmp_path, random_events(500, 11), n_views=11, group="nerf/lego")
    assert ds.preset.cyclic is False
    s = EventWindowSampler(ds.splits["train"], ds.preset, seed=0)
    draws = np.array([s.draw_window() for _ in range(500)])
    assert np.all(draws[:, 1] >= 0) and np.all(draws[:, 0] >= 1)


def test_per_load_windows(tmp_path):
    ds = _split(tmp_path, random_events(500, 21), n_views=21, max_window=4)
    s = EventWindowSampler(ds.splits["train"], ds.preset, seed=0, window="per_load")
    seen: dict[int, float] = {}
    for _ in range(400):
        i, t0, t1 = s.draw_window()
        w = (t1 - t0) / s.dt
        assert abs(w - round(w)) < 1e-9 and 1 <= round(w) <= 4
        assert seen.setdefault(i, w) == pytest.approx(w)  # fixed per view


def test_negative_sampling_ratio(tmp_path):
    # 4 active pixels out of W * H = 384.
    ev = _events([1, 5, 9, 13], [1, 2, 3, 4], [0.5, 1.0, 1.5, 2.0], [1, -1, 1, 1])
    ev["t"][-1] = 4.0
    ds = _split(tmp_path, ev, neg_ratio=0.2, polarity_offset=0.0)
    s = EventWindowSampler(ds.splits["train"], ds.preset, seed=0)
    _fixed(s, 3, 0.0, 3.0)
    n = 20000
    b = s.sample(n)
    on_events = (b.target != 0).double().mean().item()
    expect = 0.8 + 0.2 * 4 / (W * H)
    assert abs(on_events - expect) < 0.015
    # With neg_ratio 0 every pixel has events; with 1 they are uniform.
    s.preset = replace(s.preset, neg_ratio=0.0)
    assert bool((s.sample(500).target != 0).all())
    s.preset = replace(s.preset, neg_ratio=1.0)
    assert (s.sample(5000).target != 0).double().mean().item() < 0.05


def test_empty_window_samples_uniformly(tmp_path):
    ev = _events([1], [1], [4.0], [1])
    ds = _split(tmp_path, ev)
    s = EventWindowSampler(ds.splits["train"], ds.preset, seed=0)
    _fixed(s, 2, 1.0, 2.0)
    b = s.sample(100)
    assert torch.all(b.target == 0) and len(b) == 100


def test_sampler_input_errors(tmp_path):
    ds = _split(tmp_path, random_events(50, 5))
    with pytest.raises(ConfigError, match="window"):
        EventWindowSampler(ds.splits["train"], ds.preset, window="sometimes")
    ds1 = _split(tmp_path / "one", _events([1], [1], [2.0], [1]), n_views=1)
    with pytest.raises(DatasetError, match="at least 2 views"):
        EventWindowSampler(ds1.splits["train"], ds1.preset)


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")
def test_batch_on_cuda(tmp_path):
    ds = _split(tmp_path, random_events(3000, 5, seed=1))
    s_cpu = EventWindowSampler(ds.splits["train"], ds.preset, seed=4)
    s_gpu = EventWindowSampler(ds.splits["train"], ds.preset, seed=4, device="cuda")
    a, b = s_cpu.sample(128), s_gpu.sample(128)
    assert b.dirs0.device.type == "cuda" and b.target.device.type == "cuda"
    assert torch.equal(a.xy, b.xy.cpu()) and torch.allclose(a.dirs1, b.dirs1.cpu())
    assert a.to("cuda").origins0.device.type == "cuda"


def test_event_frame_refuses_more_than_one_loop(tmp_path):
    sp = _split(tmp_path, random_events(50, 5)).splits["train"]
    with pytest.raises(ValueError, match="more than one loop"):
        event_frame(sp, -sp.t_max - 1.0, 1.0)
