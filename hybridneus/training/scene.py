"""The scene record of a run: what a fit took from the data and the machine (``scene.yaml``).

The config is an input and is never written to. Everything a fit decides for itself goes
here instead: the scene preset it used (with the values estimated from the events and how),
the eps the loss eases from, the window the training track was smoothed over, the schedule's
length (a ``--minutes`` budget turned into steps before the first step, and re-planned to the
machine's pace during the fit) and the pixels per step of the device. It is printed when the
fit starts, saved beside ``config.yaml``, and read back on ``--resume``, which estimates
nothing again. ``hybridneus fit DATA --iters <steps>`` with the same config repeats a budgeted
run's schedule (exactly where it was never re-planned).
"""

from __future__ import annotations

import dataclasses
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from hybridneus.errors import RunError
from hybridneus.fileio import atomic_path

FILENAME = "scene.yaml"
#: Each pixel's polarity offset, beside the record (``estimate.pixel_offsets``).
PIXEL_OFFSETS = "pixel_offsets.npy"
#: Preset fields a resume applies to the dataset (the rest the dataset states itself).
PRESET_KEYS = ("threshold", "polarity_offset", "max_window", "cyclic", "neg_ratio",
               "tonemap_eps", "crop_r", "crop_y_min", "crop_y_max", "background")


@dataclass
class SceneRecord:
    """See the module docstring.

    Attributes:
        dataset: the dataset folder.
        split: the split trained on.
        preset_source: where the preset came from (a published scene's path, ``scene.json``).
        preset: the scene preset used, as a plain dict (after overrides and estimates).
        estimated: preset field -> one line on how the fit estimated it; fields not named
            here came from the dataset, its preset or the config.
        eps_start: the tonemap eps the loss eases from (``estimate.eps_ease``), or ``None``.
        steps: the schedule's length.
        steps_from: how ``steps`` was chosen (``train.iters``, or the budget and the speed).
        replans: how many times a budgeted fit re-planned its length to the pace of its
            steps (:class:`~hybridneus.training.budget.BudgetPlan`).
        paces: the slowest and fastest pace its re-plans measured, as multiples of the
            probe's time, or ``None``.
        n_rays: pixels per step.
        device: the device trained on.
        stopped_at: the step a budgeted fit stopped at because its deadline came before the
            schedule's end (the schedule still counts ``steps``); ``None``: it ran them all.
        pose_window: the views the training track was smoothed over where the fit chose
            them from the track (``refine.pose_smoothing=-1``; 0: too short to smooth),
            else ``None``.
        version: the hybridneus version that wrote the record.
        hot_pixels: the ``[x, y]`` pixels whose events the fit left out
            (``estimate.hot_pixels``); a resumed fit leaves out the same.
        pixel_offsets: the file in the run folder (:data:`PIXEL_OFFSETS`) holding each
            pixel's polarity offset (``estimate.pixel_offsets``), or ``None``; a resumed fit
            takes the same.
    """

    dataset: str
    split: str
    preset_source: str
    preset: dict[str, Any]
    estimated: dict[str, str] = field(default_factory=dict)
    eps_start: float | None = None
    steps: int = 1
    steps_from: str = "train.iters"
    n_rays: int = 256
    device: str = "cpu"
    version: str = ""
    stopped_at: int | None = None
    pose_window: int | None = None
    replans: int = 0
    paces: list[float] | None = None
    hot_pixels: list[list[int]] = field(default_factory=list)
    pixel_offsets: str | None = None

    def preset_overrides(self) -> dict[str, Any]:
        """The preset values to give the dataset reader so that it uses this record's."""
        out = {}
        for key in PRESET_KEYS:
            value = self.preset[key]
            out[key] = tuple(value) if isinstance(value, list) else value
        return out

    def lines(self) -> list[str]:
        """What the record says, one line per topic (printed when a fit starts)."""
        p = self.preset
        out = [f"scene: {self.dataset} ({self.split}), preset from the {self.preset_source}"]
        for key in ("threshold", "polarity_offset", "tonemap_eps"):
            out.append(f"  {key} {p[key]:g}" + _how(self.estimated.get(key)))
        crop = f"  crop r {p['crop_r']:g}, y {p['crop_y_min']:g} .. {p['crop_y_max']:g}"
        out.append(crop + _how(self.estimated.get("crop_r")))
        out.append(f"  {self.steps} steps ({self.steps_from}), {self.n_rays} pixels per step "
                   f"on {self.device}")
        if self.replans:
            lo, hi = self.paces or (1.0, 1.0)
            out.append(f"  re-planned {self.replans} times to the pace of its steps ({lo:.2f}x "
                       f"to {hi:.2f}x the probe's time)")
        if self.pose_window is not None:
            out.append(f"  training poses smoothed over {self.pose_window} views (chosen from "
                       "the track)" if self.pose_window else
                       "  training poses as given (the track is too short to smooth)")
        if self.hot_pixels:
            out.append(f"  {len(self.hot_pixels)} hot pixels left out")
        if self.pixel_offsets:
            out.append("  each pixel's own polarity offset, from its balance "
                       f"({self.pixel_offsets})")
        if self.stopped_at is not None:
            out.append(f"  stopped at step {self.stopped_at}: the time budget ran out")
        return out

    def save(self, path: str | os.PathLike) -> None:
        """Write the record as YAML (atomically)."""
        with atomic_path(path) as tmp:
            tmp.write_text(yaml.safe_dump(dataclasses.asdict(self), sort_keys=False))

    @classmethod
    def load(cls, path: str | os.PathLike) -> SceneRecord:
        """Read a record written by :meth:`save`.

        Raises:
            RunError: the file is missing, unreadable or not a scene record.
        """
        path = Path(path)
        if not path.is_file():
            raise RunError(f"{path}: missing (runs of hybridneus 0.1 have none and cannot be "
                           "resumed; mesh them, or fit again)")
        try:
            data = yaml.safe_load(path.read_text())
        except (OSError, yaml.YAMLError) as exc:
            first = (str(exc).splitlines() or [type(exc).__name__])[0]
            raise RunError(f"{path}: cannot read the scene record ({first})") from None
        names = {f.name for f in dataclasses.fields(cls)}
        if not isinstance(data, dict) or "dataset" not in data:
            raise RunError(f"{path}: not a scene record")
        required = {"split", "preset_source", "preset", "steps"}
        if not required <= set(data) or not isinstance(data["preset"], dict):
            raise RunError(f"{path}: incomplete scene record (missing "
                           f"{sorted(required - set(data)) or 'preset'})")
        unknown = set(data) - names
        if unknown:
            raise RunError(f"{path}: unknown keys {sorted(unknown)}")
        record = cls(**data)
        missing = [k for k in PRESET_KEYS if k not in record.preset]
        if missing or not isinstance(record.steps, int) or record.steps < 1:
            raise RunError(f"{path}: incomplete scene record (missing {missing or 'steps'})")
        _check_pixels(path, record)
        return record


