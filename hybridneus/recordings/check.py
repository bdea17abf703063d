"""Pictures that show at a glance whether a conversion got its conventions right.

- ``track.png``: the camera track in the normalised frame from above (x, z) and from the
  side (x, y), with the unit sphere, the crop cylinder, each tenth of the views' optical axes
  and the user's points; a camera looking away from the object, a flipped up axis or a track
  outside the sphere shows at once.
- ``events_<view>.png``: event frames at a few views with the user's points (or box corners)
  projected into them: a wrong clock offset, axis convention or intrinsics puts the marks off
  the object.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw

from hybridneus.data.dataset import EventDataset
from hybridneus.fileio import atomic_path

_PANEL = 420


def project(points: np.ndarray, K: np.ndarray, c2w: np.ndarray, lens=None
            ) -> tuple[np.ndarray, np.ndarray]:
    """Pixel (column, row) positions of normalised-frame ``points`` (n, 3) in a layout camera
    (pixel centres at +0.5; through ``lens``, a :class:`~hybridneus.data.lens.Lens`, when
    the dataset has one), and which of them lie in front of it."""
    R, c = c2w[:3, :3], c2w[:3, 3]
    cam = (np.asarray(points, dtype=np.float64) - c) @ R
    front = cam[:, 2] > 1e-9
    z = np.where(front, cam[:, 2], 1.0)
    if lens is not None:
        return lens.project(cam[:, :2] / z[:, None]) - 0.5, front
    uv = (cam[:, :2] / z[:, None]) * np.array([K[0, 0], K[1, 1]]) + K[:2, 2]
    uv[:, 0] += K[0, 1] * cam[:, 1] / z
    return uv - 0.5, front


def _save(img: Image.Image, path: Path) -> None:
    with atomic_path(path) as tmp:
        img.save(tmp, format="PNG")


def track_picture(c2w: np.ndarray, crop: tuple[float, float, float], points: np.ndarray,
                  path: Path) -> Path:
    """Top and side views of the camera track (see the module docstring)."""
    img = Image.new("RGB", (2 * _PANEL, _PANEL + 24), "white")
    draw = ImageDraw.Draw(img)
    half = _PANEL / 2
    scale = 0.45 * _PANEL / 1.1

    def to_px(a: np.ndarray, b: np.ndarray, panel: int) -> list[tuple[float, float]]:
        return [(panel * _PANEL + half + scale * u, 24 + half - scale * v)
                for u, v in zip(a, b, strict=True)]

    r, y0, y1 = crop
    n = c2w.shape[0]
    centres = c2w[:, :3, 3]
    axes = c2w[:, :3, 2]
    for panel, (i, j, title) in enumerate(((0, 2, "from above: x right, z up the page"),
                                           (0, 1, "from the side: x right, y up"))):
        ox, oy = panel * _PANEL + half, 24 + half
        draw.text((panel * _PANEL + 8, 4), title, fill="black")
        draw.ellipse([ox - scale, oy - scale, ox + scale, oy + scale], outline=(150, 150, 150))
        if panel == 0:
            draw.ellipse([ox - scale * r, oy - scale * r, ox + scale * r, oy + scale * r],
                         outline=(0, 150, 0))
        else:
            draw.rectangle([ox - scale * r, oy - scale * min(y1, 1.1),
                            ox + scale * r, oy - scale * max(y0, -1.1)], outline=(0, 150, 0))
        pts = to_px(centres[:, i], centres[:, j], panel)
        for k in range(n - 1):
            shade = int(200 * k / max(n - 1, 1))
            draw.line([pts[k], pts[k + 1]], fill=(shade, 0, 200 - shade), width=2)
        for k in range(0, n, max(1, n // 10)):
            tip = centres[k] + 0.25 * axes[k]
            a, b = to_px(np.array([centres[k, i], tip[i]]), np.array([centres[k, j], tip[j]]),
                         panel)
            draw.line([a, b], fill=(255, 140, 0), width=1)
        for u, v in to_px(points[:, i], points[:, j], panel) if len(points) else []:
            draw.line([(u - 5, v - 5), (u + 5, v + 5)], fill="black", width=2)
            draw.line([(u - 5, v + 5), (u + 5, v - 5)], fill="black", width=2)
    draw.text((8, _PANEL + 6), "grey: unit sphere  green: crop  blue->red: first->last view  "
              "orange: optical axes  x: your points", fill="black")
    _save(img, path)
    return path


def event_pictures(ds: EventDataset, points: np.ndarray, out: Path, n: int = 4) -> list[Path]:
    """Event frames at ``n`` views with ``points`` (normalised frame) projected into them."""
    from hybridneus.data import event_frame
    from hybridneus.data.pictures import event_image

    sp = ds.splits["train"]
    dt = sp.t_max / (sp.n_views - 1)
    length = float(min(ds.preset.max_window, 10))
    views = np.unique(np.linspace(1, sp.n_views - 1, min(n, sp.n_views - 1)).round()).astype(int)
    written = []
    for v in views:
        frame = event_frame(sp, max(v * dt - length * dt, 0.0), v * dt, 0.0)
        img = Image.fromarray(event_image(frame))
        draw = ImageDraw.Draw(img)
        if len(points):
            uv, front = project(points, sp.intrinsics[v], sp.c2w[v], sp.lens)
            for (u, w), ok in zip(uv, front, strict=True):
                if ok:
                    draw.ellipse([u - 4, w - 4, u + 4, w + 4], outline=(0, 160, 0), width=2)
        path = out / f"events_{sp.view_names[v]}.png"
        _save(img, path)
        written.append(path)
    return written


def write_check(ds: EventDataset, points_recording: np.ndarray, frame, out: Path) -> list[Path]:
    """All check pictures of a converted dataset into ``out``.

    Args:
        ds: the converted dataset, loaded back (what ``fit`` will see).
        points_recording: (n, 3) points in the recording's frame to mark (may be empty).
        frame: the dataset's :class:`~hybridneus.recordings.frame.SceneFrame`.
        out: folder for the pictures.
    """
    out.mkdir(parents=True, exist_ok=True)
    pts = frame.to_normalised(points_recording) if len(points_recording) else np.zeros((0, 3))
    p = ds.preset
    paths = [track_picture(ds.splits["train"].c2w, (p.crop_r, p.crop_y_min, p.crop_y_max), pts,
                           out / "track.png")]
    paths += event_pictures(ds, pts, out)
    return paths
