"""Coarse-to-fine schedule for the number of active grid levels."""

from __future__ import annotations

from dataclasses import dataclass

from hybridneus.errors import ConfigError

__all__ = ["LevelSchedule"]


@dataclass(frozen=True)
class LevelSchedule:
    """Open ``levels_per_step`` more levels every ``interval`` steps, from ``start_levels``.

    ``levels_at(step) = start_levels + (step // interval) * levels_per_step``, capped at
    ``max_levels`` when given. The model passes the result to ``grid.set_active_levels``
    (which also caps at the grid's level count).

    Attributes:
        start_levels: active levels at step 0 (>= 1).
        interval: steps between openings (>= 1).
        levels_per_step: levels opened each time. Default: 1.
        max_levels: optional cap. Default: None.

    Example:
        >>> LevelSchedule(4, 1000).levels_at(2500)
        6
    """

    start_levels: int
    interval: int
    levels_per_step: int = 1
    max_levels: int | None = None

    def __post_init__(self) -> None:
        if self.start_levels < 1 or self.interval < 1 or self.levels_per_step < 0:
            raise ConfigError(
                "LevelSchedule: need start_levels >= 1, interval >= 1, levels_per_step >= 0, "
                f"got {self.start_levels}, {self.interval}, {self.levels_per_step}"
            )

    def levels_at(self, step: int) -> int:
        """Number of active levels at training step ``step`` (>= 0)."""
        n = self.start_levels + (max(int(step), 0) // self.interval) * self.levels_per_step
        return n if self.max_levels is None else min(n, self.max_levels)
