"""Reading EventNeRF-layout datasets: presets, splits, event windows and ray batches.

See docs/data.md for the layout, the presets and every convention. Loading needs only numpy;
the torch-based names (rays, windows) are imported on first use so that ``hybridneus info``
starts without importing torch.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from hybridneus.data.dataset import EventDataset, SplitData, load_dataset, load_split
from hybridneus.data.events import EventStream, load_events
from hybridneus.data.presets import (
    ScenePreset,
    apply_overrides,
    preset_for_path,
    preset_for_scene,
    resolve_preset,
)
from hybridneus.lazy import lazy_getattr

if TYPE_CHECKING:
    from hybridneus.data.rays import camera_rays, interpolate_pose, near_far_unit_sphere
    from hybridneus.data.windows import (
        EventCounter,
        EventWindowSampler,
        RayBatch,
        bayer_mask,
        event_frame,
    )

_LAZY = {
    "camera_rays": "rays",
    "interpolate_pose": "rays",
    "near_far_unit_sphere": "rays",
    "EventCounter": "windows",
    "EventWindowSampler": "windows",
    "RayBatch": "windows",
    "bayer_mask": "windows",
    "event_frame": "windows",
}


__getattr__ = lazy_getattr(__name__, {k: f"{__name__}.{m}" for k, m in _LAZY.items()},
                           globals())


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
    "preset_for_path",
    "preset_for_scene",
    "resolve_preset",
]
