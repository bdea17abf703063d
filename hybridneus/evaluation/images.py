"""Image metrics for novel views: PSNR, SSIM, and the log-space colour correction before them.

Events fix colour only up to a per-channel gain (and offset in log space), so the EventNeRF
evaluation first fits, per channel c and over the foreground pixels,
    log(gt_c + eps) ~= a_c * log(pred_c + eps) + b_c        (least squares)
and compares gt against pred' = exp(a_c * log(pred_c + eps) + b_c) - eps, clipped to [0, 1].
Images are float arrays (height, width, 3) in [0, 1]; masks are (height, width) bool.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class ImageMetrics:
    """PSNR (dB) and SSIM of one image pair, and the fitted correction (a, b per channel)."""

    psnr: float
    ssim: float
    gain: tuple[float, float, float]
    offset: tuple[float, float, float]

    def as_dict(self) -> dict:
        """The fields as a plain dict (for JSON)."""
        return asdict(self)


def _check(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None) -> np.ndarray:
    """Validate shapes; return the mask (height, width) bool (all True when None)."""
    if pred.shape != gt.shape or pred.ndim != 3 or pred.shape[2] != 3:
        raise ValueError(f"expected two (height, width, 3) images, got {pred.shape}, {gt.shape}")
    if mask is None:
        return np.ones(pred.shape[:2], dtype=bool)
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != pred.shape[:2]:
        raise ValueError(f"mask shape {mask.shape} does not match image {pred.shape[:2]}")
    if not mask.any():
        raise ValueError("mask selects no pixels")
    return mask


def psnr(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None) -> float:
    """PSNR in dB (data range 1) over the masked pixels (all channels)."""
    mask = _check(pred, gt, mask)
    err = (np.asarray(pred, np.float64) - np.asarray(gt, np.float64))[mask]
    mse = float(np.mean(err**2))
    return float("inf") if mse == 0.0 else float(-10.0 * np.log10(mse))


def ssim(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None) -> float:
    """SSIM (skimage, Gaussian 11x11 window, data range 1), averaged over the masked pixels."""
    from skimage.metrics import structural_similarity

    mask = _check(pred, gt, mask)
    _, smap = structural_similarity(
        np.asarray(pred, np.float64),
        np.asarray(gt, np.float64),
        channel_axis=-1,
        data_range=1.0,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        full=True,
    )
    return float(smap.mean(axis=-1)[mask].mean())


def fit_log_color_correction(
    pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None, eps: float = 1e-3
) -> tuple[np.ndarray, np.ndarray]:
    """Per-channel (gain (3,), offset (3,)) of log(gt + eps) ~= gain * log(pred + eps) + offset."""
    mask = _check(pred, gt, mask)
    lp = np.log(np.clip(np.asarray(pred, np.float64), 0.0, None) + eps)[mask]  # (n_fg, 3)
    lg = np.log(np.clip(np.asarray(gt, np.float64), 0.0, None) + eps)[mask]
    gain, offset = np.ones(3), np.zeros(3)
    for c in range(3):
        x = lp[:, c]
        if np.ptp(x) < 1e-12:  # a flat channel has no slope: fit the offset alone
            offset[c] = float(np.mean(lg[:, c] - x))
            continue
        design = np.stack([x, np.ones_like(x)], axis=1)
        (gain[c], offset[c]), *_ = np.linalg.lstsq(design, lg[:, c], rcond=None)
    return gain, offset


def apply_log_color_correction(
    pred: np.ndarray, gain: np.ndarray, offset: np.ndarray, eps: float = 1e-3
) -> np.ndarray:
    """pred' = exp(gain * log(pred + eps) + offset) - eps, clipped to [0, 1]."""
    lp = np.log(np.clip(np.asarray(pred, np.float64), 0.0, None) + eps)
    return np.clip(np.exp(lp * gain + offset) - eps, 0.0, 1.0)


def color_corrected_psnr_ssim(
    pred: np.ndarray, gt: np.ndarray, mask: np.ndarray | None = None, eps: float = 1e-3
) -> ImageMetrics:
    """PSNR and SSIM of ``pred`` against ``gt`` after the log-space colour correction.

    Args:
        pred: rendered image (height, width, 3) in [0, 1].
        gt: reference image (height, width, 3) in [0, 1].
        mask: foreground (height, width) bool; the fit and the metrics use only these pixels.
        eps: added before the logarithm, so black pixels stay finite.
    """
    gain, offset = fit_log_color_correction(pred, gt, mask, eps)
    corrected = apply_log_color_correction(pred, gain, offset, eps)
    return ImageMetrics(
        psnr=psnr(corrected, gt, mask),
        ssim=ssim(corrected, gt, mask),
        gain=tuple(float(v) for v in gain),
        offset=tuple(float(v) for v in offset),
    )


def read_frame(path, width: int, height: int) -> np.ndarray | None:
    """A reference frame as (height, width, 3) float32 RGB in [0, 1], or None when the file
    is unreadable or of another size (real scenes ship placeholder frames)."""
    import cv2

    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None or img.shape[:2] != (height, width):
        return None
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB).astype(np.float32) / 255.0


def foreground_mask(gt: np.ndarray, background, tol: float = 2.0 / 255.0) -> np.ndarray:
    """(height, width) bool: pixels of ``gt`` that differ from the constant ``background``
    (RGB in [0, 1]) by more than ``tol`` in some channel, i.e. where the object is."""
    return np.abs(gt - np.asarray(background, dtype=np.float32)).max(axis=-1) > tol
