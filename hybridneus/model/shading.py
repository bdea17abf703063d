"""One shading for the whole scene: the shaded colour model's light (``field.shading_degree``).

A field with this model gives an albedo per point and multiplies it by :class:`SceneShading`
of the point's normal. Under light from far away a Lambertian surface is its albedo times a
smooth function of its normal alone, which a few bands of real spherical harmonics hold well:

    shading_c(n) = exp(sum_j w_cj Y_j(n))        for each colour channel c,

with ``Y_j`` the first ``degree`` bands (``degree**2`` functions) of the unit normal ``n`` and
``w`` (3, degree**2) learned from 0 (unshaded). A colour head that reads the normal can paint a
dent in a face of one colour to look even, and the events, silent inside the face, never
object; with the shading shared by the scene, such a dent shades unevenly. With ``headlight``
a light carried by the camera (a flash, a ring light) adds ``u_c1 c + u_c2 c^2`` to the
exponent, ``c`` the cosine between the normal and the direction to the camera, ``u`` (3, 2)
learned from 0.
"""

from __future__ import annotations

import torch
from torch import nn

from hybridneus.errors import ConfigError


class SceneShading(nn.Module):
    """The scene's shading of unit normals (see the module docstring).

    Args:
        degree: spherical-harmonics bands of the normal, 1 to 4.
        headlight: add a light at the camera.

    Attributes:
        coeffs: (3, degree**2) the exponent's weights per channel.
        headlight: (3, 2) weights of ``c`` and ``c^2``, or None.

    Example:
        >>> s = SceneShading(3)
        >>> s(torch.tensor([[0.0, 1.0, 0.0]])).tolist()
        [[1.0, 1.0, 1.0]]
    """

    def __init__(self, degree: int, headlight: bool = False) -> None:
        super().__init__()
        from hybridneus.grids import SphericalHarmonics

        if not 1 <= degree <= 4:
            raise ConfigError(f"field.shading_degree: must be 0 to 4, got {degree}")
        self.sh = SphericalHarmonics(degree)
        self.coeffs = nn.Parameter(torch.zeros(3, self.sh.out_dim))
        self.headlight = nn.Parameter(torch.zeros(3, 2)) if headlight else None

    def forward(self, normals: torch.Tensor, dirs: torch.Tensor | None = None) -> torch.Tensor:
        """Shading (n, 3) of normals (n, 3), which need not be unit, seen along unit ray
        directions ``dirs`` (n, 3; needed with a headlight).

        Raises:
            ValueError: a headlight without ``dirs``.
        """
        unit = torch.nn.functional.normalize(normals, dim=-1)
        exponent = self.sh(unit) @ self.coeffs.t().to(unit.dtype)
        if self.headlight is not None:
            if dirs is None:
                raise ValueError("dirs: a shading with a headlight depends on the view")
            c = -(unit * dirs).sum(-1, keepdim=True)  # cosine to the camera
            exponent = exponent + torch.cat([c, c * c], -1) @ self.headlight.t().to(unit.dtype)
        return torch.exp(exponent)
