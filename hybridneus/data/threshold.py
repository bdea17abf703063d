"""The contrast thresholds that a split's frames and its events imply.

Events alone do not fix the threshold C. A field whose log-brightness contrast around the
background is scaled by k explains the same events with ``k * C``, as long as its colours stay
within [0, 1]; and since the event loss's residual (the quantisation of the brightness into
whole events, noise events) scales with k too, a fit that learned C from the event loss alone
would shrink C and the field's contrast together. What the events do fix is the ratio of the
ON and OFF thresholds (a pixel that brightens and darkens again fires
``n_on * C_on = n_off * C_off``; :mod:`hybridneus.data.balance` estimates it).

Frames taken at the views' times break the scale. A pixel's events do not follow the change
between two frames alone: each pixel fires against its own reference level, which lags its
brightness by up to a threshold, so a small change fires at one pixel and not at the next, and
a pixel that rose and fell back below a threshold fires nothing. A least-squares fit of frame
differences against the counts between them cannot see that state; it read 0.14 / 0.16 for ON
/ OFF thresholds of 0.2 / 0.3 on a textured asset. So the estimate *replays* the sensor
instead: over a run of consecutive frames it follows every pixel's log brightness ``L =
log(c**2.2 + eps)`` of its mosaic channel (the model the event loss uses), linear in time
between frames, from a reference at the first frame, firing ON (OFF) events whenever ``L``
passes the reference by ``C_on`` (``C_off``) and moving the reference by a whole threshold
(:func:`replay_counts`). The thresholds are those whose replay fires as many ON and as many OFF
events as the stream holds over the same span (:func:`_solve`). Before the last solve, the stream's
background activity (its rate at pixels whose brightness never changes by half a threshold) is
taken off the totals, and hot pixels (far more events than their replay) are left out.

Between two frames the replay can only take the brightness as linear in time, so every rise and
fall that a frame interval hides goes uncounted: the replay fires too few events at a given
threshold, and the solve takes C too low, the more so the faster the camera moves between
frames. So the replay runs over the :data:`RUN_VIEWS` consecutive frames over which the camera
moved least (:func:`slowest_run`: its centre's path plus its turn times its distance from the
scene's centre, the origin of a normalised dataset).

Frames that do not show the events' brightness (placeholders, another exposure, another
camera) replay into per-pixel counts unlike the stream's; the share of the counts' variance
that the replay explains is reported, and below :data:`MIN_EXPLAINED` no value is returned.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hybridneus.data.dataset import SplitData
from hybridneus.data.presets import ScenePreset

__all__ = ["ThresholdEstimate", "estimate_thresholds", "observed_counts", "replay_counts",
           "slowest_run", "solve_thresholds"]

#: The least share of the per-pixel event counts' variance the replay must explain.
MIN_EXPLAINED = 0.5
#: The fewest events of each polarity the estimate needs.
MIN_EVENTS = 2000
#: Frame values (of 255) at or beyond which a pixel's brightness is not known: black, saturated.
DARK, BRIGHT = 4, 251
#: Why no estimate is made from frames whose replay fires nothing.
STILL_FRAMES = "the frames do not change: a replay of them fires no events"
#: Pixels whose log brightness spans less than this are left out of the first solve.
MIN_CHANGE = 0.02
#: A pixel is hot when it fires more than this many times its replay's events (plus
#: :data:`HOT_SLACK`).
HOT_FACTOR, HOT_SLACK = 4.0, 10.0
#: Consecutive frames the replay runs over: the stretch where the camera moved least.
RUN_VIEWS = 60


@dataclass(frozen=True)
class ThresholdEstimate:
    """Thresholds whose replay of the frames fires the stream's events.

    Attributes:
        on: threshold of ON (brightening) events, log units.
        off: threshold of OFF events.
        explained: share of the per-pixel ON and OFF counts' variance that the replay
            explains (1: all), over the pixels used.
        pixels: pixels the replay followed.
        views: consecutive frames it followed them over.
        noise_rate: background events per pixel and frame interval taken off the totals.
        first: the first view of the run replayed.
    """

    on: float
    off: float
    explained: float
    pixels: int
    views: int = 0
    noise_rate: float = 0.0
    first: int = 0

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
                f"{self.threshold:.4g}, polarity offset {self.polarity_offset:+.3f}; the "
                f"sensor replayed over frames {self.first} .. {self.first + self.views - 1}, "
                "where the camera moved least, explains "
                f"{100 * self.explained:.0f}% of the event counts of {self.pixels} pixels)")


def replay_counts(log_frames: np.ndarray, c_on: float, c_off: float) -> tuple[np.ndarray,
                                                                           np.ndarray]:
    """ON and OFF events an ideal sensor fires while watching ``log_frames``.

    Each pixel's reference starts at its first frame; between frames the log brightness is
    linear in time, so within one interval it moves one way and crosses
    ``floor((L - ref) / C_on)`` ON (or ``floor((ref - L) / C_off)`` OFF) levels, each moving
    the reference by a whole threshold (the simulator's model, :mod:`hybridneus.simulate.events`).

    Args:
        log_frames: (n_frames, n_pixels) log brightness, in time order.
        c_on: ON threshold (> 0).
        c_off: OFF threshold (> 0).

    Returns:
        (on, off): (n_pixels,) float64 event counts over the whole run.
    """
    ref = log_frames[0].astype(np.float64)
    on = np.zeros(ref.shape)
    off = np.zeros(ref.shape)
    for frame in log_frames[1:]:
        up = np.floor((frame - ref) / c_on).clip(0.0, None)
        down = np.floor((ref - frame) / c_off).clip(0.0, None)
        ref += up * c_on - down * c_off
        on += up
        off += down
    return on, off


def slowest_run(c2w: np.ndarray, views: int) -> int:
    """The first view of the ``views`` consecutive ones over which the camera moved least.

    A view's motion is its centre's step from the previous view plus the angle it turned
    (radians) times its distance from the origin (the scene's centre in a normalised
    dataset), about how far the scene slid across its image.

    Args:
        c2w: (n_views, 4, 4) camera-to-world.
        views: the run's length; the whole track when it is not longer.
    """
    from scipy.spatial.transform import Rotation

    n = c2w.shape[0]
    if n <= views:
        return 0
    step = np.linalg.norm(np.diff(c2w[:, :3, 3], axis=0), axis=1)
    rot = Rotation.from_matrix(c2w[:, :3, :3])
    turn = (rot[1:] * rot[:-1].inv()).magnitude()
    reach = np.linalg.norm(c2w[1:, :3, 3], axis=1)
    total = np.concatenate([[0.0], np.cumsum(step + turn * reach)])
    within = total[views - 1:] - total[:n - views + 1]  # motion from view a to a + views - 1
    return int(np.argmin(within))


def _log_frames(split: SplitData, preset: ScenePreset, views: range, pixels: np.ndarray,
                chunk: int = 64) -> tuple[np.ndarray, np.ndarray]:
    """(len(views), n) float32 log brightness of ``pixels`` (flat indices) in the frames of
    ``views``, and (n,) whether a pixel is neither black nor saturated in any of them."""
    from hybridneus.data.frames import load_frames
    from hybridneus.data.mosaic import mosaic_weights

    w, h = preset.width, preset.height
    weights = mosaic_weights(np.stack([pixels % w, pixels // w], axis=1), preset.mosaic)
    out = np.empty((len(views), pixels.size), dtype=np.float32)
    known = np.ones(pixels.size, dtype=bool)
    for a in range(0, len(views), chunk):
        frames = load_frames(split, w, h, list(views[a:a + chunk]))
        values = frames.reshape(len(frames), h * w, 3)[:, pixels]
        known &= (values.min(axis=(0, 2)) > DARK) & (values.max(axis=(0, 2)) < BRIGHT)
        c = values.astype(np.float32) / 255.0
        out[a:a + len(frames)] = (weights[None] * np.log(c**2.2 + preset.tonemap_eps)).sum(-1)
    return out, known


def observed_counts(ev, width: int, pixels: np.ndarray, t0: float,
                    t1: float) -> tuple[np.ndarray, np.ndarray]:
    """(n,) ON and OFF events of ``ev`` (an :class:`~hybridneus.data.events.EventStream`) at
    ``pixels`` (sorted flat indices, ``y * width + x``) with times in (t0, t1]."""
    i0, i1 = (int(np.searchsorted(ev.t, t, side="right")) for t in (t0, t1))
    flat = ev.y[i0:i1].astype(np.int64) * width + ev.x[i0:i1]
    at = np.searchsorted(pixels, flat).clip(0, pixels.size - 1)
    hit = pixels[at] == flat
    positive = ev.p[i0:i1] > 0
    on = np.bincount(at[hit & positive], minlength=pixels.size).astype(np.float64)
    off = np.bincount(at[hit & ~positive], minlength=pixels.size).astype(np.float64)
    return on, off


def _solve(log_frames: np.ndarray, on_total: float, off_total: float, start: float,
           approach: int = 8, steps: int = 16) -> tuple[float, float] | None:
    """Thresholds whose replay fires ``on_total`` ON and ``off_total`` OFF events (``None``
    when the frames fire no events of a polarity at a threshold tried).

    A count falls close to as ``1 / C`` overall (a pixel that changes by ``D`` fires about
    ``D / C``), so first each step scales both thresholds by their replay's count over the
    target. But a count moves in whole events: frames of 8-bit values repeat exact brightness
    levels, and near the truth a count can jump by a tenth over half a percent of C, where
    such steps overshoot and cycle. So the last steps bisect, in log space and both
    polarities at once, within a quarter of the mean of those steps; there a count hardly
    depends on the other polarity's threshold (far from it, it does: with no OFF events a
    pixel's reference never comes down and it fires ON events only at new highs)."""
    target = np.array([on_total, off_total])

    def counts(c: np.ndarray) -> np.ndarray | None:
        n = np.array([v.sum() for v in replay_counts(log_frames, *c)])
        return None if n.min() <= 0 else n

    c = np.array([start, start], dtype=np.float64)
    path = []
    for _ in range(approach):
        n = counts(c)
        if n is None:
            return None
        c = np.clip(c * n / target, 1e-3, 10.0)
        path.append(np.log(c))
    centre = np.mean(path[-4:], axis=0)
    lo, hi = centre - np.log(1.25), centre + np.log(1.25)
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        n = counts(np.exp(mid))
        if n is None:
            return None
        above = n > target  # too many events: the threshold is higher
        lo, hi = np.where(above, mid, lo), np.where(above, hi, mid)
    c_on, c_off = (float(v) for v in np.exp(0.5 * (lo + hi)))
    return c_on, c_off


def estimate_thresholds(
    split: SplitData,
    preset: ScenePreset,
    max_pixels: int = 50_000,
    run_views: int = RUN_VIEWS,
    seed: int = 0,
) -> tuple[ThresholdEstimate | None, str]:
    """ON and OFF thresholds from the split's ``rgb/`` frames and its events (see the module
    docstring).

    Args:
        split: the split; its ``rgb_paths`` must name the frames at the views' times.
        preset: image size, mosaic, ``tonemap_eps`` (the sensor's log mapping) and the
            ``threshold`` the solve starts from.
        max_pixels: at most this many pixels (drawn at random) are replayed.
        run_views: the replay runs over this many consecutive frames, where the camera
            moved least (:func:`slowest_run`).
        seed: random seed of the pixels' draw.

    Returns:
        The estimate, or ``None`` with the reason why none was made (no frames, unreadable
        frames, too few events, frames that fire nothing, or frames that do not explain the
        events).
    """
    from hybridneus.errors import DatasetError

    if split.rgb_paths is None:
        return None, "no rgb/ frames"
    first = slowest_run(split.c2w, run_views)
    views = min(split.n_views, run_views)
    if views < 2:
        return None, "fewer than two views"
    h, w = preset.height, preset.width
    rng = np.random.default_rng(seed)
    pixels = np.sort(rng.choice(h * w, min(max_pixels, h * w), replace=False))
    try:
        log_frames, known = _log_frames(split, preset, range(first, first + views), pixels)
    except DatasetError as exc:
        return None, f"frames not usable ({exc})"
    times = split.view_times
    on, off = observed_counts(split.events, split.width, pixels, float(times[first]),
                              float(times[first + views - 1]))
    return solve_thresholds(log_frames[:, known], on[known], off[known],
                            float(preset.threshold), first)


def solve_thresholds(log_frames: np.ndarray, on: np.ndarray, off: np.ndarray, start: float,
                     first: int = 0) -> tuple[ThresholdEstimate | None, str]:
    """The thresholds whose replay of ``log_frames`` fires the counts ``on`` and ``off``.

    Args:
        log_frames: (n_frames, n) log brightness of ``n`` pixels, each known (neither black
            nor saturated) in every frame, over consecutive frames.
        on: (n,) ON events the stream holds at those pixels over the frames' span.
        off: (n,) OFF events.
        start: the threshold the solve starts from.
        first: the index of the run's first frame (reported).

    Returns:
        As :func:`estimate_thresholds`.
    """
    views = log_frames.shape[0]
    if min(on.sum(), off.sum()) < MIN_EVENTS:
        return None, (f"only {on.sum():.0f} ON and {off.sum():.0f} OFF events at pixels the "
                      "frames show neither black nor saturated")
    change = log_frames.max(axis=0) - log_frames.min(axis=0)
    moving = change >= MIN_CHANGE  # (the others fire nothing at any threshold above it)
    if moving.sum() < 100:
        return None, STILL_FRAMES
    solved = _solve(log_frames[:, moving], on[moving].sum(), off[moving].sum(), start)
    if solved is None:
        return None, STILL_FRAMES
    c_on, c_off = solved
    # background activity: the rate at pixels that never move by half a threshold
    still = change < 0.5 * min(c_on, c_off)
    intervals = views - 1
    rate_on = rate_off = 0.0
    if still.sum() >= 100:
        rate_on = float(on[still].mean()) / intervals
        rate_off = float(off[still].mean()) / intervals
    sim_on, sim_off = np.zeros_like(on), np.zeros_like(off)
    sim_on[~still], sim_off[~still] = replay_counts(log_frames[:, ~still], c_on, c_off)
    hot = (on + off) > HOT_FACTOR * (sim_on + sim_off) + HOT_SLACK
    keep = ~hot & ~still
    if keep.sum() < 100:
        return None, "too few pixels whose brightness changes in the frames"
    on_total = on[keep].sum() - rate_on * intervals * keep.sum()
    off_total = off[keep].sum() - rate_off * intervals * keep.sum()
    if min(on_total, off_total) <= 0:
        return None, "the events at changing pixels are no more than the background activity"
    solved = _solve(log_frames[:, keep], on_total, off_total, c_on)
    if solved is None:
        return None, STILL_FRAMES
    c_on, c_off = solved
    sim_on, sim_off = replay_counts(log_frames[:, keep], c_on, c_off)
    observed = np.concatenate([on[keep], off[keep]])
    replayed = np.concatenate([sim_on, sim_off])
    residual = observed - replayed - np.mean(observed - replayed)
    explained = 1.0 - float(np.var(residual) / max(np.var(observed), 1e-12))
    if explained < MIN_EXPLAINED:
        return None, (f"a replay of the frames explains only {100 * max(explained, 0):.0f}% of "
                      "the pixels' event counts (placeholders, or frames of another exposure "
                      "or camera?)")
    return ThresholdEstimate(c_on, c_off, explained, int(keep.sum()), views,
                             0.5 * (rate_on + rate_off), first), ""
