"""hybridneus: coloured 3D meshes from a single colour event camera.

EventNeuS (a NeuS signed distance field trained only from events) with pure-PyTorch
multiresolution feature grids in place of deep MLPs.
"""

from __future__ import annotations

from hybridneus.errors import ConfigError, DatasetError, HybridNeusError, MeshError, RunError

__version__ = "0.1.0"

__all__ = [
    "ConfigError",
    "DatasetError",
    "HybridNeusError",
    "MeshError",
    "RunError",
    "__version__",
]
