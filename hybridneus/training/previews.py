"""Preview images during training: predicted vs recorded event frames, colour, normals, curve.

Drawn with OpenCV only (no matplotlib).
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import torch

from hybridneus.fileio import atomic_path

_MAX_PREVIEW_WIDTH = 128


def diverging_bgr(frame: np.ndarray, scale: float) -> np.ndarray:
    """Signed (h, w) -> BGR uint8: red positive, blue negative, white zero."""
    v = np.clip(frame / max(scale, 1e-6), -1.0, 1.0)
    out = np.ones((*frame.shape, 3), dtype=np.float32)
    pos, neg = np.clip(v, 0, 1), np.clip(-v, 0, 1)
    out[..., 0] -= pos  # less blue where positive -> red
    out[..., 1] -= pos + neg
    out[..., 2] -= neg  # less red where negative -> blue
    return (np.clip(out, 0, 1) * 255).astype(np.uint8)


def _label(img: np.ndarray, text: str) -> np.ndarray:
    img = img.copy()
    cv2.putText(img, text, (2, 10), cv2.FONT_HERSHEY_SIMPLEX, 0.3, (0, 0, 0), 1, cv2.LINE_AA)
    return img


@torch.no_grad()
def render_window_preview(trainer, view: int | None = None) -> dict[str, np.ndarray]:
    """Render one view's window at reduced resolution.

    Returns:
        dict with ``pred_events`` and ``events`` ((h, w) signed C*E scale), ``rgb`` (h, w, 3)
        in [0, 1] at the window end, ``normal`` (h, w, 3) in [-1, 1].
    """
    from hybridneus.data import bayer_mask, camera_rays
    from hybridneus.rendering.renderer import render_rays_chunked

    win = trainer.windows
    split = win.split
    n = split.n_views
    i = n // 2 if view is None else int(view)
    t1 = i * win.dt
    t0 = max(t1 - 0.5 * win.l_max, 0.0)
    stride = max(1, math.ceil(split.width / _MAX_PREVIEW_WIDTH))
    xs = np.arange(0, split.width, stride)
    ys = np.arange(0, split.height, stride)
    gx, gy = np.meshgrid(xs, ys)
    xy = np.stack([gx.ravel(), gy.ravel()], axis=1).astype(np.int64)
    c2w0, k0 = win.pose_at(t0)
    dev = trainer.device
    o0, d0 = camera_rays(split.intrinsics[k0], split.distortion[k0], c2w0, xy, device=dev,
                         lens=split.lens)
    o1, d1 = camera_rays(split.intrinsics[i], split.distortion[i], split.c2w[i], xy, device=dev,
                         lens=split.lens)
    field = trainer.field
    soft = trainer.cfg.render.crop_softness
    out = render_rays_chunked(
        field, torch.cat([o0, o1]), torch.cat([d0, d1]), trainer.sampler, crop_softness=soft
    )
    m = xy.shape[0]
    c0, c1 = out.color[:m], out.color[m:]
    eps = trainer.tonemap_eps()  # the loss's eps at this step (eased early in training)
    diff = torch.log(c1.clamp_min(0) ** 2.2 + eps) - torch.log(c0.clamp_min(0) ** 2.2 + eps)
    bayer = torch.as_tensor(bayer_mask(xy, trainer.preset.mosaic), device=dev)
    pred = (diff * bayer).sum(-1).cpu().numpy().reshape(len(ys), len(xs))
    frame = win.frame(t0, t1) * trainer.preset.threshold
    events = frame[np.ix_(ys, xs)]
    return {
        "pred_events": pred,
        "events": events,
        "rgb": c1.cpu().numpy().reshape(len(ys), len(xs), 3),
        "normal": out.normal[m:].cpu().numpy().reshape(len(ys), len(xs), 3),
    }


def write_preview(trainer, path: Path, view: int | None = None) -> None:
    """PNG of [predicted events | recorded events | colour | normals] for one view."""
    p = render_window_preview(trainer, view)
    scale = float(np.percentile(np.abs(p["events"]), 99)) or 1.0
    rgb = (np.clip(p["rgb"], 0, 1)[..., ::-1] * 255).astype(np.uint8)
    normal = ((p["normal"] * 0.5 + 0.5).clip(0, 1)[..., ::-1] * 255).astype(np.uint8)
    tiles = [
        _label(diverging_bgr(p["pred_events"], scale), "render d log"),
        _label(diverging_bgr(p["events"], scale), "C*E"),
        _label(rgb, "colour"),
        _label(normal, "normal"),
    ]
    img = np.concatenate(tiles, axis=1)
    if img.shape[0] < 160:
        f = max(1, 160 // img.shape[0])
        img = cv2.resize(img, None, fx=f, fy=f, interpolation=cv2.INTER_NEAREST)
    _write_png(path, img)


def _panel(img: np.ndarray, box: tuple[int, int, int, int],
           series: list[tuple[str, tuple[int, int, int], np.ndarray, bool]],
           bounds: tuple[float, float] | None = None) -> None:
    """Draw ``(label, bgr, (n, 2) step/value, log10)`` series into ``box`` (x0, y0, x1, y1)
    of ``img``, on one shared y range (``bounds``, else the data's)."""
    x0b, y0b, x1b, y1b = box
    cv2.rectangle(img, (x0b, y0b), (x1b, y1b), (180, 180, 180), 1)
    drawn = [(k, c, np.column_stack([a[:, 0], np.log10(a[:, 1]) if lg else a[:, 1]]))
             for k, c, a, lg in series if len(a) >= 2]
    if not drawn:
        return
    steps = np.concatenate([d[2][:, 0] for d in drawn])
    vals = np.concatenate([d[2][:, 1] for d in drawn])
    sx0, sx1 = steps.min(), max(steps.max(), steps.min() + 1)
    lo, hi = bounds if bounds is not None else (vals.min(), max(vals.max(), vals.min() + 1e-3))
    for n, (key, colour, arr) in enumerate(drawn):
        px = x0b + (arr[:, 0] - sx0) / (sx1 - sx0) * (x1b - x0b)
        py = y1b - (np.clip(arr[:, 1], lo, hi) - lo) / (hi - lo) * (y1b - y0b)
        poly = np.stack([px, py], axis=1).round().astype(np.int32)
        cv2.polylines(img, [poly], False, colour, 1, cv2.LINE_AA)
        cv2.putText(img, key, (x0b + 120 * n, y0b - 6), cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1)
    cv2.putText(img, f"{hi:.2f}", (2, y0b + 8), cv2.FONT_HERSHEY_SIMPLEX, 0.3, (0, 0, 0), 1)
    cv2.putText(img, f"{lo:.2f}", (2, y1b), cv2.FONT_HERSHEY_SIMPLEX, 0.3, (0, 0, 0), 1)


def _points(history: list[dict[str, float]], key: str, positive: bool) -> np.ndarray:
    pts = [(r["step"], r[key]) for r in history
           if key in r and math.isfinite(r[key]) and (r[key] > 0 or not positive)]
    return np.array(pts, dtype=np.float64).reshape(-1, 2)


def write_curve(history: list[dict[str, float]], path: Path, size=(480, 400)) -> None:
    """Training curves against step as a PNG: above, log10 of the losses; below, log10 of
    the NeuS sharpness ``inv_s`` and the mean rendered opacity (0 to 1 on the same axis, so
    that a sharpness running away or a field emptying shows at a glance)."""
    w, h = size
    img = np.full((h, w, 3), 255, np.uint8)
    pad, mid = 30, int(h * 0.6)
    losses = [("loss/total", (0, 0, 0)), ("loss/event", (200, 60, 0)),
              ("loss/eikonal", (0, 140, 0)), ("loss/rgb", (0, 60, 200))]
    _panel(img, (pad, pad, w - pad, mid - pad // 2),
           [(k, c, _points(history, k, True), True) for k, c in losses])
    cv2.putText(img, "log10", (2, pad + 20), cv2.FONT_HERSHEY_SIMPLEX, 0.3, (0, 0, 0), 1)
    sharp = _points(history, "inv_s", True)
    state = [("log10 inv_s", (160, 0, 160), sharp, True),
             ("opacity x 6", (0, 120, 230), _points(history, "opacity", False) * [1, 6], False)]
    _panel(img, (pad, mid + pad // 2, w - pad, h - pad), state, bounds=(0.0, 6.0))
    last = int(max((r["step"] for r in history), default=0))
    cv2.putText(img, f"step {last}", (w - 90, h - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.35,
                (0, 0, 0), 1)
    _write_png(path, img)


def write_pose_changes(degrees: np.ndarray, moved: np.ndarray, path: Path,
                       size=(480, 300)) -> None:
    """How far the trained track moved each view from the given one, as a PNG: above, the
    rotation (degrees); below, the camera centre's shift (world units), against the view."""
    w, h = size
    img = np.full((h, w, 3), 255, np.uint8)
    pad, mid = 30, h // 2
    views = np.arange(len(degrees), dtype=np.float64)
    _panel(img, (pad, pad, w - pad, mid - pad // 2),
           [("rotation (deg)", (200, 60, 0), np.column_stack([views, degrees]), False)])
    _panel(img, (pad, mid + pad // 2, w - pad, h - pad),
           [("centre moved", (0, 120, 0), np.column_stack([views, moved]), False)])
    cv2.putText(img, "view", (w - 60, h - 8), cv2.FONT_HERSHEY_SIMPLEX, 0.35, (0, 0, 0), 1)
    _write_png(path, img)


def _write_png(path: Path, img: np.ndarray) -> None:
    path = Path(path)
    with atomic_path(path) as tmp:
        ok, buf = cv2.imencode(".png", img)
        if not ok:
            raise OSError(f"{path}: PNG encoding failed")
        tmp.write_bytes(buf.tobytes())
