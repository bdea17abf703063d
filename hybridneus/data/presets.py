"""Per-scene settings of the EventNeRF reference code, picked from a dataset's path.

The values come from the table in ``docs/data.md`` (taken from the EventNeRF reference code):
three groups (``nerf``, ``real``, ``nextnextgen``) with per-scene polarity offsets (real),
per-scene crop heights (nextnextgen), a threshold of 0.2 for nextnextgen ``cube`` and a
lighter background for real ``xbox``. A dataset written by ``hybridneus.simulate`` carries its
own preset in ``<root>/scene.json``; anything else falls back to the ``nerf`` values under the
group name ``custom``.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import os
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from hybridneus.errors import ConfigError, DatasetError

log = logging.getLogger(__name__)

DEFAULT_WIDTH = 346
DEFAULT_HEIGHT = 260
_BG = 159.0 / 255.0


@dataclass(frozen=True)
class ScenePreset:
    """Everything about a scene that the files on disk do not say.

    Attributes:
        group: ``nerf``, ``real``, ``nextnextgen`` or ``custom``.
        scene: scene name (the dataset folder name when the scene is not a published one).
        threshold: contrast threshold C; the training target is ``C * E``.
        polarity_offset: added to every event's polarity (-1/+1) when accumulating E.
        max_window: longest event window, in views (L_max of the paper).
        cyclic: the capture is a closed loop, so windows that start before t=0 wrap to the end.
        neg_ratio: fraction of a batch's pixels drawn uniformly from all pixels (the rest come
            from pixels with events).
        tonemap_eps: ``eps`` in ``log(c**2.2 + eps)`` of the loss.
        crop_r: radius of the density crop cylinder around the world y axis.
        crop_y_min: lower end of the crop cylinder.
        crop_y_max: upper end of the crop cylinder.
        background: RGB background colour in [0, 1].
        width: image width in pixels (the files do not store it; 346 for every published scene).
        height: image height in pixels (260 for every published scene).
        mosaic: the sensor's colour filter: a Bayer layout (``RGGB`` for every published
            scene, ``BGGR``, ``GRBG``, ``GBRG``) or ``mono`` (the field then renders grey).
    """

    group: str
    scene: str
    threshold: float
    polarity_offset: float
    max_window: int
    cyclic: bool
    neg_ratio: float
    tonemap_eps: float
    crop_r: float
    crop_y_min: float
    crop_y_max: float
    background: tuple[float, float, float]
    width: int = DEFAULT_WIDTH
    height: int = DEFAULT_HEIGHT
    mosaic: str = "RGGB"

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-ready dict (``background`` as a list)."""
        d = dataclasses.asdict(self)
        d["background"] = list(self.background)
        return d


GROUPS = ("nerf", "real", "nextnextgen")

_NERF = ScenePreset(
    group="nerf", scene="", threshold=0.25, polarity_offset=0.0, max_window=50, cyclic=False,
    neg_ratio=0.1, tonemap_eps=0.1, crop_r=1.0, crop_y_min=-1.0, crop_y_max=1.0,
    background=(_BG, _BG, _BG),
)
_REAL = ScenePreset(
    group="real", scene="", threshold=0.1, polarity_offset=-0.404, max_window=100, cyclic=True,
    neg_ratio=0.05, tonemap_eps=1e-5, crop_r=0.25, crop_y_min=-0.35, crop_y_max=0.15,
    background=(_BG, _BG, _BG),
)
_NEXTNEXTGEN = ScenePreset(
    group="nextnextgen", scene="", threshold=0.1, polarity_offset=0.0, max_window=100,
    cyclic=True, neg_ratio=0.05, tonemap_eps=1e-5, crop_r=0.25, crop_y_min=-0.1,
    crop_y_max=0.195, background=(_BG, _BG, _BG),
)
GROUP_DEFAULTS: dict[str, ScenePreset] = {"nerf": _NERF, "real": _REAL, "nextnextgen": _NEXTNEXTGEN}

# Per-scene values that differ from the group defaults.
SCENE_VALUES: dict[str, dict[str, dict[str, Any]]] = {
    "nerf": {s: {} for s in ("chair", "drums", "ficus", "hotdog", "lego", "materials", "mic")},
    "real": {
        "chick": {"polarity_offset": -0.438},
        "legocube": {"polarity_offset": -0.404},
        "mic": {"polarity_offset": -0.352},
        "multimeter": {"polarity_offset": -0.406},
        "plant": {"polarity_offset": -0.451},
        "ps1": {"polarity_offset": -0.438},
        "r": {"polarity_offset": -0.389},
        "sewing": {"polarity_offset": -0.375},
        "urpils": {"polarity_offset": -0.401},
        "xbox": {"polarity_offset": -0.385, "background": (200 / 255, 200 / 255, 200 / 255)},
    },
    "nextnextgen": {
        "bottle": {"crop_y_min": -0.14},
        "chicken": {"crop_y_min": -0.08},
        "controller": {"crop_y_min": -0.04},
        "cube": {"crop_y_min": 0.045, "threshold": 0.2},
        "dragon": {"crop_y_min": -0.15},
        "microphone": {"crop_y_min": -0.14},
        "multimeter": {"crop_y_min": -0.06},
        "plant": {"crop_y_min": -0.065},
        "tapes": {"crop_y_min": -0.12},
    },
}

