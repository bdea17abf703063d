"""What a run report shows, read from a run folder: nothing here renders or trains.

A run folder (docs/training.md) holds ``config.yaml``, ``scene.yaml``, ``metrics.csv`` and
``previews/``; ``hybridneus mesh`` adds ``mesh_<res>.<fmt>`` and ``hybridneus eval`` of a mesh
in the folder adds ``eval.json``. Each part the report shows is optional but the config: a
report of a fit stopped at its first step shows what there is.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from hybridneus.errors import RunError

#: Step previews shown at most (spread over the fit, the last always among them).
MAX_PREVIEWS = 6
#: Mesh files the report looks for in a run folder, newest first.
MESH_SUFFIXES = (".ply", ".obj", ".glb", ".off", ".stl")
#: The record of ``hybridneus eval`` of a mesh inside a run folder.
SCORES = "eval.json"


@dataclass
class RunContent:
    """The parts of one run folder a report shows.

    Attributes:
        run: the run folder.
        metrics: ``metrics.csv`` by column (``step`` first), missing cells as NaN.
        scene: ``scene.yaml`` (what the fit estimated and decided), or empty.
        preset: the config's preset name.
        changes: ``(key, preset value, run value)`` for every key the run's config changes
            from its preset.
        previews: step previews (``previews/step_<n>.png``), in step order.
        views: the windows rendered at the fit's end (``previews/view_<i>.png``).
        pictures: other pictures of the run (``previews/poses.png``), by title.
        mesh: the mesh to show, or None.
        scores: ``eval.json`` (Chamfer, F-score ...), or None.
        errors: the error picture ``eval --errors`` wrote, or None.
    """

    run: Path
    metrics: dict[str, list[float]] = field(default_factory=dict)
    scene: dict[str, Any] = field(default_factory=dict)
    preset: str = ""
    changes: list[tuple[str, Any, Any]] = field(default_factory=list)
    previews: list[Path] = field(default_factory=list)
    views: list[Path] = field(default_factory=list)
    pictures: dict[str, Path] = field(default_factory=dict)
    mesh: Path | None = None
    scores: dict[str, Any] | None = None
    errors: Path | None = None


def read_run(run: str | os.PathLike, mesh: str | os.PathLike | None = None,
             scores: str | os.PathLike | None = None) -> RunContent:
    """Read what the report of ``run`` shows.

    Args:
        run: a run folder.
        mesh: the mesh to show (default: the newest ``mesh*`` file in the run folder).
        scores: an ``eval --json`` record (default: the run folder's ``eval.json``).

    Raises:
        RunError: ``run`` is not a run folder, or a file given is missing or unreadable.
    """
    run = Path(run)
    if not (run / "config.yaml").is_file():
        raise RunError(f"{run}: not a run folder (no config.yaml)")
    content = RunContent(run=run)
    content.preset, content.changes = config_changes(run / "config.yaml")
    content.metrics = read_metrics(run / "metrics.csv")
    if (run / "scene.yaml").is_file():
        content.scene = _yaml(run / "scene.yaml")
    steps = sorted((run / "previews").glob("step_*.png"))
    content.previews = spread(steps, MAX_PREVIEWS)
    content.views = sorted((run / "previews").glob("view_*.png"))
    if (run / "previews" / "poses.png").is_file():
        content.pictures["How far smoothing moved each view"] = run / "previews" / "poses.png"
    content.mesh = Path(mesh) if mesh is not None else newest_mesh(run)
    if content.mesh is not None and not content.mesh.is_file():
        raise RunError(f"{content.mesh}: no such mesh file")
    path = Path(scores) if scores is not None else run / SCORES
    if scores is not None or path.is_file():
        content.scores = read_scores(path)
        picture = content.scores.get("errors")
        if picture:
            picture = Path(picture)
            if not picture.is_absolute() and not picture.is_file():
                picture = path.parent / picture
            content.errors = picture if picture.is_file() else None
    return content


def read_metrics(path: Path) -> dict[str, list[float]]:
    """``metrics.csv`` as ``{column: values}``; empty when the file is missing or empty."""
    if not path.is_file():
        return {}
    rows = list(csv.DictReader(io.StringIO(metrics_text(path))))
    if not rows:
        return {}
    # a row cut or run together by a killed write has too few cells (None) or too many
    # (a list under the key None): its cells read as missing
    columns: dict[str, list[float]] = {k: [] for k in rows[0] if k is not None}
    for row in rows:
        for key in columns:
            columns[key].append(_number(row.get(key)))
    return columns


def metrics_text(path: Path) -> str:
    """``metrics.csv``'s text, without what a crash can leave in it: NUL bytes (a file
    system that grew the file before the power went) and bytes that are not UTF-8."""
    return path.read_bytes().decode("utf-8", errors="replace").replace("\x00", "")


def config_changes(path: Path) -> tuple[str, list[tuple[str, Any, Any]]]:
    """The preset a run's config names and each ``(key, preset value, run value)`` that
    differs, keys dotted (``train.lr``)."""
    from hybridneus.config import load_config, preset_config
    from hybridneus.errors import ConfigError

    try:
        cfg = load_config(path, saved_run=True)
    except ConfigError as exc:
        raise RunError(str(exc)) from None
    name = str(getattr(cfg, "preset", "") or "fast")
    try:
        base = preset_config(name).to_dict()
    except ConfigError:
        return name, []
    ours = cfg.to_dict()
    changes = [(k, v, ours_v) for k, (v, ours_v) in _paired(_flat(base), _flat(ours)).items()
               if v != ours_v and k != "preset"]
    return name, changes


def newest_mesh(run: Path) -> Path | None:
    """The newest mesh file ``hybridneus mesh`` wrote into ``run``, or None."""
    found = [p for p in run.glob("mesh*") if p.suffix.lower() in MESH_SUFFIXES and p.is_file()]
    return max(found, key=lambda p: p.stat().st_mtime) if found else None


def read_scores(path: Path) -> dict[str, Any]:
    """An ``eval --json`` record."""
    try:
        scores = json.loads(path.read_text())
    except FileNotFoundError:
        raise RunError(f"{path}: no such scores file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise RunError(f"{path}: cannot read scores ({exc})") from None
    if not isinstance(scores, dict) or "chamfer" not in scores:
        raise RunError(f"{path}: not a record of hybridneus eval (no chamfer)")
    return scores


def spread(items: list[Path], n: int) -> list[Path]:
    """At most ``n`` of ``items`` evenly spread, the first and the last among them."""
    if len(items) <= n:
        return list(items)
    picks = sorted({round(i * (len(items) - 1) / (n - 1)) for i in range(n)})
    return [items[i] for i in picks]


def _yaml(path: Path) -> dict[str, Any]:
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise RunError(f"{path}: cannot read ({type(exc).__name__})") from None
    return data if isinstance(data, dict) else {}


def _number(text: str | None) -> float:
    if not isinstance(text, str) or not text:
        return math.nan
    try:
        return float(text)
    except ValueError:
        return math.nan


def _flat(tree: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            out |= _flat(value, name + ".")
        else:
            out[name] = value
    return out


def _paired(a: dict[str, Any], b: dict[str, Any]) -> dict[str, tuple[Any, Any]]:
    return {k: (a.get(k), b.get(k)) for k in sorted(set(a) | set(b))}


__all__ = ["MAX_PREVIEWS", "SCORES", "RunContent", "config_changes", "metrics_text",
           "newest_mesh", "read_metrics", "read_run", "read_scores", "spread"]
