"""The offset between an event file's clock and its pose track's, from the data
(``convert --clock-offset auto``).

A camera that moves faster sweeps the scene's edges over more pixels a second, so the event
rate rises and falls with the camera's speed. The pose track gives that speed on its own
clock: the angular speed plus the translational speed over the distance to where the cameras
look. The rate is that speed times how many edges are in view, which changes slowly along
the path; in logarithms that factor is a sum, which the alignment treats as noise.

1. **Coarse**: the lag at which the two log curves correlate best (Pearson), in 20 ms bins,
   over every lag at which they overlap by at least half of the shorter one.
2. **Fine**: the slope of the phase of their cross-spectrum (Welch) over the band of
   frequencies where they are coherent, each frequency weighted by its coherence: the
   maximum-likelihood estimate of a delay between two noisy signals, with its standard
   error (Carter, "Coherence and time delay estimation", Proc. IEEE 75(2), 1987).

The estimate is refused, with the reason, where the data cannot pin it: a camera moving at a
nearly constant speed (a turntable: every lag fits alike), a second lag more than a second
away that fits almost as well (a motion that repeats), or a standard error that would leave
the views more than :data:`MAX_SHIFT_PX` pixels uncertain at the track's speed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import coherence, correlate, csd

from hybridneus.errors import RecordingError
from hybridneus.recordings.frame import look_at_point
from hybridneus.recordings.poses import PoseTrack
from hybridneus.recordings.stream import EventSource

#: Fine bin, seconds.
FINE = 0.001
#: Coarse bins hold this many fine ones.
COARSE = 20
#: Both curves are smoothed over this many fine bins (Poisson noise of the counts, trackers'
#: jitter divided by short steps).
SMOOTH = 3.0
#: The least share of the shorter curve that a lag must overlap.
MIN_OVERLAP = 0.5
#: Refused when the camera's speed varies by less than this (standard deviation over mean),
MIN_SPEED_VARIATION = 0.1
#: when a lag more than a second from the best correlates at least this share of it,
MAX_RIVAL = 0.9
#: or when the standard error times the camera's RMS speed in the image exceeds this.
MAX_SHIFT_PX = 1.0
#: Frequencies whose coherence is below this are not used.
MIN_COHERENCE = 0.2
#: Welch segments of the cross-spectrum, in fine bins.
SEGMENT = 2048


@dataclass(frozen=True)
class ClockEstimate:
    """An estimated clock offset.

    Attributes:
        offset: seconds to add to an event time to get the pose clock's time.
        uncertainty: its standard error, seconds (from the cross-spectrum's coherence).
        coherence: the mean coherence of the event rate with the camera's speed over the
            frequencies used (0: unrelated, 1: one a delayed copy of the other).
        shift_px: ``uncertainty`` times the camera's RMS speed in the image, in pixels: how
            far off a view may be placed for it.
    """

    offset: float
    uncertainty: float
    coherence: float
    shift_px: float

    def line(self) -> str:
        return (f"clock offset {self.offset:.4f} s +- {self.uncertainty * 1e3:.2f} ms from the "
                f"event rate and the camera's speed (coherence {self.coherence:.2f}); at the "
                f"track's speed that is {self.shift_px:.2f} px")

    def to_json(self) -> dict:
        return {"offset_s": self.offset, "uncertainty_s": self.uncertainty,
                "coherence": self.coherence, "uncertainty_px": self.shift_px}


def event_rate(source: EventSource) -> tuple[float, np.ndarray]:
    """The events per :data:`FINE` bin: ``(time of the middle of bin 0, counts)``,
    streamed."""
    t0: float | None = None
    counts = np.zeros(0, dtype=np.float64)
    for chunk in source.chunks():
        if len(chunk) == 0:
            continue
        if t0 is None:
            t0 = float(chunk.t[0])
        k = np.floor((chunk.t - t0) / FINE).astype(np.int64)
        if k.size and k[0] < 0:
            raise RecordingError(f"{source.path}: timestamps go backwards (the file must be "
                                 "sorted by time)")
        part = np.bincount(k)
        if part.size > counts.size:
            counts = np.concatenate([counts, np.zeros(part.size - counts.size)])
        counts[: part.size] += part
    if t0 is None:
        raise RecordingError(f"{source.path}: no events")
    return t0 + 0.5 * FINE, counts  # a bin's count belongs to its middle


def camera_speed(track: PoseTrack) -> tuple[float, np.ndarray]:
    """The camera's speed in the image on a :data:`FINE` grid over the track: radians a
    second, the angular speed plus the translational speed over the median distance to where
    the cameras look. Returns ``(time of sample 0, speeds)``."""
    c2w = track.matrices()
    centre, _ = look_at_point(c2w)
    distance = float(np.median(np.linalg.norm(c2w[:, :3, 3] - centre, axis=1)))
    dt = np.diff(track.t)
    turn = (track.rotation[:-1].inv() * track.rotation[1:]).magnitude()
    move = np.linalg.norm(np.diff(track.position, axis=0), axis=1)
    speed = (turn + move / max(distance, 1e-9)) / dt
    # relative to the first sample: np.arange from an epoch time (1.7e9 s) steps by the
    # difference of two rounded numbers, 1e-4 off FINE, and drifts by milliseconds a minute
    rel = track.t - track.t[0]
    mid = 0.5 * (rel[:-1] + rel[1:])
    grid = np.arange(int(np.floor(rel[-1] / FINE)) + 1) * FINE
    return float(track.t[0]), gaussian_filter1d(np.interp(grid, mid, speed), SMOOTH)


def _log(x: np.ndarray) -> np.ndarray:
    return np.log(x + 1e-3 * max(float(x.mean()), 1e-12))


def _bin(x: np.ndarray, size: int) -> np.ndarray:
    n = x.size // size
    return x[: n * size].reshape(n, size).mean(axis=1)


def _ncc_all(a: np.ndarray, b: np.ndarray, min_overlap: int) -> tuple[np.ndarray, np.ndarray]:
    """Pearson correlation of ``a[i]`` with ``b[i + lag]`` over the overlap, for every lag
    whose overlap holds at least ``min_overlap`` samples: ``(lags, correlations)``."""
    ones_a, ones_b = np.ones_like(a), np.ones_like(b)

    def corr(x, y):  # sum_i x[i] y[i + lag], for lags -(len x - 1) .. len y - 1
        return correlate(y, x, mode="full", method="fft")

    n = np.rint(corr(ones_a, ones_b))
    sa, sb = corr(a, ones_b), corr(ones_a, b)
    saa, sbb = corr(a * a, ones_b), corr(ones_a, b * b)
    sab = corr(a, b)
    lags = np.arange(-(a.size - 1), b.size)
    ok = n >= min_overlap
    n, sa, sb, saa, sbb, sab, lags = (v[ok] for v in (n, sa, sb, saa, sbb, sab, lags))
    cov = sab - sa * sb / n
    var = (saa - sa**2 / n) * (sbb - sb**2 / n)
    r = np.where(var > 0, cov / np.sqrt(np.maximum(var, 1e-300)), 0.0)
    return lags, r


def estimate_clock_offset(source: EventSource, track: PoseTrack, focal_px: float
                          ) -> ClockEstimate:
    """Estimate the offset to add to event times to get pose times (module docstring).

    Args:
        source: the events.
        track: the pose track.
        focal_px: the camera's focal length in pixels (the image speed the refusal weighs).

    Raises:
        RecordingError: the track is not a sampled one, the two do not overlap for long
            enough at any offset, or the data cannot pin the offset (with the reason).
    """
    if not isinstance(track, PoseTrack):
        raise RecordingError(f"{track.source}: --clock-offset auto needs a sampled pose track "
                             "(a turntable description states its own times)")
    te0, rate = event_rate(source)
    tp0, speed = camera_speed(track)
    if min(rate.size, speed.size) < 20 * COARSE:
        raise RecordingError(
            f"{track.source}: the events or the track last under {20 * COARSE * FINE:g} s; "
            "too short to find a clock offset")
    variation = float(speed.std() / max(speed.mean(), 1e-12))
    if variation < MIN_SPEED_VARIATION:
        raise RecordingError(
            f"{track.source}: the camera's speed varies by only {variation:.0%} along the "
            "track (a turntable or a constant sweep), so every clock offset fits alike; give "
            "it with --clock-offset S")
    rms_px = float(np.sqrt(np.mean(speed**2))) * focal_px
    rate, speed = _log(gaussian_filter1d(rate, SMOOTH)), _log(speed)
    a, b = _bin(rate, COARSE), _bin(speed, COARSE)
    lags, r = _ncc_all(a, b, int(MIN_OVERLAP * min(a.size, b.size)))
    if lags.size == 0:
        raise RecordingError(f"{track.source}: the events and the track cannot overlap by "
                             "half of the shorter at any offset")
    best = int(np.argmax(r))
    far = np.abs(lags - lags[best]) * COARSE * FINE > 1.0
    if far.any() and r[far].max() > MAX_RIVAL * r[best]:
        first = tp0 - te0 + lags[best] * COARSE * FINE
        other = tp0 - te0 + lags[far][np.argmax(r[far])] * COARSE * FINE
        raise RecordingError(
            f"{track.source}: offsets {first:.3f} s and {other:.3f} s fit almost alike "
            f"(correlation {r[best]:.2f} and {r[far].max():.2f}; a motion that repeats); give "
            "it with --clock-offset S")
    lag, sigma, coh = float(lags[best] * COARSE), np.inf, 0.0
    for _ in range(3):  # each pass measures what is left about the last estimate
        step, sigma, coh = _phase_delay(rate, speed, int(round(lag)))
        lag = round(lag) + step
    offset = tp0 - te0 + lag * FINE
    shift = sigma * FINE * rms_px
    if not shift <= MAX_SHIFT_PX:
        raise RecordingError(
            f"{track.source}: the event rate follows the camera's speed too loosely to pin a "
            f"clock offset (best {offset:.4f} s +- {sigma * FINE * 1e3:.1f} ms, {shift:.1f} px "
            "at the track's speed); give it with --clock-offset S")
    return ClockEstimate(float(offset), float(sigma * FINE), coh, float(shift))


def _phase_delay(rate: np.ndarray, speed: np.ndarray, lag: int) -> tuple[float, float, float]:
    """The remaining delay of ``speed[i + lag]`` behind ``rate[i]`` from the slope of their
    cross-spectrum's phase, each frequency weighted by its coherence (the maximum-likelihood
    time-delay estimate): ``(delay in bins, its standard error, mean coherence)``."""
    i0, i1 = max(0, -lag), min(rate.size, speed.size - lag)
    x, y = rate[i0:i1], speed[i0 + lag:i1 + lag]
    n = min(SEGMENT, x.size // 4)
    f, gxy = csd(x, y, nperseg=n)
    _, coh = coherence(x, y, nperseg=n)
    segments = max(1, 2 * x.size // n - 1)  # Welch's, half overlapping
    # a coherence estimated from few segments is biased up by about 1/segments: only what
    # stands well above that counts, and only the band up from the lowest frequencies:
    # a high frequency that cleared the bar by chance would outweigh the rest (by f**2)
    good = coh > max(MIN_COHERENCE, 5.0 / segments)
    top = int(np.argmin(good[1:])) + 1 if not good[1:].all() else good.size
    use = np.zeros_like(good)
    use[1:top] = good[1:top]
    coh = np.minimum(coh, 1 - 1e-6)
    f, phase, coh = f[use], np.angle(gxy[use]), coh[use]
    # var(phase) = (1 - coh) / (2 segments coh) at each frequency; the slope is -2 pi f delay
    w = 2 * segments * coh / (1 - coh)
    omega = 2 * np.pi * f
    keep = np.abs(phase) < np.pi / 2  # past a quarter turn the phase may have wrapped
    w, omega, phase = w[keep], omega[keep], phase[keep]
    denom = float((w * omega**2).sum())
    if denom <= 0:
        return 0.0, np.inf, 0.0
    delay = -float((w * omega * phase).sum()) / denom
    return delay, 1.0 / np.sqrt(denom), float(coh.mean())


__all__ = ["ClockEstimate", "camera_speed", "estimate_clock_offset", "event_rate"]
