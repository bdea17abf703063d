"""Learned corrections of the camera poses (``refine.poses``), trained with the field.

A correction is a rotation vector ``w`` and a translation ``v`` in the camera's own frame:
the corrected pose is ``c2w' = c2w [R(w) | v]``, the camera turned by ``w`` about its own
centre and moved by ``v`` along its own axes (world units). Corrections are held at *knots*
along the track and interpolated linearly between them (as the reader interpolates poses):

- one knot per view (``refine.pose_knots = 0``): each view is free, for independent errors;
  each view's correction only learns from the windows that end at it, a few per thousand
  steps at the EventNeRF datasets' 999 views;
- ``K`` knots spread evenly over the track: a smooth correction for errors that drift
  (motion-capture drift, a turntable's wobble), every knot learning from a ``K``-th of the
  stream;
- one knot: one correction of every view, a fixed camera-frame offset (a hand-eye
  calibration's error).

A clock offset ``tau`` (views) between the poses and the events (``refine.clock_offset``)
moves every view along the given track: to first order the pose at ``k + tau`` is ``c2w_k
[R(tau w_k) | tau v_k]``, with ``(w_k, v_k)`` the camera-frame motion from view ``k`` to
``k + 1``, and its 6-vector adds to the knots'.

The corrections and the field can move together: shift, turn or scale every camera and the
field with them, and the events are the same. ``refine.pose_gauge`` takes that part out after
every step (:meth:`PoseCorrections.remove_gauge`): the linearised similarity transform
(rotation, translation, scale) that best explains the corrected track against the given one is
projected out of the knots, so the corrections keep only what moves the cameras against each
other.

Rays made from the given poses are moved onto the corrected ones in torch, so the event loss's
gradient reaches the corrections. Rotations use :func:`so3_exp` (Rodrigues' formula, with its
Taylor series near zero so that the gradient at the identity is exact); ``tests/test_poses.py``
checks it and its gradient against scipy's rotation vectors.
"""

from __future__ import annotations

import numpy as np
import torch

#: Below this angle (radians) :func:`so3_exp` uses the series, where the closed form divides
#: zero by zero.
SMALL_ANGLE = 1e-4


def so3_exp(w: torch.Tensor) -> torch.Tensor:
    """Rotation matrices of rotation vectors: (..., 3) -> (..., 3, 3).

    ``exp([w]x) = I + a [w]x + b [w]x^2`` with ``a = sin(t) / t``, ``b = (1 - cos(t)) / t^2``
    and ``t = |w|``; below :data:`SMALL_ANGLE` the series ``a = 1 - t^2/6``, ``b = 1/2 -
    t^2/24``. Differentiable everywhere (the angle enters only through ``t^2`` near zero).
    """
    t2 = (w * w).sum(-1, keepdim=True)[..., None]  # (..., 1, 1)
    small = t2 < SMALL_ANGLE**2
    t2_safe = torch.where(small, torch.ones_like(t2), t2)
    t = t2_safe.sqrt()
    a = torch.where(small, 1.0 - t2 / 6.0, torch.sin(t) / t)
    b = torch.where(small, 0.5 - t2 / 24.0, (1.0 - torch.cos(t)) / t2_safe)
    zero = torch.zeros_like(w[..., 0])
    k = torch.stack([zero, -w[..., 2], w[..., 1],
                     w[..., 2], zero, -w[..., 0],
                     -w[..., 1], w[..., 0], zero], dim=-1).reshape(*w.shape[:-1], 3, 3)
    eye = torch.eye(3, dtype=w.dtype, device=w.device).expand_as(k)
    return eye + a * k + b * (k @ k)


def track_motion(c2w: np.ndarray) -> np.ndarray:
    """(n, 6) camera-frame motion (rotation vector, translation) from each view to the next of
    the track ``c2w`` (n, 4, 4); the last view repeats the motion before it."""
    from scipy.spatial.transform import Rotation

    c2w = np.asarray(c2w, dtype=np.float64)
    n = len(c2w)
    motion = np.zeros((n, 6))
    if n < 2:
        return motion
    rel = np.linalg.inv(c2w[:-1]) @ c2w[1:]
    motion[:-1, :3] = Rotation.from_matrix(rel[:, :3, :3]).as_rotvec()
    motion[:-1, 3:] = rel[:, :3, 3]
    motion[-1] = motion[-2]
    return motion


