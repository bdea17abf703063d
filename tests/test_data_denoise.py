"""The background-activity filter: company counts, the bar it sets, and the training split."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from hybridneus.data.dataset import SplitData
from hybridneus.data.denoise import (
    SURVIVAL,
    company_bar,
    denoised_split,
    event_company,
    signal_events,
)
from hybridneus.data.events import EventStream

W, H = 64, 48


def _stream(x, y, t, p=None) -> EventStream:
    order = np.argsort(np.asarray(t, dtype=np.float64), kind="stable")
    n = len(order)
    p = np.ones(n) if p is None else np.asarray(p)
    return EventStream(np.asarray(x, np.int16)[order], np.asarray(y, np.int16)[order],
                       np.asarray(t, np.float64)[order], np.asarray(p, np.int8)[order])


def _split(events: EventStream, n_views: int) -> SplitData:
    return SplitData(
        name="train", path=Path("train"), c2w=np.tile(np.eye(4), (n_views, 1, 1)),
        intrinsics=np.tile(np.eye(3), (n_views, 1, 1)), distortion=np.zeros((n_views, 2)),
        width=W, height=H, view_names=[f"{i:04d}" for i in range(n_views)], events=events,
    )


def test_company_counts_other_pixels_within_the_square_and_one_slab():
    # (column, row, time) with dt = 1: slabs 0, 0, 1 and 3; a hot pixel fires three times
    ev = _stream([30, 30, 30, 10, 13, 11, 12], [30, 30, 30, 10, 10, 10, 12],
                 [0.1, 0.2, 0.3, 0.5, 0.5, 1.5, 3.5])
    company = event_company(ev, W, H, dt=1.0)
    # the hot pixel's repeats are its own; (13, 10) is 3 columns from (10, 10) but 2 from
    # (11, 10); (12, 12) is two slabs after everything else
    assert company.tolist() == [0, 0, 0, 1, 1, 2, 0]
    assert event_company(ev, W, H, dt=1.0, radius=1).tolist() == [0, 0, 0, 1, 0, 1, 0]
    with pytest.raises(ValueError, match="dt must be > 0"):
        event_company(ev, W, H, dt=0.0)


def test_company_is_the_same_whatever_the_chunking(monkeypatch):
    import hybridneus.data.denoise as dn

    rng = np.random.default_rng(0)
    n = 20000
    ev = _stream(rng.integers(0, W, n), rng.integers(0, H, n), rng.random(n) * 50.0)
    whole = event_company(ev, W, H, dt=0.7)
    monkeypatch.setattr(dn, "_CHUNK_CELLS", 3 * W * H)  # one slab per chunk
    assert np.array_equal(event_company(ev, W, H, dt=0.7), whole)
    assert whole.max() > 0


def _edge_and_noise(n_views: int, noise_rate: float, seed: int = 0):
    """A vertical edge sweeping across the image again and again (every row fires as it
    enters a column),
    background activity of ``noise_rate`` events per pixel per view, and two hot pixels.
    Returns the stream and a mask of its noise events."""
    rng = np.random.default_rng(seed)
    # a sweep over columns 8..39 starts every 50 views, 1 column a view (the object takes
    # half of the image: noise alone fires in the rest)
    sweeps = np.arange(0, n_views - 40, 50)
    cols = np.tile(np.arange(8, 40), sweeps.size)
    t_col = np.repeat(sweeps, 32) + cols - 8
    ex = np.repeat(cols, H)
    ey = np.tile(np.arange(H), cols.size)
    et = np.repeat(t_col, H) + rng.normal(0.0, 0.05, ex.size).clip(-0.2, 0.2)
    n_noise = rng.poisson(noise_rate * W * H * (n_views - 1))
    nx, ny = rng.integers(0, W, n_noise), rng.integers(0, H, n_noise)
    nt = rng.random(n_noise) * (n_views - 1)
    hot_t = np.arange(0.0, n_views - 1, 0.3)
    hx = np.concatenate([np.full(hot_t.size, 3), np.full(hot_t.size, W - 3)])
    hy = np.full(hx.size, 5)
    ht = np.concatenate([hot_t, hot_t])
    x = np.concatenate([ex, nx, hx])
    y = np.concatenate([ey, ny, hy])
    t = np.concatenate([et, nt, ht]).clip(0.0, n_views - 1)
    noise = np.concatenate([np.zeros(ex.size, bool), np.ones(nx.size + hx.size, bool)])
    t[0] = n_views - 1  # the capture ends at the last view, whichever event marks it
    order = np.argsort(t, kind="stable")
    return _stream(x[order], y[order], t[order]), noise[order]


def test_noise_is_filtered_and_the_edge_kept():
    n_views = 200
    ev, noise = _edge_and_noise(n_views, noise_rate=0.004)
    split = _split(ev, n_views)
    kept, report = denoised_split(split)
    assert report.bar >= 2
    keep, found = signal_events(ev, W, H, dt=2.0)
    assert found.bar == report.bar
    assert keep[~noise].mean() > 0.97  # the edge
    # background activity and hot pixels away from the edge (beside it, noise has company)
    since = ev.t % 50
    edge_col = np.where(since <= 31, 8 + since, -100)
    far = noise & (np.abs(ev.x - edge_col) > 8)  # 1 column a view, slabs of 2 views
    assert far.sum() > 0.5 * noise.sum() and keep[far].mean() < 0.05
    # what is left of it is about the share the bar allows (SURVIVAL of all events)
    assert keep[far].sum() < 2 * SURVIVAL * len(ev)
    # the estimate is of background activity: a hot pixel counts once per slab
    hot = noise & (ev.y == 5) & ((ev.x == 3) | (ev.x == W - 3))
    assert report.noise_share == pytest.approx((noise & ~hot).mean(), rel=0.2)
    assert len(kept.events) == report.kept == int(keep.sum())
    # views stay where the file put them, whichever event was last
    assert kept.t_max == split.t_max == n_views - 1
    assert "look like sensor noise" in report.line()


def test_a_clean_stream_is_left_whole():
    ev, noise = _edge_and_noise(200, noise_rate=0.0)
    assert noise.sum() == 2 * np.arange(0.0, 199, 0.3).size  # only the hot pixels
    clean = _stream(ev.x[~noise], ev.y[~noise], ev.t[~noise])
    split = _split(clean, 200)
    kept, report = denoised_split(split)
    assert kept is split and report.bar == 0 and report.kept == len(clean)
    assert "keeps all" in report.line()


def test_a_fit_trains_on_the_events_the_filter_keeps():
    from hybridneus.config import Config
    from hybridneus.data.estimate import training_data

    ev, noise = _edge_and_noise(200, noise_rate=0.004)
    split = _split(ev, 200)

    class Data:
        root = None

        def __getitem__(self, name):
            return split

    cfg = Config()
    cfg.priors.hull.enabled = False
    trained = training_data(Data(), cfg).split.events
    filtered = denoised_split(split)[0].events
    assert len(trained) == len(filtered) < len(ev)
    assert np.array_equal(trained.t, filtered.t) and np.array_equal(trained.x, filtered.x)
    # the share of noise among the pixels a window's rays are drawn from falls
    keep, _ = signal_events(ev, W, H, dt=2.0)
    assert noise[keep].mean() < 0.25 * noise.mean()
    cfg.estimate.denoise = False
    assert training_data(Data(), cfg).split.events is ev
    # a clean stream is trained on whole, as it is
    clean = _split(_stream(ev.x[~noise], ev.y[~noise], ev.t[~noise]), 200)
    Data.__getitem__ = lambda self, name: clean
    cfg.estimate.denoise = True
    assert training_data(Data(), cfg).split is clean


def test_noise_too_dense_to_measure_keeps_every_event():
    rng = np.random.default_rng(2)
    n = 200_000  # about 0.3 events per pixel and slab: most events have company by chance
    ev = _stream(rng.integers(0, W, n), rng.integers(0, H, n), rng.random(n) * 99.0)
    kept, report = denoised_split(_split(ev, 100))
    assert report.bar == 0 and len(kept.events) == n
    assert "too dense" in report.line()
    bar = company_bar(alone=10, events=10, cells=10)  # every cell with a lone event
    assert bar.bar == 0 and math.isnan(bar.noise_rate)
