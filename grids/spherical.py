"""Real spherical-harmonics encoding of view directions (tiny-cuda-nn order and signs)."""

from __future__ import annotations

import math

import torch
from torch import nn

from hybridneus.errors import ConfigError

__all__ = ["SphericalHarmonics"]

_PI = math.pi
# Normalisation constants of the real SH basis, written from their closed forms.
_C0 = 0.5 / math.sqrt(_PI)
_C1 = math.sqrt(3.0) / (2.0 * math.sqrt(_PI))
_C2_XY = math.sqrt(15.0) / (2.0 * math.sqrt(_PI))
_C2_Z = math.sqrt(5.0) / (4.0 * math.sqrt(_PI))
_C2_XX = math.sqrt(15.0) / (4.0 * math.sqrt(_PI))
_C3_A = math.sqrt(70.0) / (8.0 * math.sqrt(_PI))
_C3_B = math.sqrt(105.0) / (2.0 * math.sqrt(_PI))
_C3_C = math.sqrt(42.0) / (8.0 * math.sqrt(_PI))
_C3_D = math.sqrt(7.0) / (4.0 * math.sqrt(_PI))
_C3_E = math.sqrt(105.0) / (4.0 * math.sqrt(_PI))


class SphericalHarmonics(nn.Module):
    """Real spherical harmonics of bands 0 .. degree-1 evaluated on unit directions.

    Output k = l**2 + l + m holds Y_l^m for m = -l .. l, with tiny-cuda-nn's ordering and
    signs: ``Y_l^{m<0} = sqrt(2) Im(Y_l^{|m|})``, ``Y_l^0``, ``Y_l^{m>0} = sqrt(2) Re(Y_l^m)``
    where ``Y_l^m`` is the complex harmonic with the Condon-Shortley phase. For example the
    first four outputs are ``1/(2 sqrt(pi))`` and ``sqrt(3/(4 pi)) * (-y, z, -x)``.

    Unlike tiny-cuda-nn, whose SH encoding expects ``(v + 1) / 2`` in [0, 1]^3, this module
    takes the unit vector ``v`` itself. Inputs are not normalised: the bands of degree >= 2
    use ``x**2 + y**2 + z**2 = 1`` (e.g. ``3 z**2 - 1``), so non-unit inputs give polynomials
    that are not harmonics.

    Args:
        degree: number of bands, 1 .. 4; the output width is ``degree**2``.

    Example:
        >>> sh = SphericalHarmonics(4)
        >>> sh(torch.nn.functional.normalize(torch.randn(10, 3), dim=-1)).shape
        torch.Size([10, 16])
    """

    def __init__(self, degree: int = 4) -> None:
        super().__init__()
        if not 1 <= degree <= 4:
            raise ConfigError(f"SphericalHarmonics: degree must be in 1..4, got {degree}")
        self.degree = degree
        self.out_dim = degree**2

    def forward(self, dirs: torch.Tensor) -> torch.Tensor:
        """Encode directions.

        Args:
            dirs: (*, 3) unit vectors (x, y, z), float32 or float64.

        Returns:
            sh: (*, degree**2) in the input's dtype.

        Note:
            Polynomials in ``dirs``: differentiable to any order.
        """
        if dirs.shape[-1] != 3:
            raise ValueError(
                f"SphericalHarmonics: expected dirs of shape (*, 3), got {tuple(dirs.shape)}"
            )
        x, y, z = dirs.unbind(-1)
        out = [torch.full_like(x, _C0)]
        if self.degree >= 2:
            out += [-_C1 * y, _C1 * z, -_C1 * x]
        if self.degree >= 3:
            xx, yy, zz = x * x, y * y, z * z
            out += [
                _C2_XY * x * y,
                -_C2_XY * y * z,
                _C2_Z * (3.0 * zz - 1.0),
                -_C2_XY * x * z,
                _C2_XX * (xx - yy),
            ]
        if self.degree >= 4:
            out += [
                _C3_A * y * (yy - 3.0 * xx),
                _C3_B * x * y * z,
                _C3_C * y * (1.0 - 5.0 * zz),
                _C3_D * z * (5.0 * zz - 3.0),
                _C3_C * x * (1.0 - 5.0 * zz),
                _C3_E * z * (xx - yy),
                _C3_A * x * (3.0 * yy - xx),
            ]
        return torch.stack(out, dim=-1)

    def extra_repr(self) -> str:
        return f"degree={self.degree}"