class PoseCorrections(torch.nn.Module):
    """Pose corrections at knots along the track, and a clock offset (see the module
    docstring).

    Args:
        n_views: views of the split being trained.
        knots: corrections along the track: 0 (or ``n_views`` and more) one per view,
            otherwise that many spread evenly from the first view to the last.
        clock_track: the given poses (n_views, 4, 4); with them a clock offset is learned too.

    Attributes:
        delta: (n_knots, 6) parameter, rotation vector (radians) then translation (world
            units) at each knot; zero: the poses as given.
        clock: (1,) parameter, the clock offset in views, or ``None``.
    """

    def __init__(self, n_views: int, knots: int = 0,
                 clock_track: np.ndarray | None = None,
                 gauge_track: np.ndarray | None = None) -> None:
        super().__init__()
        self.n_views = n_views
        self.n_knots = n_views if knots <= 0 else min(knots, n_views)
        self.delta = torch.nn.Parameter(torch.zeros(self.n_knots, 6))
        if gauge_track is None:
            self.gauge = None
        else:
            # derived from the given poses: rebuilt, never saved in a checkpoint; the
            # projection's (7, 7) solve is fixed too, so it is made once, not every step
            g = gauge_map(gauge_track, self.knot_weights())
            self.register_buffer("gauge", torch.as_tensor(g, dtype=torch.float32),
                                 persistent=False)
            self.register_buffer("gauge_solve", torch.as_tensor(
                np.linalg.pinv(g @ g.T) @ g, dtype=torch.float32), persistent=False)
        self.clock = None
        if clock_track is not None:
            self.clock = torch.nn.Parameter(torch.zeros(1))
            self.register_buffer("motion",
                                 torch.as_tensor(track_motion(clock_track), dtype=torch.float32))

    def _knots_around(self, view: float) -> tuple[int, int, float]:
        """The two knots a continuous view index lies between, and its weight on the second."""
        if self.n_knots == 1:
            return 0, 0, 0.0
        s = min(max(float(view), 0.0), self.n_views - 1.0) * (self.n_knots - 1) / max(
            self.n_views - 1, 1)
        a = min(int(np.floor(s)), self.n_knots - 1)
        return a, min(a + 1, self.n_knots - 1), s - a

    def knot_weights(self) -> np.ndarray:
        """(n_views, n_knots) weights of each view's correction on the knots (linear)."""
        weights = np.zeros((self.n_views, self.n_knots))
        for k in range(self.n_views):
            a, b, w = self._knots_around(k)
            weights[k, a] += 1.0 - w
            weights[k, b] += w
        return weights

    def remove_gauge(self) -> None:
        """Project the knots onto corrections whose track has no common similarity transform
        against the given one (see the module docstring); nothing without a gauge map."""
        if self.gauge is None:
            return
        with torch.no_grad():  # gauge: (7, n_knots * 6); gauge_solve: pinv(g g^T) g
            coef = self.gauge_solve @ self.delta.reshape(-1)
            self.delta -= (self.gauge.T @ coef).reshape(self.delta.shape)

    def _knot_at(self, view: float) -> torch.Tensor:
        a, b, w = self._knots_around(view)
        return self.delta[a] if w == 0.0 else (1.0 - w) * self.delta[a] + w * self.delta[b]

    def at(self, view: float) -> torch.Tensor:
        """(6,) correction at a continuous view index: the knots' (linear between them) plus
        the clock offset's move along the track."""
        d = self._knot_at(view)
        if self.clock is None:
            return d
        k = min(max(int(np.floor(view)), 0), self.n_views - 1)
        return d + self.clock * self.motion[k]

    def move_rays(self, origins: torch.Tensor, dirs: torch.Tensor, rot: torch.Tensor,
                  view: float) -> tuple[torch.Tensor, torch.Tensor]:
        """Rays of the given pose, (n, 3) ``origins`` and ``dirs`` with the pose's rotation
        ``rot`` (3, 3), moved onto the corrected pose at ``view``."""
        d = self.at(view)
        rot = rot.to(origins.dtype)
        turn = rot @ so3_exp(d[:3]) @ rot.T  # the camera-frame turn, in world axes
        return origins + rot @ d[3:], dirs @ turn.T

    def regulariser(self, views: list[float]) -> torch.Tensor:
        """Mean squared knot correction (radians and world units alike) at ``views``: each
        correction pays for its size where a batch uses it (the clock offset is free)."""
        return torch.stack([(self._knot_at(v) ** 2).sum() for v in views]).mean()

    def corrected(self, c2w: np.ndarray) -> np.ndarray:
        """(n_views, 4, 4) float64 corrected poses of the given ``c2w`` (n_views, 4, 4)."""
        with torch.no_grad():
            delta = torch.stack([self.at(k) for k in range(self.n_views)]).double().cpu()
            corr = torch.eye(4, dtype=torch.float64).repeat(self.n_views, 1, 1)
            corr[:, :3, :3] = so3_exp(delta[:, :3])
            corr[:, :3, 3] = delta[:, 3:]
        return np.asarray(c2w, dtype=np.float64) @ corr.numpy()


