"""The image size of a dataset whose ``scene.json`` and path state none.

The EventNeRF layout stores no size. In order: ``scene.json`` (any of its places; read with
the preset), the published scene's path, the size of the rgb frames, the principal point
(when it lies far from the centre of the 346x260 default, the size it suggests), the default.
A stated size that the rgb frames contradict is an error.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hybridneus.errors import DatasetError


def _frame_sizes(split_dir: Path):
    """(file, (width, height)) of each readable rgb frame of a split, from its header only
    (unreadable frames are skipped: a fit does not read them; whatever reads them later
    names a bad one)."""
    from PIL import Image, UnidentifiedImageError

    folder = split_dir / "rgb"
    if not folder.is_dir():
        return
    for path in sorted(p for p in folder.iterdir() if p.is_file() and not p.name.startswith(".")):
        try:
            with Image.open(path) as img:
                size = (int(img.size[0]), int(img.size[1]))
        except (OSError, UnidentifiedImageError):
            continue
        yield path, size


def rgb_size(split_dir: Path) -> tuple[tuple[int, int], Path] | None:
    """((width, height), file) of the first readable rgb frame of a split, or None."""
    for path, size in _frame_sizes(split_dir):
        return size, path
    return None


def principal_point_size(K: np.ndarray, default: tuple[int, int]) -> tuple[int, int] | None:
    """The size the median principal point of ``K`` (n, 3, 3) suggests, when it lies more than
    20% of the default's width or height from the default's centre; else None."""
    cx, cy = float(np.median(K[:, 0, 2])), float(np.median(K[:, 1, 2]))
    w, h = default
    if abs(cx - w / 2) > 0.2 * w or abs(cy - h / 2) > 0.2 * h:
        return max(1, round(2 * cx)), max(1, round(2 * cy))
    return None


def check_rgb_size(split_dir: Path, width: int, height: int, source: str) -> None:
    """Refuse rgb frames of another size than the one stated."""
    for path, (w, h) in _frame_sizes(split_dir):
        if (w, h) != (width, height):
            raise DatasetError(f"{path}: frame is {w}x{h}, but {source} states "
                               f"{width}x{height}")


def _first_K(split_dir: Path, n: int = 16) -> np.ndarray | None:
    files = sorted((split_dir / "intrinsics").glob("*.txt"))[:n]
    mats = []
    for f in files:
        try:
            v = np.array(f.read_text().replace(",", " ").split(), dtype=np.float64)
        except (OSError, ValueError, UnicodeDecodeError):
            return None  # the full reader names the bad file
        if v.size not in (16, 20):
            return None
        mats.append(v.reshape(-1, 4)[:3, :3])
    return np.asarray(mats) if mats else None


def resolve_size(preset, stated: frozenset[str], source: str, splits: list[Path],
                 notes: list[str]):
    """``preset`` with the image size of the module docstring's order; checks a stated
    size against the rgb frames. ``splits``: the split folders to be loaded."""
    from hybridneus.data.presets import apply_overrides

    if {"width", "height"} & stated:
        for split in splits:
            check_rgb_size(split, preset.width, preset.height, source)
        return preset
    size, why = None, ""
    for split in splits:
        found = rgb_size(split)
        if found is not None:
            size, why = found[0], f"the rgb frames ({found[1]})"
            break
    if size is None and splits:
        K = _first_K(splits[0])
        size = principal_point_size(K, (preset.width, preset.height)) if K is not None \
            else None
        why = f"the principal point of {splits[0] / 'intrinsics'}, far from the centre of " \
              f"{preset.width}x{preset.height}"
    if size is None or size == (preset.width, preset.height):
        return preset
    notes.append(f"image size {size[0]}x{size[1]} from {why} (no scene.json states one)")
    for split in splits:
        check_rgb_size(split, *size, why)
    return apply_overrides(preset, {"width": size[0], "height": size[1]})


__all__ = ["check_rgb_size", "principal_point_size", "resolve_size", "rgb_size"]
