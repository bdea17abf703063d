"""Reading EventNeRF-layout datasets: presets, splits, event windows and ray batches.

See docs/data.md for the layout, the presets and every convention.
"""

from __future__ import annotations

from hybridneus.data.dataset import EventDataset, SplitData, load_dataset, load_split
from hybridneus.data.events import EventStream, load_events
from hybridneus.data.presets import (
    ScenePreset,
    apply_overrides,
    parse_override_strings,
    preset_for_path,
    preset_for_scene,
    resolve_preset,
)
from hybridneus.data.rays import camera_rays, interpolate_pose, near_far_unit_sphere
from hybridneus.data.windows import (
    EventCounter,
    EventWindowSampler,
    RayBatch,
    bayer_mask,
    event_frame,
)

__all__ = [
    "EventCounter",
    "EventDataset",
    "EventStream",
    "EventWindowSampler",
    "RayBatch",
    "ScenePreset",
    "SplitData",
    "apply_overrides",
    "bayer_mask",
    "camera_rays",
    "event_frame",
    "interpolate_pose",
    "load_dataset",
    "load_events",
    "load_split",
    "near_far_unit_sphere",
    "parse_override_strings",
    "preset_for_path",
    "preset_for_scene",
    "resolve_preset",
]
