"""``hybridneus report``: a run folder as one self-contained web page."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def report(
    run: Annotated[Path, typer.Argument(help="Run folder (a runs root uses its latest run).")]
    = Path("runs"),
    mesh: Annotated[
        Path | None,
        typer.Option(help="Mesh to show (default: the newest mesh* file in RUN).",
                     show_default=False),
    ] = None,
    scores: Annotated[
        Path | None,
        typer.Option("--eval", help="Scores of `hybridneus eval --json` (default: RUN/eval.json, "
                     "which eval writes for a mesh in a run folder).", show_default=False),
    ] = None,
    out: Annotated[Path | None, typer.Option(help="Output file (default RUN/report.html).",
                                             show_default=False)] = None,
    open_: Annotated[bool, typer.Option("--open", help="Open it in the web browser.")] = False,
) -> None:
    """Write RUN/report.html: training curves, what the fit estimated, the config changed from
    its preset, event windows beside renders, step previews, the mesh in a 3D viewer and the
    scores against a ground truth. One file; it opens from disk with no network."""
    import time
    import webbrowser

    from hybridneus.report import write_report
    from hybridneus.training.runs import resolve_run

    if not run.exists():
        from hybridneus.errors import RunError

        raise RunError(f"{run}: run folder does not exist")
    run = resolve_run(run)
    tick = time.perf_counter()
    path = write_report(run, mesh=mesh, scores=scores, out=out)
    size = path.stat().st_size / 2**20
    typer.echo(f"report: {path} ({size:.1f} MB, {time.perf_counter() - tick:.1f} s)")
    if open_:
        webbrowser.open(path.resolve().as_uri())
