"""Run folders: naming, checkpoints, the ``latest`` pointer, and loading a trained field.

A run folder ``runs/<scene>-<YYYYmmdd-HHMMSS>`` holds ``config.yaml`` (the configuration it
was given), ``scene.yaml`` (what the fit estimated and measured:
:mod:`hybridneus.training.scene`), ``checkpoints/last.pt``, ``metrics.csv``, ``previews/``
and, when TensorBoard is installed, ``tb/``. ``runs/latest`` is a one-line text file naming
the newest run folder.
Checkpoints are written atomically and hold only tensors and primitive containers, so they
load with ``torch.load(..., weights_only=True)``.
"""

from __future__ import annotations

import logging
import os
import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from hybridneus.config import Config, load_config
from hybridneus.errors import ConfigError, RunError
from hybridneus.fileio import atomic_path, creation_fault

if TYPE_CHECKING:
    from hybridneus.model.field import HybridField

CHECKPOINT = Path("checkpoints") / "last.pt"
#: The checkpoint before the last one: read when the last is missing or unreadable.
PREVIOUS = Path("checkpoints") / "previous.pt"
LATEST = "latest"


def check_runs_root(runs_root: str | os.PathLike) -> None:
    """Fail early, before any data is loaded, when ``runs_root`` cannot hold run folders.

    Raises:
        RunError: it is a file, or cannot be created.
    """
    root = Path(runs_root)
    if root.exists() and not root.is_dir():
        raise RunError(f"{root}: not a folder (--out must name a folder for the runs)")
    # nothing is created yet: a fit that fails on its data leaves no empty folder behind
    fault = creation_fault(root.absolute())
    if fault is not None:
        raise RunError(f"{root}: cannot create the runs folder ({fault})")


def new_run_dir(runs_root: str | os.PathLike, scene: str) -> Path:
    """Create and return a fresh ``<runs_root>/<scene>-<timestamp>`` folder."""
    root = Path(runs_root)
    root.mkdir(parents=True, exist_ok=True)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    safe = "".join(c if c.isalnum() or c in "-_." else "_" for c in scene) or "run"
    run = root / f"{safe}-{stamp}"
    suffix = 1
    while run.exists():
        suffix += 1
        run = root / f"{safe}-{stamp}-{suffix}"
    run.mkdir()
    return run


def set_latest(runs_root: str | os.PathLike, run_dir: str | os.PathLike) -> None:
    """Point ``<runs_root>/latest`` at ``run_dir`` (a text file with the folder name)."""
    root = Path(runs_root)
    for stale in root.glob(f".{LATEST}.*.tmp"):  # a pointer write that was killed
        stale.unlink(missing_ok=True)
    with atomic_path(root / LATEST, suffix="") as tmp:
        tmp.write_text(Path(run_dir).name + "\n")


def latest_run(runs_root: str | os.PathLike = "runs") -> Path:
    """The run folder named by ``<runs_root>/latest``, else the newest one with a checkpoint.

    Raises:
        RunError: no run folder with a checkpoint exists under ``runs_root``.
    """
    root = Path(runs_root)
    pointer = root / LATEST
    if pointer.is_file():
        name = pointer.read_text().strip()
        candidate = root / name
        if name and (candidate / CHECKPOINT).is_file():
            return candidate
    runs = [p for p in root.glob("*") if (p / CHECKPOINT).is_file()] if root.is_dir() else []
    if not runs:
        raise RunError(f"{root}: no run with a checkpoint found; train one with `hybridneus fit`")
    return max(runs, key=lambda p: (p / CHECKPOINT).stat().st_mtime)


