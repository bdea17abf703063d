"""The training curve PNG: losses above, sharpness and opacity below."""

from __future__ import annotations

import cv2
import numpy as np

from hybridneus.training.previews import write_curve

SHARPNESS_BGR = (160, 0, 160)
OPACITY_BGR = (0, 120, 230)


def _rows_with(img: np.ndarray, bgr: tuple[int, int, int], top: int) -> np.ndarray:
    """Rows at or below ``top`` holding pixels of colour ``bgr`` (the labels above a panel
    share its colours)."""
    hit = np.all(np.abs(img.astype(int) - np.array(bgr)) < 30, axis=-1)
    hit[:top] = False
    return np.nonzero(hit.any(axis=1))[0]


def test_the_curve_shows_a_runaway_sharpness_and_an_emptied_field(tmp_path):
    """inv_s climbing to 1e6 reaches the lower panel's top; opacity falling to 0 its bottom;
    a fit that does neither stays inside the panel."""
    steps = np.arange(1, 401, 10)
    runaway = [{"step": float(s), "loss/total": 1.0 / s, "loss/event": 0.5 / s,
                "inv_s": float(20 * 10 ** (s / 80)) if s < 400 else 1e6,
                "opacity": 0.9 if s < 300 else 0.0} for s in steps]
    calm = [{**r, "inv_s": 300.0, "opacity": 0.6} for r in runaway]
    images = {}
    for name, history in (("runaway", runaway), ("calm", calm)):
        path = tmp_path / f"{name}.png"
        write_curve(history, path)
        images[name] = cv2.imread(str(path))
    img = images["runaway"]
    h = img.shape[0]
    top, bottom = int(h * 0.6) + 15, h - 30  # the lower panel's box
    sharp, opacity = _rows_with(img, SHARPNESS_BGR, top), _rows_with(img, OPACITY_BGR, top)
    assert sharp.size and opacity.size
    assert sharp.min() <= top + 2 and opacity.max() >= bottom - 2
    calm_sharp = _rows_with(images["calm"], SHARPNESS_BGR, top)
    calm_opacity = _rows_with(images["calm"], OPACITY_BGR, top)
    assert calm_sharp.min() > top + 10 and calm_opacity.max() < bottom - 10
