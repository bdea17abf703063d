"""Event model of hybridneus.simulate: mosaic, crossings, timestamps, polarity offset, noise."""

from __future__ import annotations

import numpy as np
import pytest

from hybridneus.simulate import (
    EventModel,
    EventSimulator,
    NoiseConfig,
    bayer_channel,
    log_intensity,
    mosaic_rggb,
)


def _frame(h: int, w: int, rgb) -> np.ndarray:
    return np.broadcast_to(np.asarray(rgb, np.float64), (h, w, 3)).copy()


def test_mosaic_rggb_sites():
    frame = _frame(4, 6, (0.1, 0.5, 0.9))
    m = mosaic_rggb(frame)
    assert m.shape == (4, 6)
    assert np.all(m[0::2, 0::2] == 0.1)  # R: even row, even column
    assert np.all(m[0::2, 1::2] == 0.5)  # G: even row, odd column
    assert np.all(m[1::2, 0::2] == 0.5)  # G: odd row, even column
    assert np.all(m[1::2, 1::2] == 0.9)  # B: odd row, odd column
    ch = bayer_channel(4, 6)
    assert ch[0, 0] == 0 and ch[0, 1] == 1 and ch[1, 0] == 1 and ch[1, 1] == 2


@pytest.mark.parametrize("channel", [0, 1, 2])
def test_events_only_on_matching_bayer_sites(channel):
    h, w = 6, 8
    a = _frame(h, w, (0.3, 0.3, 0.3))
    b = a.copy()
    b[..., channel] = 0.9  # only one colour channel brightens
    sim = EventSimulator(a, EventModel(threshold=0.2))
    ev = sim.step(b)
    assert len(ev) > 0 and np.all(ev.p == 1)
    sites = bayer_channel(h, w)[ev.y.astype(int), ev.x.astype(int)]
    assert np.all(sites == channel)
    # every pixel of that colour fired, the same number of times
    hit = np.zeros((h, w), int)
    np.add.at(hit, (ev.y.astype(int), ev.x.astype(int)), 1)
    assert np.all(hit[bayer_channel(h, w) == channel] == hit.max())
    assert np.all(hit[bayer_channel(h, w) != channel] == 0)


def test_counts_and_interpolated_timestamps_single_pixel():
    c, eps = 0.2, 1e-3
    levels = [0.2, 0.8, 0.8, 0.1]  # up, still, down
    frames = [_frame(1, 1, (v, v, v)) for v in levels]
    sim = EventSimulator(frames[0], EventModel(threshold=c, eps=eps))
    chunks = [sim.step(f) for f in frames[1:]]
    big = log_intensity(np.array(levels), eps)
    n_up = int(np.floor((big[1] - big[0]) / c))
    assert len(chunks[0]) == n_up and np.all(chunks[0].p == 1)
    expected_t = (big[0] + c * np.arange(1, n_up + 1) - big[0]) / (big[1] - big[0])
    np.testing.assert_allclose(chunks[0].t, expected_t, rtol=0, atol=1e-12)
    assert len(chunks[1]) == 0  # no change, no events
    ref = big[0] + n_up * c
    n_down = int(np.floor((ref - big[3]) / c))
    assert len(chunks[2]) == n_down and np.all(chunks[2].p == -1)
    assert np.all((chunks[2].t > 2) & (chunks[2].t <= 3)) and np.all(np.diff(chunks[2].t) > 0)
    # the integrated events reproduce the log change to within one threshold
    total = sum(int(ch.p.astype(int).sum()) for ch in chunks)
    assert abs(total * c - (big[3] - big[0])) < c


def test_polarity_offset_integrates_to_log_change():
    o, c = -0.4, 0.1
    rng = np.random.default_rng(3)
    vals = np.concatenate([[0.5], rng.uniform(0.05, 1.0, 40)])
    frames = [_frame(2, 2, (v, v, v)) for v in vals]
    sim = EventSimulator(frames[0], EventModel(threshold=c, polarity_offset=o))
    ps = np.concatenate([sim.step(f).p for f in frames[1:]]).astype(float) / 4  # 4 pixels
    big = log_intensity(vals)
    estimate = c * (ps + o * np.abs(ps)).sum()  # per pixel: C * sum(p + o)
    assert abs(estimate - (big[-1] - big[0])) < c * (1 + abs(o))
    n_pos = (ps > 0).sum()
    assert n_pos > 0


def test_events_sorted_and_in_interval():
    rng = np.random.default_rng(0)
    frames = rng.uniform(0, 1, (5, 8, 10, 3))
    sim = EventSimulator(frames[0], EventModel(threshold=0.15))
    for k in range(1, 5):
        ev = sim.step(frames[k])
        assert ev.x.dtype == np.int16 and ev.y.dtype == np.int16
        assert ev.t.dtype == np.float64 and ev.p.dtype == np.int8
        assert np.all(np.diff(ev.t) >= 0)
        assert np.all((ev.t > k - 1) & (ev.t <= k))
        assert ev.x.max() < 10 and ev.y.max() < 8