def save_checkpoint(run_dir: str | os.PathLike, state: dict[str, Any]) -> Path:
    """Write ``state`` to ``<run_dir>/checkpoints/last.pt`` atomically, keeping the one
    before as ``previous.pt``; return the path.

    At every moment of a save ``last.pt`` is a complete checkpoint (the old one until the new
    one replaces it in one rename); what a killed save leaves (``.*.tmp.pt``) is removed by
    the next save or resume.
    """
    run_dir = Path(run_dir)
    path = run_dir / CHECKPOINT
    remove_stale_temporaries(run_dir)
    with atomic_path(path) as tmp:
        torch.save(state, tmp)
        if path.is_file():  # last.pt stays in place until the new one replaces it
            with atomic_path(run_dir / PREVIOUS) as keep:
                keep.unlink()
                try:
                    os.link(path, keep)
                except OSError:  # a file system without hard links
                    shutil.copyfile(path, keep)
    return path


#: Where a run writes files atomically (``fileio.atomic_path`` names its temporaries
#: ``.<stem>.<random>.tmp<suffix>``): the folder itself (config, scene record, metrics),
#: its checkpoints and its previews.
_ATOMIC_FOLDERS = (Path("."), CHECKPOINT.parent, Path("previews"))


def remove_stale_temporaries(run_dir: str | os.PathLike) -> list[Path]:
    """Delete what killed writes left in a run folder (``.*.tmp*`` beside the checkpoints,
    the metrics, the scene record and the previews)."""
    stale: list[Path] = []
    for sub in _ATOMIC_FOLDERS:
        folder = Path(run_dir) / sub
        if folder.is_dir():
            stale += sorted(p for p in folder.glob(".*.tmp*") if p.is_file())
    for p in stale:
        p.unlink(missing_ok=True)
    return stale


def load_checkpoint(run_dir: str | os.PathLike, map_location: Any = "cpu") -> dict[str, Any]:
    """Read ``<run_dir>/checkpoints/last.pt`` with ``weights_only=True``, or, when it is
    missing or unreadable (a kill between the two renames of a save, a damaged disk),
    ``previous.pt`` with a warning.

    Raises:
        RunError: the folder is missing, or no checkpoint in it is readable.
    """
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise RunError(f"{run_dir}: run folder does not exist")
    try:
        return _read_checkpoint(run_dir / CHECKPOINT, map_location)
    except RunError as exc:
        if not (run_dir / PREVIOUS).is_file():
            raise
        state = _read_checkpoint(run_dir / PREVIOUS, map_location)
        logging.getLogger("hybridneus").warning("%s; using %s (step %s)", exc,
                                                run_dir / PREVIOUS, state.get("step"))
        return state


def _read_checkpoint(path: Path, map_location: Any) -> dict[str, Any]:
    if not path.is_file():
        raise RunError(f"{path}: checkpoint missing (the run was never saved)")
    try:
        state = torch.load(path, map_location=map_location, weights_only=True)
    except Exception as exc:  # torch raises many types for corrupt files
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise RunError(f"{path}: cannot read checkpoint ({first})") from None
    if not isinstance(state, dict) or "model" not in state:
        raise RunError(f"{path}: not a hybridneus checkpoint")
    missing = [k for k in ("scene", "step", "total_steps") if k not in state]
    if missing or not isinstance(state["scene"], dict):
        what = ", ".join(missing) if missing else "scene (not a mapping)"
        raise RunError(f"{path}: checkpoint lacks {what} (written by another tool, or "
                       "damaged)")
    knots = state.get("knots")
    if knots is not None and not _knots_ok(knots):
        raise RunError(f"{path}: checkpoint's schedule knots are not (step, progress) pairs "
                       "starting at (0, 0) (written by another tool, or damaged)")
    return state


def _knots_ok(knots: Any) -> bool:
    try:
        pairs = [(int(k), float(q)) for k, q in knots]
    except (TypeError, ValueError):
        return False
    return bool(pairs) and pairs[0] == (0, 0.0) and all(
        a[0] < b[0] and 0.0 <= b[1] <= 1.0 for a, b in zip(pairs, pairs[1:], strict=False))


