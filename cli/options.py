"""Options several commands share: ``--set key=value`` on the one config tree."""

from __future__ import annotations

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