def _run(noise: NoiseConfig, seed: int = 0, n: int = 30) -> list:
    rng = np.random.default_rng(1)
    base = rng.uniform(0.2, 0.8, (24, 32, 3))
    frames = [np.clip(base * (1 + 0.3 * np.sin(k / 3.0)), 0, 1) for k in range(n)]
    sim = EventSimulator(frames[0], EventModel(threshold=0.2), noise, seed=seed)
    return [sim.step(f) for f in frames[1:]]


def _count(chunks) -> int:
    return sum(len(c) for c in chunks)


def test_noise_changes_counts_as_expected():
    clean = _count(_run(NoiseConfig()))
    assert clean > 0
    # background activity: Poisson, rate * pixels * intervals extra events on average
    rate = 0.05
    extra = _count(_run(NoiseConfig(background_rate=rate))) - clean
    expected = rate * 24 * 32 * 29
    assert abs(extra - expected) < 5 * np.sqrt(expected)
    # hot pixels: the extra events sit on few pixels
    hot = _run(NoiseConfig(hot_pixel_fraction=0.01, hot_pixel_rate=3.0))
    assert _count(hot) > clean
    # threshold mismatch changes counts but keeps them close
    mism = _count(_run(NoiseConfig(threshold_sigma=0.05)))
    assert mism != clean and abs(mism - clean) < 0.5 * clean


def test_noise_is_seeded():
    noise = NoiseConfig(threshold_sigma=0.05, background_rate=0.05, hot_pixel_fraction=0.01)
    a, b, c = _run(noise, 1), _run(noise, 1), _run(noise, 2)
    assert all(np.array_equal(x.t, y.t) and np.array_equal(x.x, y.x)
               for x, y in zip(a, b, strict=True))
    assert not all(len(x) == len(y) and np.array_equal(x.t, y.t) for x, y in zip(a, c, strict=True))


def test_refractory_period_spaces_events():
    refr = 0.3
    chunks = _run(NoiseConfig(background_rate=0.2, refractory=refr))
    free = _run(NoiseConfig(background_rate=0.2))
    assert _count(chunks) < _count(free)
    x = np.concatenate([c.x for c in chunks]).astype(int)
    y = np.concatenate([c.y for c in chunks]).astype(int)
    t = np.concatenate([c.t for c in chunks])
    pix = y * 32 + x
    order = np.lexsort((t, pix))
    same = pix[order][1:] == pix[order][:-1]
    gaps = np.diff(t[order])[same]
    assert gaps.min() >= refr - 1e-12


def test_event_model_validation():
    with pytest.raises(ValueError):
        EventModel(threshold=0)
    with pytest.raises(ValueError):
        EventModel(polarity_offset=1.5)


def test_timestamp_jitter_moves_events_within_their_interval():
    clean = _run(NoiseConfig())
    jittered = _run(NoiseConfig(jitter=0.05))
    assert _count(clean) == _count(jittered)
    for k, (a, b) in enumerate(zip(clean, jittered, strict=True), 1):
        assert len(a) == len(b)
        assert np.all(np.diff(b.t) >= 0) and np.all((b.t > k - 1) & (b.t <= k))
    t_a = np.sort(np.concatenate([c.t for c in clean]))
    t_b = np.sort(np.concatenate([c.t for c in jittered]))
    assert 0 < np.abs(t_a - t_b).mean() < 0.05


def test_a_davis346_has_its_thresholds_and_finds_its_own_hot_pixels():
    from hybridneus.data.hot import find_hot_pixels, pixel_counts
    from hybridneus.simulate import DAVIS346_THRESHOLD, davis346_noise

    c, o = DAVIS346_THRESHOLD
    assert np.exp(c * (1 + o)) == pytest.approx(1.143) and np.exp(c * (1 - o)) == \
        pytest.approx(1.225)
    noise = davis346_noise(0.03)
    assert noise.background_rate == pytest.approx(0.003) and noise.hot_pixel_rate == \
        pytest.approx(3.0) and noise.refractory == pytest.approx(0.5 / 30)
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(1)  # a smooth texture sliding by a pixel a view
    base = 0.5 + 4 * gaussian_filter(rng.normal(0, 0.1, (120, 160, 3)), (4, 4, 0))
    frames = [np.clip(np.roll(base, k, axis=1), 0.05, 1) for k in range(60)]
    sim = EventSimulator(frames[0], EventModel(threshold=c, polarity_offset=o), noise, seed=3)
    chunks = [sim.step(f) for f in frames[1:]]
    x = np.concatenate([ch.x for ch in chunks])
    y = np.concatenate([ch.y for ch in chunks])
    hot = find_hot_pixels(pixel_counts(x, y, 160, 120))
    truth = sorted((int(i % 160), int(i // 160)) for i in sim._hot)
    assert len(truth) == 2 and sorted(hot.pixels()) == truth
    with pytest.raises(ValueError, match="view_seconds"):
        davis346_noise(0.0)
