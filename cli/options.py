"""What several commands share: ``--set key=value`` on the one config tree, and the
library's log lines on stderr."""

from __future__ import annotations

import logging
import sys
from typing import Annotated

import typer

SetOption = Annotated[
    list[str] | None,
    typer.Option(
        "--set",
        help="Override a config key, e.g. --set data.threshold=0.2 --set train.lr=0.005 "
        "(repeatable; every key is in docs/training.md).",
        show_default=False,
    ),
]


def config_with(preset: str, sets: list[str] | None):
    """The preset's :class:`~hybridneus.config.Config` with the ``--set`` overrides, checked.

    Raises:
        ConfigError: unknown preset or key, wrong type or range.
    """
    from hybridneus.config import apply_overrides, preset_config, validate

    return validate(apply_overrides(preset_config(preset), sets or []))


class StderrLines(logging.Handler):
    """Each record as one plain line on whatever ``sys.stderr`` is when it is emitted."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            sys.stderr.write(self.format(record) + "\n")
        except Exception:  # noqa: BLE001 - logging must never raise into the caller
            self.handleError(record)


def log_to_stderr(level: int = logging.INFO) -> None:
    """Show the ``hybridneus`` logger's records from ``level`` up as plain lines on stderr
    (once, however often a command runs in one process)."""
    logger = logging.getLogger("hybridneus")
    if not any(isinstance(h, StderrLines) for h in logger.handlers):
        logger.addHandler(StderrLines())
    logger.setLevel(level)
