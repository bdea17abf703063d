"""The interface that mesh extraction, evaluation and rendering read a trained field through.

Anything with these methods is a field: the trained hybrid model, the ``eventneus`` MLP,
and the analytic shapes in :mod:`hybridneus.model.analytic` used by tests.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import torch


@runtime_checkable
class Field(Protocol):
    """A signed distance field with a view-dependent colour field, in world coordinates.

    Points are in the dataset's world frame (the reconstruction volume is the unit sphere /
    the cube [-1, 1]^3). Methods take and return torch tensors on ``field.device``;
    negative SDF is inside the object.
    """

    device: torch.device

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        """Signed distance at ``points`` (n_points, 3) -> (n_points,)."""
        ...

    def sdf_and_gradient(self, points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Signed distance (n_points,) and its spatial gradient (n_points, 3)."""
        ...

    def color(self, points: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
        """Linear-in-[0, 1] RGB (n_points, 3) seen along unit view directions (n_points, 3)."""
        ...
