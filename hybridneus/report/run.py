"""``RUN/report.html``: one run folder as a page, from what the folder holds."""

from __future__ import annotations

import datetime
import math
import os
from pathlib import Path
from typing import Any

from hybridneus.fileio import atomic_path
from hybridneus.report import page
from hybridneus.report.content import RunContent, read_run

FILENAME = "report.html"

# (label, scene.yaml key) of what the fit took from the data and decided, in that order.
_RECORD = (
    ("dataset", "dataset"), ("split", "split"), ("preset source", "preset_source"),
    ("estimated (how)", "estimated"), ("loss eps eased from", "eps_start"),
    ("steps", "steps"), ("steps from", "steps_from"), ("budget re-plans", "replans"),
    ("stopped at step", "stopped_at"), ("pose window", "pose_window"),
    ("rays per step", "n_rays"), ("device", "device"), ("hybridneus", "version"),
)
# (label, scene.yaml preset key) of the scene values the fit trained with.
_PRESET = (
    ("contrast threshold C", "threshold"), ("polarity offset", "polarity_offset"),
    ("tone-map eps", "tonemap_eps"), ("crop radius", "crop_r"), ("crop y min", "crop_y_min"),
    ("crop y max", "crop_y_max"), ("background", "background"), ("mosaic", "mosaic"),
    ("window (views)", "max_window"), ("size", None),
)
# (label, eval.json key) of the scores shown.
_SCORES = (
    ("Chamfer distance", "chamfer"), ("floor (GT against itself)", "floor"),
    ("accuracy (mesh to GT)", "accuracy"), ("completeness (GT to mesh)", "completeness"),
    ("F-score", "fscore"), ("precision", "precision"), ("recall", "recall"),
    ("F-score distance", "threshold"), ("SDF-MAE", "sdf_mae"), ("protocol", "protocol"),
    ("ground truth", "gt"), ("mesh", "mesh"),
)


def write_report(run: str | os.PathLike, mesh: str | os.PathLike | None = None,
                 scores: str | os.PathLike | None = None,
                 out: str | os.PathLike | None = None) -> Path:
    """Write the report of a run folder, one self-contained HTML file.

    Args:
        run: the run folder.
        mesh: the mesh to show (default: the newest ``mesh*`` file in the run folder).
        scores: an ``eval --json`` record (default: the run folder's ``eval.json``).
        out: the file (default ``RUN/report.html``); written atomically.

    Returns:
        The path written.

    Raises:
        RunError: not a run folder, or a named file missing or unreadable.
    """
    content = read_run(run, mesh, scores)
    path = Path(out) if out is not None else content.run / FILENAME
    text = render(content)
    with atomic_path(path, suffix=".html") as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path


def render(content: RunContent) -> str:
    """The report's HTML."""
    from plotly.offline import get_plotlyjs

    from hybridneus.report.figures import curves_figure, mesh_figure

    scene = content.scene
    logged = [s for s in content.metrics.get("step", []) if math.isfinite(s)] or [0]
    stamp = datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M")
    planned = scene.get("steps", "?")
    done = f"stopped at step {scene['stopped_at']} of {planned}" if scene.get("stopped_at") \
        else f"{planned} steps"
    body = [f"<h1>{page.esc(content.run.name)}</h1>",
            page.paragraph(f"preset {content.preset}, {done}, logged to step "
                           f"{int(max(logged))}; report written {stamp}", "meta")]
    if content.scores is not None:
        parts = [page.table(["metric", "value"], _score_rows(content.scores))]
        if content.errors is not None:
            parts.append(page.picture(content.errors, "above: the ground truth coloured by "
                                      "its distance to the mesh; below: the mesh by its "
                                      "distance to the ground truth"))
        body.append(page.section("Scores against the ground truth", "scores", parts))
    if content.mesh is not None:
        fig, shown, total = mesh_figure(content.mesh)
        note = f"{content.mesh.name}: {total:,} faces"
        if shown < total:
            note += f", shown decimated to {shown:,}"
        body.append(page.section("Mesh", "mesh", [
            page.paragraph(note + "; drag to turn, scroll to zoom.", "note"),
            page.plot(fig, "mesh-view")]))
    fig = curves_figure(content.metrics)
    body.append(page.section("Training curves", "curves-section", [
        page.plot(fig, "curves") if fig is not None else
        page.paragraph("metrics.csv holds no rows yet.", "note")]))
    parts = [page.table(["", "value"], _record_rows(scene))]
    if scene:
        parts.append(page.details("scene.yaml", page.yaml_text(scene)))
    body.append(page.section("What the fit took from the data", "scene", parts))
    body.append(page.section(
        f"Config: changed from the preset {content.preset}", "config",
        [page.table(["key", "preset", "this run"], content.changes) if content.changes
         else page.paragraph("The preset as it is.", "note")]))
    if content.views:
        body.append(page.section("Events and renders at the fit's end", "views", [
            page.paragraph("Each: the rendered log-brightness change over an event window, the "
                           "recorded C * E of the same window, the colour and the normals of "
                           "the view at the window's end.", "note"),
            *(page.picture(p, p.stem.replace("_", " "), 2.0) for p in content.views)]))
    if content.previews:
        body.append(page.section("Step previews", "previews", [
            page.picture(p, f"step {int(p.stem.split('_')[-1])}", 2.0)
            for p in content.previews]))
    for title, path in content.pictures.items():
        body.append(page.section(title, path.stem, [page.picture(path)]))
    return page.document(f"hybridneus report: {content.run.name}", body, get_plotlyjs())


def _record_rows(scene: dict[str, Any]) -> list[tuple[str, Any]]:
    preset = scene.get("preset") or {}
    rows = [(label, preset.get(key)) for label, key in _PRESET if key and key in preset]
    if "width" in preset:
        rows.append(("size", f"{preset['width']} x {preset['height']}"))
    rows += [(label, scene.get(key)) for label, key in _RECORD if key in scene]
    hot = scene.get("hot_pixels")
    if hot:
        rows.append(("hot pixels masked", len(hot)))
    return rows


def _score_rows(scores: dict[str, Any]) -> list[tuple[str, Any]]:
    return [(label, scores[key]) for label, key in _SCORES if key in scores]


__all__ = ["FILENAME", "render", "write_report"]
