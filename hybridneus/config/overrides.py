"""Typed assignment of dotted keys, ``key=value`` overrides, YAML files, and the keys of
hybridneus 0.1 configs."""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import types
import typing
from pathlib import Path
from typing import Any

import yaml

from hybridneus.config.tree import Config, preset_config
from hybridneus.errors import ConfigError


def _type_name(tp: Any) -> str:
    return getattr(tp, "__name__", None) or str(tp).replace("typing.", "")


def _coerce(key: str, value: Any, tp: Any) -> Any:
    """Check ``value`` against the annotation ``tp``; return it converted (int -> float etc)."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(key, value, arg)
            except ConfigError as exc:
                errors.append(exc)
        raise ConfigError(f"{key}: expected {_type_name(tp)}, got {value!r}")
    if origin is list:
        (item_tp,) = typing.get_args(tp) or (Any,)
        if not isinstance(value, list | tuple):
            raise ConfigError(f"{key}: expected a list, got {value!r}")
        return [_coerce(f"{key}[{i}]", v, item_tp) for i, v in enumerate(value)]
    if tp is Any:
        return value
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise ConfigError(f"{key}: expected true or false, got {value!r}")
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise ConfigError(f"{key}: expected an integer, got {value!r}")
    if tp is float:
        if isinstance(value, int | float) and not isinstance(value, bool):
            return float(value)
        if isinstance(value, str):
            # YAML 1.1 reads a mantissa without a point ("1e-8") as a string
            try:
                number = float(value)
            except ValueError:
                number = math.nan
            if math.isfinite(number):
                return number
        raise ConfigError(f"{key}: expected a number, got {value!r}")
    if tp is str:
        if isinstance(value, str):
            return value
        raise ConfigError(f"{key}: expected a string, got {value!r}")
    raise ConfigError(f"{key}: unsupported type {_type_name(tp)}")


def _section_fields(obj: Any) -> dict[str, Any]:
    hints = typing.get_type_hints(type(obj))
    return {f.name: hints[f.name] for f in dataclasses.fields(obj)}


#: Keys of hybridneus 0.1 configs: their new name, or ``None`` where the key is gone (a
#: schedule counted in steps, a prior that did not earn its place). A run's ``config.yaml``
#: written by 0.1 still loads (:func:`config_from_dict` moves or drops these); ``--set``
#: with an old key is an error that names the new one.
LEGACY_KEYS: dict[str, str | None] = {
    "loss.lambda_curvature": "priors.curvature.weight",
    "loss.curvature_step": "priors.curvature.step",
    "loss.curvature_end": "priors.curvature.end",
    "loss.lambda_hull": "priors.hull.weight",
    "loss.hull_resolution": "priors.hull.resolution",
    "loss.hull_ramp": None,
    "loss.hull_grow": None,
    "loss.hull_start": None,
    "loss.lambda_sparsity": None,
    "loss.sparsity_tau": None,
    "loss.lambda_background_matter": None,
    "loss.background_matter_sigma": None,
    "loss.background_matter_start": None,
    "train.inv_s_floor": "priors.sharpness_floor.floor",
    "train.inv_s_floor_at": "priors.sharpness_floor.at",
    "train.inv_s_floor_min_steps": None,
    "train.inv_s_floor_delay": None,
    "train.inv_s_floor_blend": None,
    "train.collapse_opacity": "priors.collapse_guard.opacity",
    "train.collapse_window": "priors.collapse_guard.window",
    "train.collapse_retries": "priors.collapse_guard.retries",
    "train.collapse_healthy": "priors.collapse_guard.healthy",
    "train.collapse_lr_factor": "priors.collapse_guard.lr_factor",
    "data.crop_from_events": "estimate.crop",
    "data.offset_from_events": "estimate.polarity_offset",
    "data.eps_from_events": "estimate.tonemap_eps",
    "data.eps_max": "estimate.eps_max",
    "data.eps_start": None,
    "data.eps_anneal_steps": None,
    "data.denoise": None,
    "data.denoise_slab": None,
    "field.color_init": None,
    "field.color_init_distance": None,
}
#: Keys removed in hybridneus 0.3, experiments that were measured and not adopted: their
#: default then (what this version does) and whether another value made a field this version
#: cannot build. A saved config that holds one loads without it; one whose field had such a
#: part is refused (:func:`config_from_dict`).
REMOVED_KEYS: dict[str, tuple[Any, bool]] = {
    "grid.domain": ("volume", True),
    "grid.domain_margin": (0.3, False),
    "field.prefit_steps": (0, False),
    "field.color_activation": ("relu", True),
    "field.color_grid_levels": (0, True),
    "field.shading_degree": (0, True),
    "field.shading_headlight": (False, True),
    "field.learned_background": (False, True),
    "render.empty_share": (0.0, False),
    "render.empty_share_until": (1.0, False),
    "render.cos_anneal_at": (0.0, False),
    "train.replan_at": ([0.05, 0.15, 0.3, 0.5, 0.7], False),
    "train.replan_lengthen": (False, False),
    "train.lr_sdf_head": (1.0, False),
    "train.lr_sdf_head_until": (0.0, False),
    "train.view_balance": (0.0, False),
    "train.windows_per_step": (1, False),
    "priors.curvature.event_weight": (1.0, False),
    "priors.curvature.order": (1, False),
    "priors.curvature.silent_only": (False, False),
    "priors.curvature.robust": (0.0, False),
    "priors.hull.silent_depth": (0.0, False),
    "priors.sharpness_ceiling.follow_levels": (False, False),
    "refine.poses": (False, False),
    "refine.pose_knots": (0, False),
    "refine.clock_offset": (False, False),
    "refine.pose_lr": (0.0005, False),
    "refine.pose_start": (0.5, False),
    "refine.pose_weight": (0.01, False),
    "refine.pose_gauge": (False, False),
    "priors.silent_lines.enabled": (False, False),
    "priors.silent_lines.weight": (1.0, False),
    "priors.silent_lines.lines": (32, False),
    "priors.silent_lines.min_length": (8, False),
    "priors.silent_lines.max_length": (128, False),
    "priors.silent_lines.views": (2.0, False),
    "priors.silent_lines.max_bend": (0.1, False),
    "priors.silent_lines.start": (0.2, False),
    "priors.silent_lines.ramp": (0.05, False),
}
#: Old keys whose value 0 meant "off": they also set their prior's ``enabled``.
_LEGACY_SWITCHES = {"loss.lambda_curvature", "loss.lambda_hull", "train.inv_s_floor",
                    "train.collapse_opacity"}


def _drop_removed(data: dict[str, Any], source: str) -> tuple[dict[str, Any], list[str]]:
    """``data`` without the keys of :data:`REMOVED_KEYS`, and a note for each dropped at
    another value than its default.

    Raises:
        ConfigError: a removed key at a value that made a field this version cannot build.
    """
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in data.items()}
    notes = []
    for key, (default, shapes_field) in REMOVED_KEYS.items():
        section, *middle, name = key.split(".")
        node, parents = out.get(section), []
        for part in middle:
            parents.append((node, part))
            node = node.get(part) if isinstance(node, dict) else None
        if not isinstance(node, dict) or name not in node:
            continue
        value = node.pop(name)
        # a removed prior leaves no empty section behind
        while parents and node == {}:
            parent, part = parents.pop()
            del parent[part]
            node = parent
        if value == default:
            continue
        if shapes_field:
            raise ConfigError(f"{source}: {key}={value!r} was removed in hybridneus 0.3 (only "
                              f"{default!r} remains); fit the scene again")
        notes.append(f"{key}={value!r} dropped")
    return out, notes


def _migrate(data: dict[str, Any]) -> tuple[dict[str, Any], list[str]]:
    """A 0.1 config dict in today's keys, and what was moved or dropped."""
    out = {k: (dict(v) if isinstance(v, dict) else v) for k, v in data.items()}
    notes = []
    for old, new in LEGACY_KEYS.items():
        section, name = old.split(".")
        if not isinstance(out.get(section), dict) or name not in out[section]:
            continue
        value = out[section].pop(name)
        if section == "train" and name == "warmup":
            continue
        if new is None:
            notes.append(f"{old} dropped")
            continue
        parts = new.split(".")
        node = out
        for part in parts[:-1]:
            node = node.setdefault(part, {})
        if old in _LEGACY_SWITCHES:
            node["enabled"] = bool(value and value > 0)
            if not value or value <= 0:
                notes.append(f"{old}={value} -> {'.'.join(parts[:-1])}.enabled=false")
                continue
        node[parts[-1]] = value
        notes.append(f"{old} -> {new}")
    train = out.get("train")
    if isinstance(train, dict) and isinstance(train.get("warmup"), int) and train["warmup"] > 1:
        train.pop("warmup")  # 0.1 counted warm-up steps; now it is a fraction
        notes.append("train.warmup (steps) dropped")
    return out, notes