def save_pixel_offsets(run_dir: str | os.PathLike, offsets: np.ndarray) -> str:
    """Write each pixel's polarity offset into ``run_dir`` (atomically); return the file's
    name, as :attr:`SceneRecord.pixel_offsets` records it."""
    with atomic_path(Path(run_dir) / PIXEL_OFFSETS) as tmp, open(tmp, "wb") as f:
        np.save(f, np.asarray(offsets, np.float32), allow_pickle=False)
    return PIXEL_OFFSETS


def load_pixel_offsets(run_dir: str | os.PathLike, record: SceneRecord, size: int) -> np.ndarray:
    """The offsets :func:`save_pixel_offsets` wrote for ``record``, checked against an image
    of ``size`` pixels.

    Raises:
        RunError: the file is missing, unreadable, or not ``size`` offsets in (-1, 1).
    """
    path = Path(run_dir) / str(record.pixel_offsets)
    try:
        offsets = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise RunError(f"{path}: cannot read the pixels' polarity offsets ({first})") from None
    if (offsets.shape != (size,) or offsets.dtype.kind != "f"
            or not np.all(np.abs(offsets) < 1.0)):
        raise RunError(f"{path}: not {size} polarity offsets in (-1, 1) (shape "
                       f"{offsets.shape}, {offsets.dtype})")
    return offsets.astype(np.float32)


def _check_pixels(path: Path, record: SceneRecord) -> None:
    """``hot_pixels`` must be ``[x, y]`` pairs inside the image (a resume masks them)."""
    w, h = record.preset.get("width"), record.preset.get("height")
    for xy in record.hot_pixels if isinstance(record.hot_pixels, list) else [None]:
        pair = isinstance(xy, list) and len(xy) == 2 and all(
            isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in xy)
        if not pair or (isinstance(w, int) and xy[0] >= w) or (isinstance(h, int) and xy[1] >= h):
            raise RunError(f"{path}: hot_pixels holds {xy!r}, not an [x, y] pixel of the "
                           f"{w}x{h} image")


def _how(line: str | None) -> str:
    return f"  (estimated: {line})" if line else ""
