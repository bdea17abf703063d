"""``RUNS/index.html`` of a batch: its summary table, each job linked to its run's report."""

from __future__ import annotations

import datetime
import os
from pathlib import Path
from typing import Any

from hybridneus.fileio import atomic_path
from hybridneus.report import page

FILENAME = "index.html"


def write_index(runs: str | os.PathLike, rows: list[dict[str, Any]],
                columns: tuple[str, ...]) -> Path:
    """Write a batch's index page: one row per job (``columns`` of ``rows``, the summary's),
    the job's name linked to its ``report`` when it has one.

    Returns:
        The path written (``RUNS/index.html``, atomically).
    """
    runs = Path(runs)
    counts: dict[str, int] = {}
    for row in rows:
        counts[row["status"]] = counts.get(row["status"], 0) + 1
    cells = []
    for row in rows:
        line = []
        for key in columns:
            value = row.get(key)
            if key == "job" and row.get("report") and Path(row["report"]).is_file():
                line.append(page.link(os.path.relpath(row["report"], runs), str(value)))
            elif key == "report":
                continue
            else:
                line.append(page.esc(page.fmt(value)))
        cells.append(line)
    stamp = datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M")
    summary = ", ".join(f"{n} {status}" for status, n in sorted(counts.items()))
    body = [f"<h1>Batch {page.esc(runs.resolve().name)}</h1>",
            page.paragraph(f"{len(rows)} jobs: {summary}; written {stamp}. A job's name opens "
                           "its report.", "meta"),
            page.table([c for c in columns if c != "report"], cells, raw=True)]
    path = runs / FILENAME
    with atomic_path(path, suffix=".html") as tmp:
        tmp.write_text(page.document(f"hybridneus batch: {runs.name}", body), encoding="utf-8")
    return path


__all__ = ["FILENAME", "write_index"]