def set_value(cfg: Config, key: str, value: Any) -> None:
    """Assign ``value`` to the dotted ``key`` (``train.lr``) with type checking.

    Raises:
        ConfigError: the key is unknown, names a whole section, or the value has the wrong type.
    """
    parts = key.split(".")
    obj: Any = cfg
    for i, part in enumerate(parts):
        fields = _section_fields(obj)
        if part not in fields:
            if key in LEGACY_KEYS:
                new = LEGACY_KEYS[key]
                hint = f"now {new}" if new else "removed in hybridneus 0.2"
                raise ConfigError(f"{key}: unknown key ({hint}; docs/training.md)")
            if key in REMOVED_KEYS:
                raise ConfigError(f"{key}: unknown key (removed in hybridneus 0.3, an experiment "
                                  "that did not become a default)")
            where = ".".join(parts[:i]) or "config"
            raise ConfigError(
                f"{key}: unknown key {part!r} in {where}; expected one of {sorted(fields)}"
            )
        child = getattr(obj, part)
        if i == len(parts) - 1:
            if dataclasses.is_dataclass(child):
                if not isinstance(value, dict):
                    raise ConfigError(f"{key}: is a section; set one of its keys ({key}.<name>)")
                for sub_key, sub_value in value.items():
                    set_value(cfg, f"{key}.{sub_key}", sub_value)
                return
            setattr(obj, part, _coerce(key, value, fields[part]))
            return
        if not dataclasses.is_dataclass(child):
            raise ConfigError(f"{key}: {'.'.join(parts[: i + 1])} is not a section")
        obj = child


