"""The contrast thresholds that a split's frames and the events between them imply.

Events alone do not fix the threshold C. A field whose log-brightness contrast around the
background is scaled by k explains the same events with ``k * C``, as long as its colours stay
within [0, 1]; and since the event loss's residual (the quantisation of the brightness into
whole events, noise events) scales with k too, a fit that learned C from the event loss alone
would shrink C and the field's contrast together. What the events do fix is the ratio of the
ON and OFF thresholds (a pixel that brightens and darkens again fires
``n_on * C_on = n_off * C_off``; :mod:`hybridneus.data.balance` estimates it).

Frames taken at the views' times break the scale: between frames i and j a pixel's log
brightness changes by ``dL = L_j - L_i`` with ``L = log(c**2.2 + eps)`` of its mosaic channel
(the model the event loss uses), and the events between them count
``dL ~ C_on * n_on - C_off * n_off``, up to the two ends' sub-threshold residuals. A robust
(soft-L1) least-squares fit of ``dL`` against ``(n_on, -n_off)`` over the pixels with events
gives both thresholds. Frames that do not show the events' brightness (placeholders, another
exposure, another camera) explain little of ``dL``'s variance; the estimate then says so and
returns no value.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybridneus.data.dataset import SplitData
from hybridneus.data.presets import ScenePreset

__all__ = ["ThresholdEstimate", "estimate_thresholds"]

#: The least share of ``dL``'s variance the fitted thresholds must explain.
MIN_EXPLAINED = 0.5
#: The fewest pixels with events the estimate needs.
MIN_PIXELS = 2000


@dataclass(frozen=True)
class ThresholdEstimate:
    """Thresholds fitted to frame log-brightness changes.

    Attributes:
        on: threshold of ON (brightening) events, log units.
        off: threshold of OFF events.
        explained: share of ``dL``'s variance the fit explains (1: all), over the pixels used.
        pixels: pixel samples (pixel x frame pair) the fit used.
    """

    on: float
    off: float
    explained: float
    pixels: int

    @property
    def threshold(self) -> float:
        """The preset's ``C``: the mean of the two."""
        return 0.5 * (self.on + self.off)

    @property
    def polarity_offset(self) -> float:
        """The preset's polarity offset ``o``, with ``C_on = C (1 + o)``, ``C_off = C (1 - o)``."""
        return (self.on - self.off) / (self.on + self.off)

    def line(self) -> str:
        """One line for the log and ``hybridneus info``."""
        return (f"thresholds from the frames: ON {self.on:.4g}, OFF {self.off:.4g} (C "
                f"{self.threshold:.4g}, polarity offset {self.polarity_offset:+.3f}; "
                f"{100 * self.explained:.0f}% of the frames' log-brightness changes explained "
                f"over {self.pixels} pixels)")


def _log_brightness(frame: np.ndarray, weights: np.ndarray, eps: float) -> np.ndarray:
    c = frame.reshape(-1, 3).astype(np.float64) / 255.0
    return (weights * np.log(c**2.2 + eps)).sum(axis=1)


def _latest_polarity(pixel: np.ndarray, polarity: np.ndarray, n_pixels: int) -> np.ndarray:
    """(n_pixels,) int8 polarity of each pixel's last event in time order (0: none)."""
    out = np.zeros(n_pixels, dtype=np.int8)
    last, first_of_reversed = np.unique(pixel[::-1], return_index=True)
    out[last] = polarity[::-1][first_of_reversed]
    return out