PRESET_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(ScenePreset))
_INT_FIELDS = {"max_window", "width", "height"}
_BOOL_FIELDS = {"cyclic"}
_STR_FIELDS = {"group", "scene", "mosaic"}


def preset_for_scene(group: str, scene: str) -> ScenePreset:
    """The published preset of ``group/scene``.

    Args:
        group: ``nerf``, ``real`` or ``nextnextgen``.
        scene: a scene name; unknown names get the group defaults (real: polarity offset
            -0.404, the mean of the published scenes; nextnextgen: crop_y_min -0.1).

    Raises:
        ConfigError: unknown group.
    """
    if group not in GROUP_DEFAULTS:
        raise ConfigError(f"group: unknown preset group {group!r} (known: {', '.join(GROUPS)})")
    base = replace(GROUP_DEFAULTS[group], scene=scene)
    return replace(base, **SCENE_VALUES[group].get(scene, {}))


def _coerce(key: str, value: Any) -> Any:
    """Check (and for strings from the command line, parse) one override value."""
    if key in _BOOL_FIELDS:
        if isinstance(value, bool):
            return value
        if isinstance(value, str) and value.lower() in ("true", "yes", "1", "false", "no", "0"):
            return value.lower() in ("true", "yes", "1")
        raise ConfigError(f"{key}: expected true/false, got {value!r}")
    if key in _INT_FIELDS:
        if isinstance(value, str):
            try:
                value = int(value)
            except ValueError:
                raise ConfigError(f"{key}: expected an integer, got {value!r}") from None
        if isinstance(value, bool) or not isinstance(value, int):
            if isinstance(value, float) and value.is_integer():
                value = int(value)
            else:
                raise ConfigError(f"{key}: expected an integer, got {value!r}")
        if value < 1:
            raise ConfigError(f"{key}: must be >= 1, got {value}")
        return value
    if key in _STR_FIELDS:
        if not isinstance(value, str):
            raise ConfigError(f"{key}: expected a string, got {value!r}")
        if key == "mosaic":
            from hybridneus.data.mosaic import check_mosaic

            return check_mosaic(value)
        return value
    if key == "background":
        if isinstance(value, str):
            try:
                parts = [float(v) for v in value.replace(" ", "").split(",") if v]
            except ValueError:
                raise ConfigError(f"{key}: expected 1 or 3 numbers, got {value!r}") from None
        elif isinstance(value, int | float) and not isinstance(value, bool):
            parts = [float(value)]
        elif isinstance(value, list | tuple) and all(
            isinstance(v, int | float) and not isinstance(v, bool) for v in value
        ):
            parts = [float(v) for v in value]
        else:
            raise ConfigError(f"{key}: expected 1 or 3 numbers, got {value!r}")
        if len(parts) == 1:
            parts = parts * 3
        if len(parts) != 3 or not all(0.0 <= v <= 1.0 for v in parts):
            raise ConfigError(f"{key}: expected 1 or 3 numbers in [0, 1], got {value!r}")
        return tuple(parts)
    # float fields
    if isinstance(value, str):
        try:
            value = float(value)
        except ValueError:
            raise ConfigError(f"{key}: expected a number, got {value!r}") from None
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"{key}: expected a number, got {value!r}")
    value = float(value)
    if value != value or value in (float("inf"), float("-inf")):
        raise ConfigError(f"{key}: expected a finite number, got {value!r}")
    if key in ("threshold", "tonemap_eps", "crop_r") and value <= 0:
        raise ConfigError(f"{key}: must be > 0, got {value}")
    if key == "neg_ratio" and not 0.0 <= value <= 1.0:
        raise ConfigError(f"{key}: must be in [0, 1], got {value}")
    return value


def apply_overrides(preset: ScenePreset, overrides: dict[str, Any] | None) -> ScenePreset:
    """Return ``preset`` with some fields replaced.

    Args:
        preset: the preset to start from.
        overrides: field name -> value. Values are type-checked; strings (from the command
            line) are parsed: ``"0.2"``, ``"true"``, ``"0.6,0.6,0.6"``.

    Raises:
        ConfigError: unknown key or a value of the wrong type (one line naming the key).
    """
    if not overrides:
        return preset
    clean: dict[str, Any] = {}
    for key, value in overrides.items():
        if key not in PRESET_FIELDS:
            raise ConfigError(
                f"{key}: unknown preset key (known: {', '.join(PRESET_FIELDS)})"
            )
        clean[key] = _coerce(key, value)
    out = replace(preset, **clean)
    if out.crop_y_min >= out.crop_y_max:
        raise ConfigError(
            f"crop_y_min: must be below crop_y_max, got {out.crop_y_min} >= {out.crop_y_max}"
        )
    return out