def apply_overrides(cfg: Config, overrides: typing.Iterable[str]) -> Config:
    """Apply ``key=value`` strings (values parsed as YAML: ``0.005``, ``true``, ``[1, 2]``).

    Raises:
        ConfigError: malformed override, unknown key or wrong type.
    """
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"--set {item}: expected key=value, e.g. train.lr=0.005")
        key, text = item.split("=", 1)
        key = key.strip()
        if key == "preset":
            raise ConfigError("preset: choose it with --preset (or a Config), not --set")
        try:
            value = yaml.safe_load(text) if text.strip() else ""
        except yaml.YAMLError:
            value = text
        if value is None and text.strip().lower() not in ("null", "none", "~"):
            value = text
        if isinstance(value, str) and value.lower() == "none":
            value = None
        set_value(cfg, key, value)
    return cfg


def config_from_dict(data: dict[str, Any], source: str = "config") -> Config:
    """Build a :class:`Config` from a nested dict, starting from its ``preset`` defaults.

    Raises:
        ConfigError: ``data`` is not a mapping, or holds an unknown key / wrong type.
    """
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a mapping at the top level")
    preset = data.get("preset", "fast")
    if not isinstance(preset, str):
        raise ConfigError(f"{source}: preset: expected a string, got {preset!r}")
    cfg = preset_config(preset)
    data, notes = _migrate(data)
    data, dropped = _drop_removed(data, source)
    if notes:
        logging.getLogger("hybridneus").info(
            "%s: a hybridneus 0.1 config; %s", source, "; ".join(notes))
    if dropped:
        logging.getLogger("hybridneus").info(
            "%s: keys removed in hybridneus 0.3; %s", source, "; ".join(dropped))
    try:
        for key, value in data.items():
            if key == "preset":
                continue
            set_value(cfg, key, value)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from None
    return cfg


def save_config(cfg: Config, path: str | os.PathLike) -> None:
    """Write the resolved tree as YAML (atomically)."""
    from hybridneus.fileio import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_text(yaml.safe_dump(cfg.to_dict(), sort_keys=False))


#: Keys whose default moved after the key was added, with the value that does what the
#: software did before the key existed. A run's saved config that lacks one of them was
#: trained with that value, so :func:`load_config` with ``saved_run=True`` restores it
#: instead of today's default. A key belongs here once its default moves, and stays when it
#: moves back.
RUN_KEY_ORIGINS: dict[str, Any] = {}


def _has_key(data: dict[str, Any], key: str) -> bool:
    node: Any = data
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return False
        node = node[part]
    return True


def load_config(path: str | os.PathLike, saved_run: bool = False) -> Config:
    """Read a YAML written by :func:`save_config` (or by hand).

    ``saved_run``: the file is a run's ``config.yaml``; keys it lacks from
    :data:`RUN_KEY_ORIGINS` take the value the run was trained with.

    Raises:
        ConfigError: unreadable YAML, unknown key or wrong type (naming the file).
    """
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError(f"{path}: cannot read config ({first})") from None
    cfg = config_from_dict(data or {}, source=str(path))
    if saved_run and isinstance(data, dict):
        for key, value in RUN_KEY_ORIGINS.items():
            if not _has_key(data, key):
                set_value(cfg, key, value)
    return cfg
