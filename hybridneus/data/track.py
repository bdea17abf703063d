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
"""

from __future__ import annotations

import numpy as np

__all__ = ["smooth_track"]


def smooth_track(c2w: np.ndarray, window: int, order: int = 5) -> np.ndarray:
    """The track ``c2w`` (n, 4, 4) with its centres and orientations filtered along the
    views: a local polynomial of degree ``order`` over ``window`` views (odd; shortened to the
    track's length, and to nothing below ``order + 2`` views, where the track is returned as
    it is).

    Returns:
        (n, 4, 4) float64 camera-to-world poses.

    Raises:
        ValueError: ``window`` below 0 or ``order`` below 1.
    """
    from scipy.signal import savgol_filter
    from scipy.spatial.transform import Rotation

    if window < 0 or order < 1:
        raise ValueError(f"smooth_track: window {window} and order {order}: expected a window "
                         ">= 0 and an order >= 1")
    c2w = np.asarray(c2w, dtype=np.float64)
    n = len(c2w)
    window = min(window, n if n % 2 else n - 1)
    window -= 1 - window % 2  # the filter needs an odd length
    out = c2w.copy()
    if window < order + 2:
        return out
    quat = Rotation.from_matrix(c2w[:, :3, :3]).as_quat()
    # q and -q are one rotation: the filter needs the sign that keeps neighbours close
    flips = np.cumsum(np.einsum("ij,ij->i", quat[1:], quat[:-1]) < 0) % 2
    quat[1:] *= np.where(flips, -1.0, 1.0)[:, None]
    quat = savgol_filter(quat, window, order, axis=0, mode="interp")
    quat /= np.linalg.norm(quat, axis=1, keepdims=True)
    out[:, :3, :3] = Rotation.from_quat(quat).as_matrix()
    out[:, :3, 3] = savgol_filter(c2w[:, :3, 3], window, order, axis=0, mode="interp")
    return out