def load_run_config(run_dir: str | os.PathLike) -> Config:
    """The resolved :class:`Config` saved in ``<run_dir>/config.yaml``; keys added since
    the run was saved whose default has moved take the value it was trained with
    (:data:`hybridneus.config.overrides.RUN_KEY_ORIGINS`).

    Raises:
        RunError: the file is missing. ConfigError: it does not parse.
    """
    path = Path(run_dir) / "config.yaml"
    if not path.is_file():
        raise RunError(f"{path}: config missing")
    return load_config(path, saved_run=True)


def build_field(cfg: Config, scene: dict[str, Any]):
    """A fresh field for ``cfg`` and the scene values saved in a checkpoint."""
    from hybridneus.model.field import HybridField

    return HybridField(
        cfg.grid,
        cfg.field,
        background=tuple(scene["background"]),
        crop=tuple(scene["crop"]),
        grey=bool(scene.get("grey", False)),
    )


def resolve_run(run_dir: str | os.PathLike) -> Path:
    """``run_dir`` itself, or the latest run when it is a runs root with a ``latest`` file
    (what every command that reads a run takes as RUN)."""
    run_dir = Path(run_dir)
    if not (run_dir / CHECKPOINT).is_file() and (run_dir / LATEST).is_file():
        return latest_run(run_dir)
    return run_dir


def load_field(
    run_dir: str | os.PathLike, device: str = "auto", checkpoint: dict[str, Any] | None = None
) -> HybridField:
    """Load the trained field of a run folder, in eval mode, on ``device``.

    Args:
        run_dir: a run folder (or a runs root holding a ``latest`` pointer).
        device: ``auto``, ``cpu``, ``cuda`` or ``cuda:N``.
        checkpoint: the run's checkpoint already read by :func:`load_checkpoint` (it is
            tens of MB: read it once when the cameras are wanted too); ``None`` reads it.

    Returns:
        The :class:`~hybridneus.model.field.HybridField` (implements ``Field``).

    Raises:
        RunError: missing or unreadable run folder / checkpoint.
    """
    from hybridneus.device import resolve_device
    from hybridneus.training.state import position

    run_dir = resolve_run(run_dir)
    dev = resolve_device(device)
    state = load_checkpoint(run_dir) if checkpoint is None else checkpoint
    try:
        cfg = load_run_config(run_dir)
    except ConfigError as exc:
        raise RunError(str(exc)) from None
    field = build_field(cfg, state["scene"])
    try:
        field.load_state_dict(state["model"])
    except RuntimeError as exc:
        first = str(exc).splitlines()[0]
        raise RunError(f"{run_dir / CHECKPOINT}: does not match config.yaml ({first})") from None
    field.update_step(position(state), int(state["total_steps"]))
    return field.to(dev).eval()


def load_cameras(
    run_dir: str | os.PathLike, checkpoint: dict[str, Any] | None = None
) -> np.ndarray | None:
    """Centres (n_views, 3) of the cameras a run was trained from, or ``None``.

    Runs save them in their checkpoint; for older runs they are read from the poses of the
    dataset that ``config.yaml`` names, when that folder is still there. ``checkpoint``: the
    run's checkpoint already read by :func:`load_checkpoint` (``None`` reads it).

    Raises:
        RunError: missing or unreadable run folder / checkpoint, or non-finite saved centres.
    """
    from hybridneus.data.dataset import read_camera_centres
    from hybridneus.errors import DatasetError

    run_dir = resolve_run(run_dir)
    state = load_checkpoint(run_dir) if checkpoint is None else checkpoint
    saved = state.get("scene", {}).get("cameras")
    if saved:
        centres = np.asarray(saved, dtype=np.float64).reshape(-1, 3)
        if not np.isfinite(centres).all():
            raise RunError(f"{run_dir / CHECKPOINT}: camera centres hold NaN or inf")
        return centres
    try:
        cfg = load_run_config(run_dir)
        return read_camera_centres(Path(cfg.data.path) / cfg.data.split)
    except (RunError, DatasetError, TypeError):
        return None