def _preset_from_parts(
    parts: tuple[str, ...],
) -> tuple[ScenePreset, str, frozenset[str]] | None:
    """Find ``<group>/<scene>`` in path parts (the last matching group wins); also return the
    fields it states: all of them for a published scene, all but the polarity offset (the
    group's default is a guess at a sensor's) for another scene of the group."""
    for i in range(len(parts) - 2, -1, -1):
        group = parts[i]
        if group in GROUP_DEFAULTS:
            scene = parts[i + 1]
            preset = preset_for_scene(group, scene)
            if scene in SCENE_VALUES[group]:
                return preset, f"path ({group}/{scene})", frozenset(PRESET_FIELDS)
            return (
                preset,
                f"path ({group}/, unknown scene {scene!r}: {group} group defaults)",
                frozenset(PRESET_FIELDS) - {"polarity_offset"},
            )
    return None


def _read_scene_json(path: Path) -> dict[str, Any] | None:
    """The ``preset`` object of ``scene.json`` plus the image size it states anywhere
    (``preset``, the top level or ``camera``), or None when it states neither."""
    try:
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        raise DatasetError(f"{path}: cannot read ({exc})") from None
    except json.JSONDecodeError as exc:
        raise DatasetError(f"{path}: invalid JSON ({exc.msg} at line {exc.lineno})") from None
    if not isinstance(doc, dict):
        raise DatasetError(f"{path}: expected a JSON object at the top level")
    preset = doc.get("preset")
    if preset is not None and not isinstance(preset, dict):
        raise DatasetError(f"{path}: 'preset' must be an object of ScenePreset fields")
    values = dict(preset or {}) | _scene_size(doc, path)
    return values or None


def _scene_size(doc: dict[str, Any], path: Path) -> dict[str, int]:
    """``width``/``height`` wherever ``scene.json`` states them; they must be positive
    integers and agree between places."""
    found: dict[str, tuple[int, str]] = {}
    places = (("preset", doc.get("preset")), ("top level", doc), ("camera", doc.get("camera")))
    for where, obj in places:
        if not isinstance(obj, dict):
            continue
        for key in ("width", "height"):
            if key not in obj:
                continue
            v = obj[key]
            if isinstance(v, bool) or not isinstance(v, int | float) or not v >= 1 \
                    or not float(v).is_integer():
                raise DatasetError(f"{path}: {key} ({where}) must be a positive integer, "
                                   f"got {v!r}")
            if key in found and found[key][0] != int(v):
                raise DatasetError(f"{path}: {key} {found[key][0]} ({found[key][1]}) and "
                                   f"{int(v)} ({where}) disagree")
            found.setdefault(key, (int(v), where))
    return {k: v for k, (v, _) in found.items()}


def preset_for_path(path: str | os.PathLike) -> ScenePreset:
    """The preset for a dataset root (see :func:`resolve_preset`, which also says why)."""
    return resolve_preset(path)[0]


def resolve_preset(path: str | os.PathLike) -> tuple[ScenePreset, str]:
    """Pick the preset for a dataset root and say where it came from.

    Order: ``<root>/scene.json`` with a ``preset`` object (fields missing there are taken from
    the path's preset, else from the ``nerf`` group); else ``.../<group>/<scene>`` in the
    path; else the ``nerf`` group values under group ``custom``.

    Args:
        path: dataset root (the folder that holds the split folders).

    Returns:
        ``(preset, source)``; ``source`` is a short human-readable string such as
        ``"path (real/multimeter)"`` or ``"scene.json"``.

    Raises:
        DatasetError: ``scene.json`` exists but is unreadable or holds bad values.
    """
    preset, source, _ = resolve_preset_fields(path)
    return preset, source


def resolve_preset_fields(
    path: str | os.PathLike,
) -> tuple[ScenePreset, str, frozenset[str]]:
    """:func:`resolve_preset`, plus the fields that the path or ``scene.json`` stated.

    A published scene's path states all of its fields, another scene of a group all but the
    polarity offset; ``scene.json`` states the keys it holds; the ``nerf`` values of the
    fallback state nothing. A reader may estimate what is not stated from the data (the
    polarity offset: :mod:`hybridneus.data.balance`).
    """
    root = Path(path)
    resolved = root.resolve()
    parts = resolved.parts
    from_path = _preset_from_parts(parts)
    scene_json = root / "scene.json"
    if scene_json.is_file():
        values = _read_scene_json(scene_json)
        if values is not None:
            base = from_path[0] if from_path else replace(_NERF, group="custom", scene=root.name)
            unknown = sorted(k for k in values if k not in PRESET_FIELDS)
            for key in unknown:
                log.warning("%s: ignoring unknown preset key %r", scene_json, key)
                values.pop(key)
            stated = frozenset(values) | (from_path[2] if from_path else frozenset())
            try:
                return apply_overrides(base, values), "scene.json", stated
            except ConfigError as exc:
                raise DatasetError(f"{scene_json}: preset {exc}") from None
    if from_path is not None:
        return from_path
    return (
        replace(_NERF, group="custom", scene=resolved.name),
        "fallback: path names no nerf/real/nextnextgen scene and no scene.json preset, "
        "using nerf group values",
        frozenset(),
    )
