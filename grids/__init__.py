"""Pure-PyTorch feature-grid encodings (installed as ``hybridneus.grids``).

Exact tiny-cuda-nn-style multiresolution hash and dense grids, spherical harmonics and a
NeuS frequency encoding with EventNeuS annealing; all twice differentiable, CPU and CUDA.
See docs/grids.md.
"""

from .frequency import FrequencyEncoding, annealing_weights, full_bands
from .gather import gather_levels, gather_rows, interpolate_corners, scatter_rows, trilinear
from .hash import DenseGrid, HashGrid
from .levels import PRIMES, GridLevel, make_levels, per_level_scale
from .schedule import LevelSchedule
from .spherical import SphericalHarmonics

__all__ = [
    "DenseGrid",
    "FrequencyEncoding",
    "GridLevel",
    "HashGrid",
    "LevelSchedule",
    "PRIMES",
    "SphericalHarmonics",
    "annealing_weights",
    "full_bands",
    "gather_rows",
    "interpolate_corners",
    "gather_levels",
    "make_levels",
    "per_level_scale",
    "scatter_rows",
    "trilinear",
]
