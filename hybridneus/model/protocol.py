"""The interface that mesh extraction, evaluation and rendering read a trained field through.

Anything with these methods is a field: the trained hybrid model, the ``eventneus`` MLP,
and the analytic shapes in :mod:`hybridneus.model.analytic` used by tests.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np
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


def as_points(a: Any, device: torch.device) -> tuple[torch.Tensor, bool]:
    """``a`` as a float32 tensor on ``device``, and whether it came in as numpy (or a list).

    The convenience convention of the library's fields: numpy in gives numpy out, tensors
    in give tensors on the field's device out.
    """
    if isinstance(a, torch.Tensor):
        return a.to(device, torch.float32), False
    return torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32)).to(device), True
