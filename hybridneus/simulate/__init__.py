"""hybridneus.simulate: render a mesh along a camera trajectory and simulate a colour event
camera, writing datasets in the EventNeRF layout (see docs/simulate.md).

Open3D is imported only when a :class:`Renderer` is created.
"""

from __future__ import annotations

from hybridneus.simulate.capture import CaptureErrors, written_poses
from hybridneus.simulate.dataset import (
    CAMERA_RADIUS,
    SimulationConfig,
    crop_cylinder,
    resolve_mesh,
    simulate_dataset,
    split_trajectories,
    with_overrides,
)
from hybridneus.simulate.events import (
    DAVIS346_THRESHOLD,
    REALISTIC_NOISE,
    EventChunk,
    EventModel,
    EventSimulator,
    NoiseConfig,
    SimulationError,
    bayer_channel,
    davis346_noise,
    log_intensity,
    mosaic_rggb,
)
from hybridneus.simulate.procedural import BUILTIN_SCENES, builtin_scene
from hybridneus.simulate.render import PinholeCamera, Renderer, Shading, sample_bilinear
from hybridneus.simulate.scene_mesh import Normalization, SceneMesh, load_mesh, normalization_for
from hybridneus.simulate.trajectory import (
    Trajectory,
    circle,
    even_spiral,
    look_at_origin,
    seiffert_spiral,
)

__all__ = [
    "BUILTIN_SCENES",
    "CAMERA_RADIUS",
    "DAVIS346_THRESHOLD",
    "REALISTIC_NOISE",
    "CaptureErrors",
    "EventChunk",
    "EventModel",
    "EventSimulator",
    "NoiseConfig",
    "davis346_noise",
    "Normalization",
    "PinholeCamera",
    "Renderer",
    "SceneMesh",
    "Shading",
    "SimulationConfig",
    "SimulationError",
    "Trajectory",
    "bayer_channel",
    "builtin_scene",
    "circle",
    "crop_cylinder",
    "even_spiral",
    "load_mesh",
    "log_intensity",
    "look_at_origin",
    "mosaic_rggb",
    "normalization_for",
    "resolve_mesh",
    "sample_bilinear",
    "seiffert_spiral",
    "simulate_dataset",
    "split_trajectories",
    "with_overrides",
    "written_poses",
]
