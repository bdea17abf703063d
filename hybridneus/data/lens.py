"""Lens distortion in OpenCV's models, applied where rays are made: a per-pixel ray table.

A converted recording whose calibration has a distorted lens keeps its events on the pixels
the sensor gave them; ``scene.json`` states the lens (``"lens": {"model": "radtan",
"coeffs": [k1, k2, p1, p2, k3]}``; ``equidistant`` for the Kannala-Brandt fisheye model with
``[k1, k2, k3, k4]``), the intrinsics files keep the pinhole ``K``, and :class:`Lens` turns
every pixel centre into the undistorted normalised direction ``(x / z, y / z)`` once, with
OpenCV (``cv2.undistortPoints`` iterated to 1e-14, ``cv2.fisheye.undistortPoints``).
Projection (the visual hull, ``convert --check``) uses OpenCV's forward models.

The EventNeRF layout's own 5x4 intrinsics (``k1 k2`` applied approximately, as the reference
code does) are a different, older convention and stay in :mod:`hybridneus.data.rays`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hybridneus.errors import DatasetError

#: Lens models and their coefficient counts, in OpenCV's order.
LENS_MODELS = {"radtan": (4, 5, 8, 12, 14), "equidistant": (4,)}

_CRITERIA = (3, 200, 1e-14)  # cv2.TERM_CRITERIA_COUNT | EPS, iterations, epsilon


@dataclass(frozen=True)
class Lens:
    """A distorted lens shared by every view of a split.

    Attributes:
        model: ``radtan`` (``cv2.undistortPoints``' model) or ``equidistant``
            (``cv2.fisheye``).
        coeffs: the model's coefficients in OpenCV's order.
        K: (3, 3) the layout's pinhole matrix (pixel centres at ``+0.5``).
        width: image width in pixels.
        height: image height in pixels.
    """

    model: str
    coeffs: tuple[float, ...]
    K: np.ndarray
    width: int
    height: int
    _table: dict = field(default_factory=dict, compare=False, repr=False)

    def _cv_K(self) -> np.ndarray:
        K = np.array(self.K, dtype=np.float64)
        K[0, 2] -= 0.5  # OpenCV puts pixel (0, 0)'s centre at (0, 0)
        K[1, 2] -= 0.5
        return K

    @property
    def table(self) -> np.ndarray:
        """(height, width, 2) float64 undistorted ``(x / z, y / z)`` of every pixel centre."""
        if "xy" not in self._table:
            import cv2

            u, v = np.meshgrid(np.arange(self.width), np.arange(self.height))
            pix = np.stack([u, v], -1).reshape(-1, 1, 2).astype(np.float64)
            D = np.asarray(self.coeffs, dtype=np.float64)
            if self.model == "equidistant":
                xy = cv2.fisheye.undistortPoints(pix, self._cv_K(), D, criteria=_CRITERIA)
            else:
                xy = cv2.undistortPoints(pix, self._cv_K(), D, criteria=_CRITERIA)
            table = xy.reshape(self.height, self.width, 2)
            if not np.isfinite(table).all():
                raise DatasetError(f"lens {self.model} {list(self.coeffs)}: undistortion "
                                   "gives non-finite directions at some pixels")
            self._table["xy"] = table
        return self._table["xy"]

    def project(self, xn: np.ndarray) -> np.ndarray:
        """(n, 2) continuous layout pixel coordinates (centres at ``+0.5``) of undistorted
        normalised points ``xn`` (n, 2)."""
        import cv2

        xn = np.asarray(xn, dtype=np.float64).reshape(-1, 2)
        D = np.asarray(self.coeffs, dtype=np.float64)
        if self.model == "equidistant":
            uv = cv2.fisheye.distortPoints(xn.reshape(-1, 1, 2), self._cv_K(), D)
        else:
            pts = np.concatenate([xn, np.ones((xn.shape[0], 1))], axis=1)
            uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), self._cv_K(), D)
        return uv.reshape(-1, 2) + 0.5

    def to_json(self) -> dict[str, Any]:
        return {"model": self.model, "coeffs": [float(c) for c in self.coeffs]}


def read_lens(doc: dict[str, Any] | None, K: np.ndarray, width: int, height: int,
              where: str) -> Lens | None:
    """The ``lens`` entry of a ``scene.json`` document, checked; None when it has none (or
    an undistorted one).

    Args:
        doc: the parsed ``scene.json`` (or None).
        K: (n_views, 3, 3) the split's intrinsics: a lens needs them all equal.
        where: the file, for messages.

    Raises:
        DatasetError: an unknown model, a wrong number of coefficients, non-finite values,
            or views with different intrinsics.
    """
    lens = (doc or {}).get("lens")
    if lens is None:
        return None
    if not isinstance(lens, dict):
        raise DatasetError(f"{where}: lens must be an object with model and coeffs")
    model = lens.get("model")
    if model == "pinhole":
        return None
    if model not in LENS_MODELS:
        raise DatasetError(f"{where}: lens model {model!r} unknown (expected "
                           f"{', '.join(LENS_MODELS)} or pinhole)")
    try:
        coeffs = tuple(float(c) for c in lens.get("coeffs", []))
    except (TypeError, ValueError):
        raise DatasetError(f"{where}: lens coeffs must be numbers") from None
    if len(coeffs) not in LENS_MODELS[model]:
        raise DatasetError(f"{where}: lens model {model} takes "
                           f"{' or '.join(map(str, LENS_MODELS[model]))} coefficients, got "
                           f"{len(coeffs)}")
    if not np.isfinite(coeffs).all():
        raise DatasetError(f"{where}: lens coeffs are not all finite")
    if not any(coeffs):
        return None
    K = np.asarray(K, dtype=np.float64)
    if not np.allclose(K, K[:1], rtol=0, atol=1e-9):
        raise DatasetError(f"{where}: a lens needs every view's intrinsics to be the same")
    return Lens(model=model, coeffs=coeffs, K=K[0].copy(), width=width, height=height)


def split_lens(scene_json: Path, K: np.ndarray, distortion: np.ndarray, width: int,
               height: int) -> Lens | None:
    """The lens a dataset's ``scene.json`` states for a split with intrinsics ``K`` (n, 3, 3)
    and EventNeRF distortion ``(k1, k2)`` (n, 2), or None; an unreadable ``scene.json`` has
    already been refused by the preset's reader, so it counts as none here."""
    try:
        doc = json.loads(scene_json.read_text()) if scene_json.is_file() else None
    except (OSError, ValueError):
        doc = None
    lens = read_lens(doc if isinstance(doc, dict) else None, K, width, height, str(scene_json))
    if lens is not None and np.any(distortion):
        raise DatasetError(f"{scene_json}: states a lens, and the 5x4 intrinsics (k1 k2) "
                           "distort too; give one")
    return lens


__all__ = ["LENS_MODELS", "Lens", "read_lens", "split_lens"]
