"""hybridneus: coloured 3D meshes from a single colour event camera.

EventNeuS (a NeuS signed distance field trained only from events) with pure-PyTorch
multiresolution feature grids in place of deep MLPs. The flat names below are the ones most
pipelines need; each lives in a topic sub-package (``hybridneus.data``, ``.simulate``,
``.grids``, ``.model``, ``.rendering``, ``.training``, ``.meshing``, ``.evaluation``) and is
imported on first use, so ``import hybridneus`` stays light (no torch, no Open3D).

Example:
    >>> import hybridneus as hn  # doctest: +SKIP
    >>> field = hn.fit("data/real/multimeter", "fast", out="runs")  # doctest: +SKIP
    >>> mesh = hn.extract_mesh(field, res=300, color=True)  # a trimesh.Trimesh  # doctest: +SKIP
    >>> hn.chamfer_distance(mesh, "gt_mesh.ply").chamfer  # doctest: +SKIP
"""

from __future__ import annotations

from hybridneus.errors import ConfigError, DatasetError, HybridNeusError, MeshError, RunError
from hybridneus.lazy import lazy_getattr

__version__ = "0.3.0"

# public name -> module that defines it
_LAZY: dict[str, str] = {
    "Config": "hybridneus.config",
    "preset_config": "hybridneus.config",
    "fit": "hybridneus.api",
    "load_dataset": "hybridneus.data",
    "EventWindowSampler": "hybridneus.data",
    "simulate_dataset": "hybridneus.simulate",
    "latest_run": "hybridneus.training.runs",
    "load_field": "hybridneus.training.runs",
    "extract_mesh": "hybridneus.meshing",
    "save_mesh": "hybridneus.meshing",
    "load_mesh": "hybridneus.meshing",
    "mesh_to_open3d": "hybridneus.meshing",
    "mesh_from_open3d": "hybridneus.meshing",
    "mesh_to_numpy": "hybridneus.meshing",
    "mesh_from_numpy": "hybridneus.meshing",
    "chamfer_distance": "hybridneus.evaluation",
    "sdf_mae": "hybridneus.evaluation",
    "color_corrected_psnr_ssim": "hybridneus.evaluation",
    "write_report": "hybridneus.report",
}


__getattr__ = lazy_getattr(__name__, _LAZY, globals())


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__all__ = [
    "ConfigError",
    "DatasetError",
    "HybridNeusError",
    "MeshError",
    "RunError",
    "__version__",
    *_LAZY,
]
