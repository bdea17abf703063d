"""One look for every progress bar: description, bar, count, rate, elapsed, ETA, info."""

from __future__ import annotations

import sys

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    Task,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.text import Text


class _RateColumn(ProgressColumn):
    """Completed units per second, e.g. ``12.3 it/s``."""

    def __init__(self, unit: str) -> None:
        super().__init__()
        self.unit = unit

    def render(self, task: Task) -> Text:
        speed = task.finished_speed or task.speed
        if speed is None:
            return Text(f"? {self.unit}/s", style="progress.data.speed")
        return Text(f"{speed:.3g} {self.unit}/s", style="progress.data.speed")


class _InfoColumn(ProgressColumn):
    """Free text set with ``progress.update(task, info=...)`` (loss values, counts)."""

    def render(self, task: Task) -> Text:
        return Text(str(task.fields.get("info", "")))


def make_progress(unit: str = "it", transient: bool = False, disable: bool = False) -> Progress:
    """Return a :class:`rich.progress.Progress` with rate (``unit``/s), elapsed and ETA.

    Progress goes to stderr so that ``--json`` output on stdout stays machine-readable.
    Put per-step numbers in the ``info`` field: ``progress.update(task, info="loss 0.1")``.
    """
    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        _RateColumn(unit),
        TimeElapsedColumn(),
        TextColumn("eta"),
        TimeRemainingColumn(),
        _InfoColumn(),
        console=Console(file=sys.stderr),
        transient=transient,
        disable=disable,
    )
