"""Helpers of the training tests: a tiny model config and a simulated scene to fit."""

from __future__ import annotations

import torch

from hybridneus.config import Config, apply_overrides, preset_config

#: A small model that fits the 48x36 test scene in well under a second per ten steps.
TINY = [
    "grid.n_levels=6",
    "grid.log2_table_size=14",
    "grid.base_resolution=8",
    "grid.max_resolution=64",
    "grid.start_levels=3",
    "render.n_coarse=12",
    "render.n_importance=8",
    "render.occupancy_resolution=24",
    "render.occupancy_every=8",
    "render.occupancy_march=48",
    "loss.n_random_points=256",
    "train.n_rays=64",
    "train.warmup=0.1",
    "train.log_every=2",
    "train.preview_every=0",
    "train.checkpoint_every=0",
]


def tiny(*extra: str, preset: str = "fast") -> Config:
    """The preset with :data:`TINY` and ``extra`` applied."""
    return apply_overrides(preset_config(preset), [*TINY, *extra])


def params(field) -> dict[str, torch.Tensor]:
    """A copy of a field's state."""
    return {k: v.detach().clone() for k, v in field.state_dict().items()}


def stop_at(step: int):
    """A callback that interrupts a fit (as Ctrl-C does) once it reaches ``step``."""
    def callback(trainer, logs):
        if trainer.step == step:
            raise KeyboardInterrupt

    return callback
