"""Smoothing a camera track whose poses jitter from view to view (``refine.pose_smoothing``).

Motion capture, SLAM and hand-eye chains report every pose with its own small error, while
the camera itself, carried by an arm, a turntable or a hand, cannot change its motion between
two of a thousand views. Where the jitter is larger than what changes between neighbouring
views, it is most of a pose's error, and a local polynomial fit of the track over a few
dozen views takes it out while keeping the motion.

The fit is a Savitzky-Golay filter (:func:`scipy.signal.savgol_filter`) of the camera
centres and of the orientations as unit quaternions, their signs made continuous along the
track and renormalised after the filter; near the ends the polynomial of the first or last
full window is used. A filter of order ``p`` over ``w`` views passes every motion that a
polynomial of degree ``p`` follows over ``w`` views; a track that turns faster (a shake, a
jump in the poses) is bent, so the window must span less than such a feature.

How long a window a track wants depends on its jitter and its motion, which the track itself
tells: :func:`choose_window` picks the window whose fit predicts each interior view best
from its neighbours alone (leave-one-out; for a local least-squares fit the left-out
residual is the residual over ``1 - c0``, ``c0`` the filter's weight on the view itself, so
no refit is needed).
"""

from __future__ import annotations

import numpy as np

__all__ = ["choose_window", "exact_windows", "filter_is_exact", "pose_errors", "smooth_track"]

# A window that predicts a view from its neighbours needs views on both sides; the shortest
# one scored, and the share of the track the longest may span.
_LONGEST_SHARE = 1 / 3


def filter_is_exact(window: int, order: int, tol: float = 1e-6) -> bool:
    """Whether scipy's filter of ``order`` over ``window`` views keeps every polynomial of
    that degree (at the window's centre, to ``tol``).

    scipy computes the coefficients from powers of the raw offsets, which lose precision
    for long windows of high order (order 7 from 179 views, order 5 from 797): the filter
    then shrinks the track towards the origin instead of smoothing it.
    """
    from scipy.signal import savgol_coeffs

    if window % 2 == 0 or window < order + 2:
        return False
    coeffs = savgol_coeffs(window, order)[::-1]  # the weights in the offsets' order
    half = window // 2
    x = np.arange(-half, half + 1) / max(half, 1)
    errors = [abs(coeffs.sum() - 1.0)]
    errors += [abs(float(coeffs @ x**k)) for k in range(1, order + 1)]
    return max(errors) <= tol


def exact_windows(order: int, longest: int) -> list[int]:
    """The odd windows from ``order + 2`` views up to ``longest`` whose filter of ``order``
    is exact (:func:`filter_is_exact`), shortest first."""
    shortest = order + 2 + (order % 2 == 0)
    return [w for w in range(shortest, longest + 1, 2) if filter_is_exact(w, order)]


def _quaternions(c2w: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    quat = Rotation.from_matrix(c2w[:, :3, :3]).as_quat()
    # q and -q are one rotation: the filter needs the sign that keeps neighbours close
    flips = np.cumsum(np.einsum("ij,ij->i", quat[1:], quat[:-1]) < 0) % 2
    quat[1:] *= np.where(flips, -1.0, 1.0)[:, None]
    return quat


def _fit_window(n: int, window: int, order: int) -> int:
    """``window`` shortened to the track's length and made odd; 0 where nothing is left."""
    window = min(window, n if n % 2 else n - 1)
    window -= 1 - window % 2  # the filter needs an odd length
    return window if window >= order + 2 else 0


def _filter(values: np.ndarray, window: int, order: int) -> np.ndarray:
    from scipy.signal import savgol_filter

    if not filter_is_exact(window, order):
        raise ValueError(f"smooth_track: a {window}-view window of order {order} is "
                         "numerically unstable (its filter no longer keeps polynomials of "
                         "that degree); use a shorter window or a lower order")
    return savgol_filter(values, window, order, axis=0, mode="interp")


def choose_window(c2w: np.ndarray, order: int = 5) -> int:
    """The window of :func:`smooth_track` that the track ``c2w`` (n, 4, 4) itself supports
    best: the odd window, from ``order + 2`` views up to a third of the track, whose fit
    predicts each interior view (one that every candidate window fits from both sides) best
    from its neighbours alone. The orientations and the centres are scored apart by their
    mean squared leave-one-out residual, each score taken relative to its own smallest, and
    the window with the smallest sum of the two is chosen.

    Returns:
        the window, or 0 for a track too short to score (fewer than ``3 * (order + 2)``
        views).
    """
    from scipy.signal import savgol_coeffs, savgol_filter

    c2w = np.asarray(c2w, dtype=np.float64)
    n = len(c2w)
    candidates = exact_windows(order, int(n * _LONGEST_SHARE))
    if not candidates:
        return 0
    margin = candidates[-1] // 2
    inner = slice(margin, n - margin)
    total = np.zeros(len(candidates))
    for values in (_quaternions(c2w), c2w[:, :3, 3]):
        scores = np.empty(len(candidates))
        for i, w in enumerate(candidates):
            fitted = savgol_filter(values, w, order, axis=0, mode="interp")
            self_weight = savgol_coeffs(w, order)[w // 2]
            left_out = (values - fitted)[inner] / (1.0 - self_weight)
            scores[i] = np.mean(np.sum(left_out**2, axis=1))
        total += scores / max(scores.min(), np.finfo(float).tiny)
    return candidates[int(np.argmin(total))]


def smooth_track(c2w: np.ndarray, window: int, order: int = 5) -> np.ndarray:
    """The track ``c2w`` (n, 4, 4) with its centres and orientations filtered along the
    views: a local polynomial of degree ``order`` over ``window`` views (odd; shortened to the
    track's length, and to nothing below ``order + 2`` views, where the track is returned as
    it is).

    Returns:
        (n, 4, 4) float64 camera-to-world poses.

    Raises:
        ValueError: ``window`` below 0, ``order`` below 1, or a window and order whose filter
            is numerically unstable (:func:`filter_is_exact`).
    """
    from scipy.spatial.transform import Rotation

    if window < 0 or order < 1:
        raise ValueError(f"smooth_track: window {window} and order {order}: expected a window "
                         ">= 0 and an order >= 1")
    c2w = np.asarray(c2w, dtype=np.float64)
    out = c2w.copy()
    window = _fit_window(len(c2w), window, order)
    if not window:
        return out
    quat = _filter(_quaternions(c2w), window, order)
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    out[:, :3, :3] = Rotation.from_quat(quat).as_matrix()
    out[:, :3, 3] = _filter(c2w[:, :3, 3], window, order)
    return out


def pose_errors(estimated: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-view rotation error (degrees) and camera-centre error (world units) of
    ``estimated`` (n, 4, 4) against ``truth`` (n, 4, 4)."""
    rel = np.einsum("nji,njk->nik", estimated[:, :3, :3], truth[:, :3, :3])
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return (np.degrees(np.arccos(cos)),
            np.linalg.norm(estimated[:, :3, 3] - truth[:, :3, 3], axis=1))