def gauge_map(c2w: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(7, n_knots * 6) linear map from the knots (flattened, rotation then translation per
    knot) to the similarity transform their corrections make of the whole track, to first
    order: the world rotation ``q``, translation ``t`` and scale ``sigma`` that best explain
    every view's world-frame turn ``R_k w_k`` (as ``q``) and centre shift ``R_k v_k`` (as
    ``q x c_k + t + sigma c_k``), by least squares over the views.

    Args:
        c2w: (n_views, 4, 4) the given poses.
        weights: (n_views, n_knots) each view's weights on the knots.
    """
    c2w = np.asarray(c2w, dtype=np.float64)
    n, k = weights.shape
    rot, centre = c2w[:, :3, :3], c2w[:, :3, 3]
    a = np.zeros((n, 6, 7))  # the transform's effect on each view's (turn, shift)
    a[:, :3, :3] = np.eye(3)
    cx = np.zeros((n, 3, 3))  # q x c = -[c]x q
    cx[:, 0, 1], cx[:, 0, 2] = centre[:, 2], -centre[:, 1]
    cx[:, 1, 0], cx[:, 1, 2] = -centre[:, 2], centre[:, 0]
    cx[:, 2, 0], cx[:, 2, 1] = centre[:, 1], -centre[:, 0]
    a[:, 3:, :3] = cx
    a[:, 3:, 3:6] = np.eye(3)
    a[:, 3:, 6] = centre
    normal = np.einsum("nij,nik->jk", a, a)
    # each view's world (turn, shift) is diag(R, R) times its camera-frame correction
    block = np.zeros((n, 6, 6))
    block[:, :3, :3] = rot
    block[:, 3:, 3:] = rot
    per_view = np.einsum("nji,njk->nik", a, block)  # (n, 7, 6): A_n^T diag(R_n, R_n)
    rhs = np.einsum("nk,nij->ikj", weights, per_view).reshape(7, k * 6)
    return np.linalg.pinv(normal) @ rhs


class PoseOptimizer:
    """Adam for the corrections: lazy (sparse) for the knots, since a batch touches only the
    few knots around its window's two ends and dense Adam's momentum would go on moving every
    knot it touched for tens of steps without new evidence; plain Adam for the clock offset,
    which every batch informs."""

    def __init__(self, poses: PoseCorrections, lr: float, betas: tuple[float, float]) -> None:
        self.poses = poses
        self.knots = torch.optim.SparseAdam([poses.delta], lr=lr, betas=betas)
        self.clock = None if poses.clock is None else torch.optim.Adam([poses.clock], lr=lr,
                                                                       betas=betas)

    def set_lr(self, lr: float) -> None:
        for opt in (self.knots, self.clock):
            if opt is not None:
                opt.param_groups[0]["lr"] = lr

    def step(self, learn: bool) -> None:
        """Apply the gradients the backward pass left (only when ``learn``), then clear them."""
        delta = self.poses.delta
        grad, delta.grad = delta.grad, None
        if grad is not None and learn:
            delta.grad = grad.to_sparse(1)  # only the batch's knots move
            self.knots.step()
            delta.grad = None
            self.poses.remove_gauge()
        if self.clock is not None:
            if learn and self.poses.clock.grad is not None:
                self.clock.step()
            self.poses.clock.grad = None

    def state_dict(self) -> dict:
        return {"knots": self.knots.state_dict(),
                "clock": None if self.clock is None else self.clock.state_dict()}

    def load_state_dict(self, state: dict) -> None:
        if "knots" not in state:  # a checkpoint of the per-view corrections alone
            self.knots.load_state_dict(state)
            return
        self.knots.load_state_dict(state["knots"])
        if self.clock is not None and state.get("clock") is not None:
            self.clock.load_state_dict(state["clock"])


def pose_errors(estimated: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-view rotation error (degrees) and camera-centre error (world units) of
    ``estimated`` (n, 4, 4) against ``truth`` (n, 4, 4)."""
    rel = np.einsum("nji,njk->nik", estimated[:, :3, :3], truth[:, :3, :3])
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return (np.degrees(np.arccos(cos)),
            np.linalg.norm(estimated[:, :3, 3] - truth[:, :3, 3], axis=1))
