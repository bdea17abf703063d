"""A realistic capture's pose errors: what the written poses get wrong about the true ones.

Real pose sources (turntable and hand-eye calibration, motion capture) leave errors of tenths of
a degree and millimetres, and a clock offset between poses and events. The simulator renders
and fires events from the true poses and, for the training split, writes poses with these
errors into ``pose/`` and the true ones into ``pose_true/`` (which the reader ignores), so
that a benchmark can measure robustness, and a refinement's result, against a known truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from hybridneus.data.rays import interpolate_pose


@dataclass
class CaptureErrors:
    """Errors of the training split's written poses (all 0: exact poses).

    Attributes:
        rotation_deg: RMS angle of a random turn of each view's camera about its centre.
        translation: RMS shift of each view's camera centre, as a share of the camera's
            distance from the origin (0.01: 1%).
        clock_offset_views: the written pose of view ``k`` is the true pose at ``k + this``
            (a clock offset between the pose source and the events, in views).
        smooth_views: 0: each view's error drawn on its own; > 0: errors drawn every this
            many views and interpolated linearly between (a drift, as motion capture and
            turntables make); ``rotation_deg`` and ``translation`` are then their RMS at the
            knots.
        seed: seed of the random errors.
    """

    rotation_deg: float = 0.0
    translation: float = 0.0
    clock_offset_views: float = 0.0
    seed: int = 0
    smooth_views: float = 0.0

    def __post_init__(self) -> None:
        if self.rotation_deg < 0 or self.translation < 0 or self.smooth_views < 0:
            raise ValueError("capture errors: rotation_deg, translation and smooth_views must "
                             "be >= 0")

    def any(self) -> bool:
        return bool(self.rotation_deg or self.translation or self.clock_offset_views)


def written_poses(c2w: np.ndarray, errors: CaptureErrors) -> np.ndarray:
    """(n, 4, 4) poses as a capture with ``errors`` would record the true ``c2w`` (n, 4, 4):
    shifted in time by the clock offset, then turned and moved per view (camera frame)."""
    n = c2w.shape[0]
    s = np.clip(np.arange(n) + errors.clock_offset_views, 0.0, n - 1.0)
    a = np.floor(s).astype(int)
    b = np.minimum(a + 1, n - 1)
    shifted = interpolate_pose(c2w[a], c2w[b], s - a).reshape(n, 4, 4)
    rng = np.random.default_rng(errors.seed)
    knots = n if errors.smooth_views <= 0 else int(np.ceil((n - 1) / errors.smooth_views)) + 1
    turn = _along(rng.normal(size=(knots, 3)), n) * np.radians(errors.rotation_deg) / np.sqrt(3)
    distance = np.linalg.norm(c2w[:, :3, 3], axis=1, keepdims=True)
    move = _along(rng.normal(size=(knots, 3)), n) * errors.translation * distance / np.sqrt(3)
    err = np.tile(np.eye(4), (n, 1, 1))
    err[:, :3, :3] = Rotation.from_rotvec(turn).as_matrix()
    err[:, :3, 3] = move
    return shifted @ err


def _along(values: np.ndarray, n: int) -> np.ndarray:
    """(knots, 3) values spread evenly over ``n`` views, linear between them: (n, 3)."""
    if len(values) == n:
        return values
    at = np.linspace(0.0, len(values) - 1.0, n)
    return np.stack([np.interp(at, np.arange(len(values)), v) for v in values.T], axis=1)