def estimate_thresholds(
    split: SplitData,
    preset: ScenePreset,
    span: int = 1,
    n_pairs: int = 128,
    max_pixels: int = 200_000,
    seed: int = 0,
) -> tuple[ThresholdEstimate | None, str]:
    """ON and OFF thresholds from the split's ``rgb/`` frames and its events.

    Args:
        split: the split; its ``rgb_paths`` must name the frames at the views' times.
        preset: image size, mosaic and ``tonemap_eps`` (the sensor's log mapping).
        span: views between the two frames of a pair. One: each pixel's own threshold
            (sensors differ from pixel to pixel) then adds least to the error, which grows
            with the events counted.
        n_pairs: frame pairs, spread evenly over the split.
        max_pixels: at most this many pixel samples go into the fit (drawn at random).
        seed: random seed of that draw.

    Returns:
        The estimate, or ``None`` with the reason why none was made (no frames, unreadable
        frames, too few pixels with events, or frames that do not explain the events).
    """
    from scipy.optimize import least_squares

    from hybridneus.data.frames import load_frames
    from hybridneus.data.mosaic import mosaic_weights
    from hybridneus.data.windows import event_counter
    from hybridneus.errors import DatasetError

    if split.rgb_paths is None:
        return None, "no rgb/ frames"
    n = split.n_views
    if n < 2:
        return None, "fewer than two views"
    span = max(1, min(span, n - 1))
    starts = np.unique(np.linspace(0, n - 1 - span, num=max(1, n_pairs)).round().astype(int))
    needed = sorted(set(starts) | set(starts + span))
    try:
        loaded = load_frames(split, preset.width, preset.height, [int(v) for v in needed])
    except DatasetError as exc:
        return None, f"frames not usable ({exc})"
    frames = dict(zip(needed, loaded, strict=True))
    h, w = preset.height, preset.width
    ys, xs = np.mgrid[0:h, 0:w]
    weights = mosaic_weights(np.stack([xs.ravel(), ys.ravel()], axis=1), preset.mosaic)
    times = split.view_times
    ev = split.events
    pixel = ev.y.astype(np.int64) * w + ev.x
    counter = event_counter(split)
    columns = []
    for i in starts:
        j = i + span
        # Events of the change from frame i to frame j carry times in (t_i, t_j]; the look-back
        # before t_i finds each pixel's latest event before the window.
        b0, i0, i1 = (int(np.searchsorted(ev.t, times[k], side="right"))
                      for k in (max(i - span, 0), i, j))
        counts = counter.counts(i0, i1)  # (pixels, 2): OFF, ON
        before = _latest_polarity(pixel[b0:i0], ev.p[b0:i0], h * w)
        after = _latest_polarity(pixel[i0:i1], ev.p[i0:i1], h * w)
        a, b = frames[i].reshape(-1, 3), frames[j].reshape(-1, 3)
        usable = ((counts.sum(axis=1) > 0) & (a.min(axis=1) > 4) & (b.min(axis=1) > 4)
                  & (a.max(axis=1) < 251) & (b.max(axis=1) < 251))
        dl = _log_brightness(frames[j], weights, preset.tonemap_eps) - _log_brightness(
            frames[i], weights, preset.tonemap_eps)
        # A pixel's brightness sits on average half a threshold past the level of its latest
        # event, on that event's side: the window's ends add half an ON (OFF) threshold per
        # end whose latest event was ON (OFF), with the start's counted negative.
        on = counts[:, 1] + 0.5 * ((after == 1).astype(float) - (before == 1))
        off = counts[:, 0] + 0.5 * ((after == -1).astype(float) - (before == -1))
        columns.append(np.stack([dl, on, off], axis=1)[usable])
    d, on, off = np.concatenate(columns).T
    if d.size < MIN_PIXELS:
        return None, f"only {d.size} pixels with events in frames neither black nor saturated"
    if d.size > max_pixels:
        keep = np.random.default_rng(seed).choice(d.size, max_pixels, replace=False)
        d, on, off = d[keep], on[keep], off[keep]
    # Least squares for a start, then a soft-L1 fit that hot pixels and noise events move less.
    start, *_ = np.linalg.lstsq(np.stack([on, -off], axis=1), d, rcond=None)
    scale = max(float(np.median(np.abs(d))), 1e-3)
    fit = least_squares(lambda c: c[0] * on - c[1] * off - d, np.clip(start, 1e-3, None),
                        loss="soft_l1", f_scale=scale, bounds=(1e-4, np.inf))
    c_on, c_off = (float(v) for v in fit.x)
    residual = c_on * on - c_off * off - d
    explained = 1.0 - float(np.var(residual) / max(np.var(d), 1e-12))
    if explained < MIN_EXPLAINED:
        return None, (f"the frames explain only {100 * max(explained, 0):.0f}% of the events' "
                      "changes (placeholders, or frames of another exposure or camera?)")
    return ThresholdEstimate(c_on, c_off, explained, int(d.size)), ""
