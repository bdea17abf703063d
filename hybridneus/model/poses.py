"""Learned corrections of the camera poses (``refine.poses``): one rotation and one translation
per view, in the camera's own frame, trained with the field.

A view's corrected pose is ``c2w' = c2w [R(w) | v]``: the camera turns by the rotation vector
``w`` about its own centre and moves by ``v`` along its own axes (world units). Between views
the correction is interpolated linearly, as the reader interpolates poses, so a window that
starts between two views gets a correction between theirs. Rays made from the given poses are
moved onto the corrected ones in torch, so the event loss's gradient reaches the corrections.

Rotations use :func:`so3_exp` (Rodrigues' formula, with its Taylor series near zero so that
the gradient at the identity is exact); ``tests/test_poses.py`` checks it and its gradient
against scipy's rotation vectors.
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


class PoseCorrections(torch.nn.Module):
    """Per-view pose corrections (see the module docstring).

    Args:
        n_views: views of the split being trained.

    Attributes:
        delta: (n_views, 6) parameter, rotation vector (radians) then translation (world
            units) of each view; zero: the poses as given.
    """

    def __init__(self, n_views: int) -> None:
        super().__init__()
        self.n_views = n_views
        self.delta = torch.nn.Parameter(torch.zeros(n_views, 6))

    def at(self, view: float) -> torch.Tensor:
        """(6,) correction at a continuous view index (linear between views)."""
        s = min(max(float(view), 0.0), self.n_views - 1.0)
        a = int(np.floor(s))
        b = min(a + 1, self.n_views - 1)
        w = s - a
        return self.delta[a] if w == 0.0 else (1.0 - w) * self.delta[a] + w * self.delta[b]

    def move_rays(self, origins: torch.Tensor, dirs: torch.Tensor, rot: torch.Tensor,
                  view: float) -> tuple[torch.Tensor, torch.Tensor]:
        """Rays of the given pose, (n, 3) ``origins`` and ``dirs`` with the pose's rotation
        ``rot`` (3, 3), moved onto the corrected pose at ``view``."""
        d = self.at(view)
        rot = rot.to(origins.dtype)
        turn = rot @ so3_exp(d[:3]) @ rot.T  # the camera-frame turn, in world axes
        return origins + rot @ d[3:], dirs @ turn.T

    def regulariser(self, views: list[float]) -> torch.Tensor:
        """Mean squared correction (radians and world units alike) at ``views``: each
        correction pays for its size where a batch uses it."""
        return torch.stack([(self.at(v) ** 2).sum() for v in views]).mean()

    def corrected(self, c2w: np.ndarray) -> np.ndarray:
        """(n_views, 4, 4) float64 corrected poses of the given ``c2w`` (n_views, 4, 4)."""
        with torch.no_grad():
            delta = self.delta.detach().double().cpu()
            corr = torch.eye(4, dtype=torch.float64).repeat(self.n_views, 1, 1)
            corr[:, :3, :3] = so3_exp(delta[:, :3])
            corr[:, :3, 3] = delta[:, 3:]
        return np.asarray(c2w, dtype=np.float64) @ corr.numpy()


def pose_errors(estimated: np.ndarray, truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-view rotation error (degrees) and camera-centre error (world units) of
    ``estimated`` (n, 4, 4) against ``truth`` (n, 4, 4)."""
    rel = np.einsum("nji,njk->nik", estimated[:, :3, :3], truth[:, :3, :3])
    cos = np.clip((np.trace(rel, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return (np.degrees(np.arccos(cos)),
            np.linalg.norm(estimated[:, :3, 3] - truth[:, :3, 3], axis=1))
