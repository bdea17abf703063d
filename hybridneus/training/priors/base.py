"""What a prior is: a named, switchable assumption that adds loss terms or acts on the state.

A prior hooks into a training step at up to three places, each a no-op by default:

- :meth:`Prior.terms`: loss terms from the step's :class:`StepContext` (the render output,
  the random volume points), as ``{name: (weight, value)}``; they are logged as
  ``loss/<name>``;
- :meth:`Prior.after_update`: after the optimiser's step, before the logs (a projection of
  the parameters);
- :meth:`Prior.after_logs`: with the step's logged numbers (a watch that may restore state);

and may scale the learning rate (:meth:`Prior.lr_scale`) and keep state across a resume
(:meth:`Prior.state_dict`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import torch

if TYPE_CHECKING:
    from hybridneus.rendering.renderer import RenderOutput


@dataclass
class RandomPoints:
    """The step's random volume points and what the field says there.

    Attributes:
        points: (n, 3) uniform in the crop box grown by ``loss.random_box_margin``.
        sdf: (n,) raw SDF, differentiable.
        outside: (n,) bool, outside the crop cylinder.
    """

    points: torch.Tensor
    sdf: torch.Tensor
    outside: torch.Tensor


@dataclass
class StepContext:
    """What one training step hands to the loss terms.

    Attributes:
        field: the field being trained.
        out: the render of the step's rays (both window ends, or the frames' pixels).
        origins: (n_rays, 3) ray origins of ``out``.
        dirs: (n_rays, 3) unit directions.
        p: training progress of the step, in [0, 1].
        generator: the trainer's random generator (on the field's device).
        batch: the step's batch (:class:`~hybridneus.data.windows.RayBatch`, or a frame
            batch under RGB supervision), or ``None``.
        random: the random volume points, or ``None`` when no term asked for them.
        eikonal: SDF gradient blocks for the Eikonal term, each with per-point weights
            (``None``: all count); a term that evaluates gradients appends its own.
    """

    field: Any
    out: RenderOutput
    origins: torch.Tensor
    dirs: torch.Tensor
    p: float
    generator: torch.Generator
    batch: Any = None
    random: RandomPoints | None = None
    eikonal: list[tuple[torch.Tensor, torch.Tensor | None]] = field(default_factory=list)


class Prior:
    """Base class: every hook does nothing (see the module docstring)."""

    #: the config sub-tree's name (``priors.<name>``)
    name = ""
    #: the prior reads :attr:`StepContext.random`
    uses_random_points = False

    def terms(self, ctx: StepContext) -> dict[str, tuple[float, torch.Tensor]]:
        """Loss terms ``{name: (weight, value)}`` of this step (none by default)."""
        return {}

    def after_update(self, trainer: Any, p: float) -> None:
        """Called after the optimiser's step at progress ``p``."""

    def after_logs(self, trainer: Any, logs: dict[str, float]) -> None:
        """Called with the step's logs (``trainer.step`` already counts the step)."""

    def lr_scale(self, trainer: Any) -> float:
        """Multiplier of the learning rate at ``trainer.step``."""
        return 1.0

    def state_dict(self) -> dict[str, Any]:
        """What a checkpoint must keep of this prior (primitives only)."""
        return {}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore :meth:`state_dict`'s output."""
