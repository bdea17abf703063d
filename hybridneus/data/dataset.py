"""Loading an EventNeRF-layout dataset: splits, poses, intrinsics, events, rgb names.

Layout (see ``docs/data.md``)::

    <root>/<split>/pose/*.txt         16 floats, row-major 4x4 camera-to-world (OpenCV axes)
    <root>/<split>/intrinsics/*.txt   16 floats (4x4, K top-left) or 20 (fifth row k1 k2 0 0)
    <root>/<split>/rgb/*              optional; only the names are used
    <root>/<split>/events/<one>.npz   keys x (column), y (row), t, p

Views are matched by sorted file name. Every check raises :class:`DatasetError` with a
one-line message that names the offending file or folder first.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hybridneus.data.events import EventStream, load_events
from hybridneus.data.checks import (
    check_camera,
    check_intrinsics,
    check_poses,
    check_view_names,
)
from hybridneus.data.imagesize import resolve_size
from hybridneus.data.lens import Lens, split_lens
from hybridneus.data.presets import (
    PRESET_FIELDS,
    ScenePreset,
    apply_overrides,
    resolve_preset_fields,
)
from hybridneus.errors import DatasetError

log = logging.getLogger(__name__)

STANDARD_SPLITS = ("train", "validation", "test")
_REQUIRED = ("pose", "intrinsics", "events")


@dataclass
class SplitData:
    """One split (``train``, ``validation``, ``test``, ...) of a dataset.

    Attributes:
        name: split folder name.
        path: split folder.
        c2w: (n_views, 4, 4) float64 camera-to-world, OpenCV axes (x right, y down, z forward).
        intrinsics: (n_views, 3, 3) float64 pinhole matrices K.
        distortion: (n_views, 2) float64 radial coefficients (k1, k2); zeros for 4x4 files.
        width: image width in pixels (from the preset; the files do not store it).
        height: image height in pixels.
        view_names: (n_views,) file stems of the pose files, in view order.
        events: the split's :class:`EventStream`.
        rgb_paths: paths of the rgb files in view order, or None when ``rgb/`` is absent.
        lens: the distorted lens ``scene.json`` states (OpenCV's models; rays then come from
            its per-pixel table), or None.
        pixel_offset: (height * width,) float32 polarity offsets of each pixel
            (:func:`hybridneus.data.balance.pixel_offsets`) used in place of the preset's
            one, or None.
    """

    name: str
    path: Path
    c2w: np.ndarray
    intrinsics: np.ndarray
    distortion: np.ndarray
    width: int
    height: int
    view_names: list[str]
    events: EventStream
    rgb_paths: list[Path] | None = None
    lens: Lens | None = None
    pixel_offset: np.ndarray | None = None

    @property
    def n_views(self) -> int:
        """Number of views."""
        return int(self.c2w.shape[0])

    @property
    def t_max(self) -> float:
        """Largest event timestamp; the time of the last view."""
        return self.events.t_max

    @property
    def view_times(self) -> np.ndarray:
        """(n_views,) float64 time of each view: ``i / (n_views - 1) * t_max``."""
        n = self.n_views
        if n < 2:
            return np.zeros(n)
        return np.arange(n, dtype=np.float64) / (n - 1) * self.t_max


@dataclass
class EventDataset:
    """A loaded dataset.

    Attributes:
        root: the dataset folder.
        preset: the :class:`ScenePreset` in use (after overrides).
        preset_source: where the preset came from, e.g. ``"path (real/multimeter)"``.
        splits: split name -> :class:`SplitData`.
        notes: messages worth showing to the user (polarity conversion, size checks).
        stated: the preset fields that the path, ``scene.json``, the caller or an override
            gave; the others are the fallback's ``nerf`` values, which a fit may replace with
            estimates from the events (``estimate.polarity_offset``).
    """

    root: Path
    preset: ScenePreset
    preset_source: str
    splits: dict[str, SplitData]
    notes: list[str] = field(default_factory=list)
    stated: frozenset[str] = frozenset(PRESET_FIELDS)

    def __getitem__(self, split: str) -> SplitData:
        try:
            return self.splits[split]
        except KeyError:
            raise DatasetError(
                f"{self.root / split}: split not loaded (have: {', '.join(self.splits)})"
            ) from None


def _list_files(folder: Path, suffix: str | None) -> list[Path]:
    """Regular, non-hidden files in ``folder`` (optionally with ``suffix``), sorted by name."""
    try:
        entries = list(os.scandir(folder))
    except OSError as exc:
        raise DatasetError(f"{folder}: cannot list folder ({exc.strerror})") from None
    out = [
        Path(e.path)
        for e in entries
        if not e.name.startswith(".")
        and (suffix is None or e.name.lower().endswith(suffix))
        and _is_file(e)
    ]
    return sorted(out, key=lambda p: _natural(p.name))


def _is_file(entry: os.DirEntry) -> bool:
    try:
        return entry.is_file()
    except OSError as exc:  # a symlink loop, for one
        raise DatasetError(f"{entry.path}: cannot read ({exc.strerror})") from None


def _natural(name: str) -> list:
    """Sort key that orders ``r_2`` before ``r_10`` (numbers compared as numbers)."""
    return [(0, int(part), "") if part.isdigit() else (1, 0, part)
            for part in re.split(r"(\d+)", name)]


def _read_floats(path: Path, counts: tuple[int, ...], what: str) -> np.ndarray:
    """Read a whitespace-separated text file of floats with one of ``counts`` values."""
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{path}: cannot read ({exc})") from None
    try:
        values = np.array([float(v) for v in text.replace(",", " ").split()], dtype=np.float64)
    except ValueError as exc:
        raise DatasetError(f"{path}: not a list of numbers ({exc})") from None
    if values.size not in counts:
        expected = " or ".join(str(c) for c in counts)
        raise DatasetError(f"{path}: expected {expected} floats ({what}), found {values.size}")
    return values


def read_camera_centres(split_dir: str | os.PathLike) -> np.ndarray:
    """Camera centres (n_views, 3) from the ``pose/`` files of one split folder, without
    reading its events.

    Raises:
        DatasetError: no pose files, or a malformed one (the message names it).
    """
    pose_files = _list_files(Path(split_dir) / "pose", ".txt")
    if not pose_files:
        raise DatasetError(f"{Path(split_dir) / 'pose'}: no .txt pose files")
    c2w = _read_pose_matrices(pose_files)
    check_poses(c2w, pose_files)
    return c2w[:, :3, 3].copy()


def _read_pose_matrices(pose_files: list[Path]) -> np.ndarray:
    """(n, 4, 4) camera-to-world matrices, one per file, unchecked (see :func:`_check_poses`)."""
    c2w = np.empty((len(pose_files), 4, 4))
    for i, f in enumerate(pose_files):
        c2w[i] = _read_floats(f, (16,), "row-major 4x4 camera-to-world pose").reshape(4, 4)
    return c2w


def _read_views(
    split_dir: Path,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str], list[Path]]:
    pose_files = _list_files(split_dir / "pose", ".txt")
    intr_files = _list_files(split_dir / "intrinsics", ".txt")
    if not pose_files:
        raise DatasetError(f"{split_dir / 'pose'}: no .txt pose files")
    check_view_names({"pose": [f.stem for f in pose_files],
                      "intrinsics": [f.stem for f in intr_files]}, split_dir)
    n = len(pose_files)
    c2w = _read_pose_matrices(pose_files)
    K = np.empty((n, 3, 3))
    dist = np.zeros((n, 2))
    for i, f in enumerate(intr_files):
        v = _read_floats(f, (16, 20), "4x4 intrinsics, or 5x4 with k1 k2 0 0 as fifth row")
        m = v.reshape(-1, 4)
        K[i] = m[:3, :3]
        if m.shape[0] == 5:
            dist[i] = m[4, :2]
    check_poses(c2w, pose_files)
    check_intrinsics(K, dist, intr_files)
    return c2w, K, dist, [f.stem for f in pose_files], intr_files


def _find_splits(root: Path) -> dict[str, Path]:
    """Sub-folders of ``root`` that look like splits (hold pose/, intrinsics/ or events/)."""
    try:
        subdirs = [Path(e.path) for e in os.scandir(root) if e.is_dir()]
    except OSError as exc:
        raise DatasetError(f"{root}: cannot list folder ({exc.strerror})") from None
    found = {
        d.name: d
        for d in subdirs
        if not d.name.startswith(".") and any((d / r).is_dir() for r in _REQUIRED)
    }
    order = [s for s in STANDARD_SPLITS if s in found] + sorted(
        s for s in found if s not in STANDARD_SPLITS
    )
    return {s: found[s] for s in order}


def _check_resolution(
    K: np.ndarray, width: int, height: int, split_dir: Path, notes: list[str]
) -> None:
    """Warn when the principal point does not fit the image size in use."""
    cx, cy = float(np.median(K[:, 0, 2])), float(np.median(K[:, 1, 2]))
    if abs(cx - width / 2) > 0.2 * width or abs(cy - height / 2) > 0.2 * height:
        msg = (
            f"{split_dir}: principal point ({cx:.1f}, {cy:.1f}) suggests an image of about "
            f"{round(2 * cx)}x{round(2 * cy)}, but {width}x{height} is in use (the format "
            "stores no size; set overrides width=..., height=... if it is wrong)"
        )
        log.warning(msg)
        notes.append(msg)


def load_split(
    split_dir: str | os.PathLike, width: int, height: int, notes: list[str] | None = None
) -> SplitData:
    """Load one split folder.

    Args:
        split_dir: the split folder (holding pose/, intrinsics/, events/, optional rgb/).
        width: image width in pixels.
        height: image height in pixels.
        notes: list that receives messages for the user (polarity conversion, size checks).

    Raises:
        DatasetError: any deviation from the layout (see ``docs/data.md``).
    """
    split_dir = Path(split_dir)
    notes = notes if notes is not None else []
    if not split_dir.is_dir():
        raise DatasetError(f"{split_dir}: missing split folder")
    for sub in _REQUIRED:
        if not (split_dir / sub).is_dir():
            raise DatasetError(f"{split_dir / sub}: missing folder")
    c2w, K, dist, names, intr_files = _read_views(split_dir)
    rgb_paths: list[Path] | None = None
    if (split_dir / "rgb").is_dir():
        rgb_paths = _list_files(split_dir / "rgb", None)
        if not rgb_paths:
            rgb_paths = None
        else:
            check_view_names({"pose": names, "rgb": [p.stem for p in rgb_paths]}, split_dir)
    npz = _list_files(split_dir / "events", ".npz")
    if len(npz) != 1:
        listed = ", ".join(p.name for p in npz) if npz else "none"
        raise DatasetError(
            f"{split_dir / 'events'}: expected exactly one .npz file, found {len(npz)} "
            f"({listed})"
        )
    _check_resolution(K, width, height, split_dir, notes)
    check_camera(K, dist, intr_files, width, height)
    radius = float(np.linalg.norm(c2w[:, :3, 3], axis=1).max())
    if radius > 1.0:
        msg = (
            f"{split_dir / 'pose'}: cameras reach radius {radius:.3g} > 1; rays are bounded "
            "by the unit sphere (NeRF++ normalisation), so parts of the scene may be cut"
        )
        log.warning(msg)
        notes.append(msg)
    events = load_events(npz[0], width, height)
    if events.polarity_note != "-1/+1":
        notes.append(f"{npz[0]}: polarity stored as {events.polarity_note}")
    t0, t_max = float(events.t[0]), events.t_max
    if t0 > 0.1 * t_max:
        msg = (
            f"{npz[0]}: timestamps start at {t0:.6g}, far from 0 (max {t_max:.6g}); view i "
            "of N is placed at i / (N - 1) * max(t), which assumes t starts near 0"
        )
        log.warning(msg)
        notes.append(msg)
    return SplitData(
        name=split_dir.name,
        path=split_dir,
        c2w=c2w,
        intrinsics=K,
        distortion=dist,
        width=width,
        height=height,
        view_names=names,
        events=events,
        rgb_paths=rgb_paths,
    )


def load_dataset(
    root: str | os.PathLike,
    preset: ScenePreset | None = None,
    overrides: dict[str, Any] | None = None,
    splits: str | Iterable[str] | None = None,
) -> EventDataset:
    """Load an EventNeRF-layout dataset.

    Args:
        root: dataset folder, e.g. ``data/real/multimeter``.
        preset: the preset to use; None picks it from ``root`` (``scene.json``, then the
            path, then the ``nerf`` values as group ``custom``).
        overrides: preset fields to replace, e.g. ``{"threshold": 0.2, "width": 640}``.
        splits: split name(s) to load; None loads every split folder found.

    Returns:
        The :class:`EventDataset`.

    Raises:
        DatasetError: the layout or a file is wrong (message names the file).
        ConfigError: an override key is unknown or its value has the wrong type.

    Example:
        >>> ds = load_dataset("data/real/multimeter", splits="train")  # doctest: +SKIP
        >>> ds.splits["train"].events.t.shape  # doctest: +SKIP
    """
    root = Path(root)
    if not root.exists():
        raise DatasetError(f"{root}: dataset folder does not exist")
    if not root.is_dir():
        raise DatasetError(f"{root}: not a folder")
    if preset is None:
        preset, source, stated = resolve_preset_fields(root)
    else:
        source, stated = "given", frozenset(PRESET_FIELDS)
    if overrides:
        preset = apply_overrides(preset, overrides)
        stated = stated | frozenset(overrides)
        source += " + overrides (" + ", ".join(f"{k}={v}" for k, v in overrides.items()) + ")"
    notes: list[str] = []
    if source.startswith("fallback"):
        notes.append(f"{root}: preset {source}")
    found = _find_splits(root)
    if splits is None:
        wanted = list(found)
        if not wanted and any((root / r).is_dir() for r in _REQUIRED):
            raise DatasetError(
                f"{root}: this is a split folder; pass the dataset folder above it "
                f"({root.parent}) and select the split with splits=[{root.name!r}]"
            )
        if not wanted:
            raise DatasetError(
                f"{root}: no split folders (expected e.g. {root / 'train'} holding pose/, "
                "intrinsics/ and events/)"
            )
    else:
        wanted = [splits] if isinstance(splits, str) else list(splits)
        for s in wanted:
            if s not in found:
                have = ", ".join(found) if found else "none"
                raise DatasetError(f"{root / s}: missing split folder (found: {have})")
    preset = resolve_size(preset, stated, source, [found[s] for s in wanted], notes)
    loaded = {s: load_split(found[s], preset.width, preset.height, notes) for s in wanted}
    for sp in loaded.values():
        sp.lens = split_lens(root / "scene.json", sp.intrinsics, sp.distortion, sp.width,
                             sp.height)
    return EventDataset(root=root, preset=preset, preset_source=source, splits=loaded,
                        notes=notes, stated=stated)
