"""Everything a checkpoint holds of a trainer, so that a resumed run continues exactly.

The state is tensors and primitive containers only (it loads with ``weights_only=True``):
the step, the field, the occupancy grid, the optimiser's moments, every random state (torch's,
the trainer's generator, the window and frame samplers') and each prior's own state.
"""

from __future__ import annotations

import logging
from typing import Any

import numpy as np
import torch

from hybridneus.training.schedules import Timeline

#: Checkpoint layout version (1: hybridneus 0.1, whose guard state sat under ``guard``).
VERSION = 2


def trainer_state(trainer) -> dict[str, Any]:
    """The state of ``trainer`` (a :class:`~hybridneus.training.trainer.Trainer`)."""
    return {
        "version": VERSION,
        "step": trainer.step,
        "total_steps": trainer.total_steps,
        # a re-planned budget's (step, progress) knots: the schedules resume where they were
        "knots": [[int(k), float(q)] for k, q in trainer.timeline.knots],
        "elapsed": trainer.elapsed,
        "model": trainer.field.state_dict(),
        "occupancy": trainer.occupancy.occupied.clone(),
        "optimizer": trainer.optimizer.state_dict(),
        "torch_rng": torch.get_rng_state(),
        "generator": trainer.generator.get_state(),
        "window_rng": _primitive(trainer.windows.rng.bit_generator.state),
        "frame_rng": None if trainer.frames is None
        else _primitive(trainer.frames.rng.bit_generator.state),
        "priors": {p.name: p.state_dict() for p in trainer.priors},
        "scene": _scene(trainer),
        "config": trainer.cfg.to_dict(),
    }


def load_trainer_state(trainer, state: dict[str, Any]) -> None:
    """Put ``state`` (from :func:`trainer_state`) back into ``trainer``."""
    trainer.field.load_state_dict(state["model"])
    trainer.occupancy.occupied.copy_(state["occupancy"])
    trainer.optimizer.load_state_dict(state["optimizer"])
    torch.set_rng_state(state["torch_rng"])
    try:
        trainer.generator.set_state(state["generator"])
    except RuntimeError:
        # Saved on the other kind of device: CPU and CUDA generator states differ in size
        # and cannot be carried across, so the sample draws continue from a new stream
        # (everything else resumes exactly).
        trainer.generator.manual_seed(trainer.cfg.train.seed + 1 + int(state["step"]))
        logging.getLogger("hybridneus").info(
            "resumed on %s; the checkpoint's sampler state does not fit this device (saved on "
            "another kind of device?): ray jitter and random points continue from a new "
            "random stream", trainer.device.type)
    trainer.windows.rng.bit_generator.state = state["window_rng"]
    if trainer.frames is not None and state.get("frame_rng") is not None:
        trainer.frames.rng.bit_generator.state = state["frame_rng"]
    trainer.step = int(state["step"])
    trainer.timeline = timeline(state)
    trainer.elapsed = float(state.get("elapsed", 0.0))
    saved = state.get("priors", {})
    for prior in trainer.priors:
        prior.load_state_dict({**saved.get(prior.name, {}), "step": trainer.step})
    trainer.field.update_step(trainer.timeline.position(trainer.step), trainer.total_steps)


def timeline(state: dict[str, Any]) -> Timeline:
    """The schedule of a saved state (a checkpoint from before re-plans kept their progress
    has no knots: ``step / total_steps``)."""
    knots = [(int(k), float(q)) for k, q in state.get("knots") or [(0, 0.0)]]
    return Timeline(int(state["total_steps"]), knots)


def position(state: dict[str, Any]) -> float:
    """The saved step's position on its schedule, for
    :meth:`~hybridneus.model.field.HybridField.update_step`."""
    return timeline(state).position(int(state["step"]))


def _scene(trainer) -> dict[str, Any]:
    """What meshing needs of the scene (:attr:`Trainer.scene`)."""
    return dict(trainer.scene)


def _primitive(value: Any) -> Any:
    """numpy scalars and arrays inside a bit-generator state -> Python ints and lists."""
    if isinstance(value, dict):
        return {k: _primitive(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.integer):
        return int(value)
    return value
