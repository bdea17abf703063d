"""Checks of a split's views: poses that are rigid, intrinsics a real camera could have.

Each check is vectorised over the views and names the first bad file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hybridneus.errors import DatasetError

#: Tolerance of the rotation checks: rotations written with 6 decimals are orthonormal to
#: ~1e-6; 1e-3 still catches any scale, shear or a mistyped entry.
_ROT_TOL = 1e-3


def check_poses(c2w: np.ndarray, files: list[Path]) -> None:
    """Vectorised checks of (n_views, 4, 4) poses; the message names the first bad file."""

    def fail(mask: np.ndarray, why: str) -> None:
        if np.any(mask):
            i = int(np.argmax(mask))
            raise DatasetError(f"{files[i]}: {why}")

    fail(~np.isfinite(c2w).all(axis=(1, 2)), "pose holds NaN or inf")
    fail(
        np.abs(c2w[:, 3] - np.array([0.0, 0.0, 0.0, 1.0])).max(axis=1) > 1e-6,
        "last row of the 4x4 pose is not 0 0 0 1",
    )
    rot = c2w[:, :3, :3]
    det = np.linalg.det(rot)
    fail(np.abs(det) < 1e-8, "rotation is not invertible (determinant 0)")
    gram_err = np.abs(np.einsum("nji,njk->nik", rot, rot) - np.eye(3)).max(axis=(1, 2))
    fail(
        (np.abs(det - 1.0) > 10 * _ROT_TOL) | (gram_err > _ROT_TOL),
        "top-left 3x3 is not a rotation (needs orthonormal columns and determinant +1)",
    )


def check_intrinsics(K: np.ndarray, dist: np.ndarray, files: list[Path]) -> None:
    """Vectorised checks of (n_views, 3, 3) K and (n_views, 2) distortion."""

    def fail(mask: np.ndarray, why: str) -> None:
        if np.any(mask):
            i = int(np.argmax(mask))
            raise DatasetError(f"{files[i]}: {why}")

    fail(~(np.isfinite(K).all(axis=(1, 2)) & np.isfinite(dist).all(axis=1)),
         "intrinsics hold NaN or inf")
    fail(np.abs(K[:, 2] - np.array([0.0, 0.0, 1.0])).max(axis=1) > 1e-6,
         "third row of K is not 0 0 1")
    fail((K[:, 0, 0] <= 0) | (K[:, 1, 1] <= 0),
         "K is not invertible: focal lengths fx, fy must be > 0")
    fail(np.abs(K[:, 1, 0]) > 1e-6, "K[1, 0] must be 0 (upper-triangular pinhole matrix)")


def check_camera(K: np.ndarray, dist: np.ndarray, files: list[Path], width: int,
                 height: int) -> None:
    """Checks of K (n, 3, 3) and ``k1 k2`` (n, 2) that need the image size: the principal
    point inside the image, a skew of at most 5% of fx, and a radial factor at the image's
    corners between 0.2 and 5 (no real lens bends rays further; such values come from
    wrong units or columns)."""

    def fail(mask: np.ndarray, why) -> None:
        if np.any(mask):
            i = int(np.argmax(mask))
            raise DatasetError(f"{files[i]}: {why(i)}")

    cx, cy = K[:, 0, 2], K[:, 1, 2]
    fail((cx < 0) | (cx > width) | (cy < 0) | (cy > height),
         lambda i: f"principal point ({cx[i]:g}, {cy[i]:g}) lies outside the "
                   f"{width}x{height} image")
    skew = np.abs(K[:, 0, 1])
    fail(skew > 0.05 * K[:, 0, 0],
         lambda i: f"skew K[0, 1] = {K[i, 0, 1]:g} is more than 5% of fx ({K[i, 0, 0]:g})")
    # the farthest corner's normalised radius, and the radial factor the rays divide by
    dx = np.maximum(cx, width - cx) / K[:, 0, 0]
    dy = np.maximum(cy, height - cy) / K[:, 1, 1]
    r2 = dx * dx + dy * dy
    factor = 1.0 + dist[:, 0] * r2 + dist[:, 1] * r2 * r2
    fail((factor < 0.2) | (factor > 5.0),
         lambda i: f"distortion k1={dist[i, 0]:g}, k2={dist[i, 1]:g} scales the corner rays by "
                   f"{1 / factor[i]:.3g}, far from any real lens (wrong units or columns?)")


def check_view_names(folders: dict[str, list[str]], split_dir: Path) -> None:
    """Views are paired by file stem: every folder must hold the same stems."""
    (first, names), *rest = folders.items()
    for other, theirs in rest:
        if theirs == names:
            continue
        only_first, only_other = sorted(set(names) - set(theirs)), sorted(set(theirs) - set(names))
        if len(names) != len(theirs) and (only_first or only_other):
            # a file lost from one folder: say which view it was
            view, has, lacks = ((only_first[0], first, other) if only_first else
                                (only_other[0], other, first))
            raise DatasetError(f"{split_dir}: view counts differ ({first}/ has {len(names)} "
                               f"files, {other}/ has {len(theirs)}): view {view} is in {has}/ "
                               f"but not in {lacks}/")
        missing = only_first + only_other
        where = (f"{missing[0]} is in only one of {first}/ and {other}/" if missing else
                 f"{first}/ and {other}/ order their files differently")
        raise DatasetError(f"{split_dir}: view names differ: {where} (views are paired "
                           "by file name)")


__all__ = ["check_camera", "check_intrinsics", "check_poses", "check_view_names"]
