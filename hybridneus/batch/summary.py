"""A batch's summary: one row per job, as ``RUNS/summary.csv`` and ``RUNS/summary.md``."""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

from hybridneus.fileio import atomic_path

COLUMNS = ("job", "status", "steps", "wall_s", "chamfer", "fscore", "mesh", "report", "error")


def rows(ids: list[str], jobs: dict[str, dict[str, Any]]) -> list[dict[str, Any]]:
    """The summary's rows for ``ids``, from the batch state's records."""
    out = []
    for i in ids:
        r = jobs[i]
        out.append({"job": i, "status": r["status"], "steps": r.get("steps"),
                    "wall_s": r.get("wall_s"), "chamfer": r.get("chamfer"),
                    "fscore": r.get("fscore"), "mesh": r.get("mesh"),
                    "report": r.get("report"), "error": r.get("error")})
    return out


def cell(value: Any) -> str:
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.5g}"
    return str(value).replace("|", "/")


def write_summary(runs: Path, table: list[dict[str, Any]]) -> tuple[Path, Path]:
    """Write ``summary.csv`` and ``summary.md`` in ``runs``; return their paths."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS)
    writer.writeheader()
    for row in table:
        writer.writerow({k: "" if row[k] is None else row[k] for k in COLUMNS})
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(cell(row[k]) for k in COLUMNS) + " |" for row in table]
    paths = runs / "summary.csv", runs / "summary.md"
    for path, text in zip(paths, (buf.getvalue(), "\n".join(lines) + "\n"), strict=True):
        with atomic_path(path) as tmp:
            tmp.write_text(text)
    return paths


__all__ = ["COLUMNS", "cell", "rows", "write_summary"]
