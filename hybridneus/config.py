"""Every training default in one dataclass tree, with presets, YAML and dotted overrides.

``Config`` holds one sub-tree per component (``grid``, ``field``, ``render``, ``loss``,
``train``, ``data``). Presets (``fast``, ``quality``, ``eventneus``) are functions that
return a full ``Config``; the CLI applies ``--set section.key=value`` overrides on top, and
each run saves the resolved tree as ``config.yaml``. An unknown key or a value of the wrong
type raises :class:`~hybridneus.errors.ConfigError` naming the key.
"""

from __future__ import annotations

import dataclasses
import os
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from hybridneus.errors import ConfigError


@dataclass
class GridConfig:
    """Position encoding of the SDF network: a feature grid, or NeRF-style frequencies."""

    kind: str = "hash"  # hash | dense | frequency
    n_levels: int = 16  # grid levels
    n_features: int = 2  # features per level
    log2_table_size: int = 17  # hash table size T = 2**log2_table_size per level
    base_resolution: int = 16  # coarsest level's resolution
    max_resolution: int = 512  # finest level's resolution (per-level scale derived from it)
    start_levels: int = 4  # levels active at step 0 (coarse-to-fine)
    levels_full_at: float = 0.4  # fraction of training at which all levels are active
    n_frequencies: int = 8  # kind=frequency: number of octave bands (EventNeuS: 8 to 9)
    frequency_start: int = 0  # kind=frequency: bands active at step 0 (N_fmin)
    frequency_anneal_at: float = 0.5  # kind=frequency: fraction of training at all bands
    domain: str = "volume"  # grid span: crop (a cube around the crop box) or volume ([-1, 1]^3)
    domain_margin: float = 0.3  # domain=crop: cube half-side = (1 + this) x the box's largest half


@dataclass
class FieldConfig:
    """SDF head, colour head, NeuS variance and background."""

    sdf_hidden: int = 64  # width of the SDF head's hidden layers
    sdf_layers: int = 1  # number of hidden layers in the SDF head
    sdf_skip: list[int] = field(default_factory=list)  # layers that re-receive the input
    feature_dim: int = 15  # geometric features passed from the SDF head to the colour head
    softplus_beta: float = 100.0  # Softplus sharpness in the SDF head
    init_radius: float = 0.5  # initial sphere radius (world units; capped by the crop radius)
    prefit_steps: int = 0  # extra Adam steps fitting the initial sphere (0: geometric init only)
    color_hidden: int = 64  # width of the colour head's hidden layers
    color_layers: int = 2  # number of hidden layers in the colour head
    color_activation: str = "relu"  # relu | softplus
    sh_degree: int = 4  # spherical-harmonics degree of the view encoding (degree**2 values)
    color_position_frequencies: int = 0  # PE(x) bands fed to the colour head (0: none)
    inv_s_init: float = 0.3  # NeuS variance parameter v; inv_s = exp(10 v)
    learned_background: bool = False  # learn the background colour instead of the preset's
    color_init: str = "grey"  # grey (the sigmoid midpoint) or contrast (away from the background)
    color_init_distance: float = 0.5  # color_init=contrast: start this far from the background


@dataclass
class RenderConfig:
    """Ray sampling and NeuS compositing."""

    n_coarse: int = 24  # samples per ray placed uniformly (over occupied space)
    n_importance: int = 16  # samples per ray added by NeuS up-sampling (split over rounds)
    up_rounds: int = 2  # NeuS up-sampling rounds, at inv_s = up_base_inv_s * 2**round
    up_base_inv_s: float = 64.0  # sharpness of the first up-sampling round (doubles per round)
    occupancy: bool = True  # skip empty space with an occupancy grid refreshed from the SDF
    occupancy_resolution: int = 64  # cells per axis over the crop box
    occupancy_every: int = 16  # steps between occupancy refreshes
    occupancy_band: float = 3.0  # cells within band / inv_s (+ half a cell diagonal) are kept
    occupancy_march: int = 128  # look-ups per ray when placing samples in occupied space
    crop_softness: float = 0.01  # width of the soft crop-cylinder edge (world units)
    cos_anneal_at: float = 0.0  # fraction of training over which NeuS's cos term anneals
    chunk: int = 65536  # points per chunk when rendering without gradients
    near_min: float = 0.05  # smallest ray start distance from the camera


@dataclass
class LossConfig:
    """Weights ``lambda_<name>`` of each loss term (0 switches a term off)."""

    lambda_event: float = 1.0  # event loss (EventNeRF/EventNeuS, Bayer-masked log difference)
    lambda_eikonal: float = 0.1  # (|grad sdf| - 1)^2 on samples and random volume points
    lambda_curvature: float = 0.05  # normal variation at the rendered surface points
    lambda_sparsity: float = 0.0  # exp(-tau |sdf|) on random points in the crop (anti-floater)
    lambda_outside: float = 1.0  # relu(-sdf) at random points outside the crop (no caps there)
    lambda_hull: float = 1.0  # relu(-sdf) at random points the events' visual hull calls empty
    hull_resolution: int = 96  # hull grid points along the crop box's longest side
    hull_grow: int = 0  # hull voxels added around the hull before the rest counts as empty
    hull_start: int = 0  # steps without the hull term at the start
    hull_ramp: int = 300  # steps after hull_start over which the hull weight grows from 0 to 1
    sparsity_tau: float = 50.0  # decay of the sparsity term (1/world units)
    lambda_background_matter: float = 0.0  # thin matter that looks like the background
    background_matter_sigma: float = 0.1  # colour distance at which that term fades (exp(-(d/s)^2))
    background_matter_start: float = 0.25  # fraction of training before that term starts
    n_random_points: int = 1024  # random volume points per step for Eikonal/regularisers
    random_box_margin: float = 0.15  # random points fill the crop box grown by this fraction
    curvature_step: float = 0.01  # finite-difference step of the curvature term (world units)
    curvature_end: float = 0.5  # 0: constant curvature weight; else it falls to 0 linearly by
    # this fraction of training
    lambda_rgb: float = 1.0  # squared colour error (only with train.supervision = rgb)


@dataclass
class TrainConfig:
    """Optimiser, budget and logging."""

    iters: int = 2000  # steps (a --minutes budget re-estimates this from the measured speed)
    minutes: float = 0.0  # wall-clock budget in minutes (0: no limit; stops at iters)
    n_rays: int = 0  # pixels per step, each at both window ends (0: 256 on CPU, 1024 on CUDA)
    lr: float = 0.01  # grid and heads
    lr_variance: float = 0.01  # NeuS variance parameter (sharpness)
    inv_s_floor: float = 200.0  # lowest inv_s allowed by inv_s_floor_at (0: no floor)
    inv_s_floor_at: float = 0.5  # fraction of training at which the floor reaches inv_s_floor
    inv_s_floor_min_steps: int = 1500  # ... but not before this step
    inv_s_floor_delay: int = 100  # steps without a floor at the start
    inv_s_floor_blend: int = 100  # steps after the delay over which the floor rises to its curve
    betas: list[float] = field(default_factory=lambda: [0.9, 0.99])  # Adam betas
    adam_eps: float = 1e-15  # Adam epsilon
    warmup: int = 50  # linear learning-rate warm-up steps
    decay_start: float = 0.5  # fraction of training after which the lr decays exponentially
    decay_final: float = 0.1  # lr multiplier reached at the last step
    seed: int = 0  # seeds torch, the ray jitter and the event-window sampler
    collapse_opacity: float = 0.01  # a window's mean opacity below this: restore (0: off)
    collapse_window: int = 25  # steps per opacity mean, and between the restorable states
    collapse_retries: int = 3  # restores before the run goes on empty
    collapse_healthy: float = 0.1  # a window's mean opacity from this: a restore point
    collapse_lr_factor: float = 0.5  # learning-rate multiplier after each restore
    threads: int = 0  # torch CPU threads (0: leave torch's default)
    log_every: int = 10  # steps between metrics.csv rows / TensorBoard scalars
    preview_every: int = 500  # steps between preview PNGs (0: never)
    checkpoint_every: int = 500  # steps between checkpoints (and always at the end)
    window: str = "per_iteration"  # event-window sampling: per_iteration | per_load
    supervision: str = "events"  # events, or rgb: the rgb/ frames (2 * n_rays pixels per step)


@dataclass
class DataConfig:
    """The dataset and overrides of its scene preset (``None``: the preset's value)."""

    path: str = ""  # dataset folder (set by the CLI / fit())
    split: str = "train"  # split to train on
    threshold: float | None = None  # contrast threshold C
    polarity_offset: float | None = None  # added to each event's polarity
    max_window: int | None = None  # longest event window, in views
    cyclic: bool | None = None  # windows wrap around (360-degree captures)
    neg_ratio: float | None = None  # fraction of rays drawn uniformly (not from events)
    tonemap_eps: float | None = None  # eps in log(c^2.2 + eps)
    crop_r: float | None = None  # crop-cylinder radius around the y axis
    crop_y_min: float | None = None  # crop-cylinder bottom
    crop_y_max: float | None = None  # crop-cylinder top
    background: list[float] | None = None  # RGB in [0, 1] behind the object
    denoise: bool = False  # targets from the events that nearby pixels confirm (see docs)
    denoise_slab: float = 2.0  # denoise: time slab, in views, within which company counts
    crop_from_events: bool = True  # shrink the crop to the events' visual hull (if no crop set)
    offset_from_events: bool = True  # polarity offset from the events if none is stated
    eps_from_events: bool = True  # cap tonemap_eps (eps_max, and what the events' changes need)
    eps_max: float = 1e-3  # eps_from_events: the largest tonemap eps the loss uses
    eps_start: float | None = None  # eps at step 0 (eps_from_events sets it when it lowers eps)
    eps_anneal_steps: int = 500  # steps over which eps goes from eps_start to tonemap_eps

    def overrides(self) -> dict[str, Any]:
        """The preset overrides that are set, as ``{name: value}`` for the data module."""
        skip = {"path", "split", "denoise", "denoise_slab", "crop_from_events",
                "offset_from_events", "eps_from_events", "eps_max", "eps_start",
                "eps_anneal_steps"}
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name not in skip and value is not None:
                out[f.name] = tuple(value) if isinstance(value, list) else value
        return out


@dataclass
class Config:
    """The full training configuration (what ``config.yaml`` in a run folder holds)."""

    preset: str = "fast"
    grid: GridConfig = dataclasses.field(default_factory=GridConfig)
    field: FieldConfig = dataclasses.field(default_factory=FieldConfig)
    render: RenderConfig = dataclasses.field(default_factory=RenderConfig)
    loss: LossConfig = dataclasses.field(default_factory=LossConfig)
    train: TrainConfig = dataclasses.field(default_factory=TrainConfig)
    data: DataConfig = dataclasses.field(default_factory=DataConfig)

    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict of primitives (YAML- and ``weights_only``-safe)."""
        return dataclasses.asdict(self)


# ---------------------------------------------------------------------------------------
# Presets


def _fast() -> Config:
    return Config(preset="fast")


def _quality() -> Config:
    cfg = Config(preset="quality")
    cfg.grid.log2_table_size = 19
    cfg.grid.max_resolution = 1024
    cfg.render.n_coarse = 32
    cfg.render.n_importance = 32
    cfg.render.up_rounds = 4
    cfg.render.occupancy_resolution = 96
    cfg.train.iters = 8000
    cfg.train.n_rays = 512
    return cfg


def _eventneus() -> Config:
    """The paper's architecture: deep Softplus MLP on annealed positional encoding."""
    cfg = Config(preset="eventneus")
    cfg.grid.kind = "frequency"
    cfg.grid.n_frequencies = 8
    cfg.grid.frequency_start = 0
    cfg.grid.frequency_anneal_at = 0.5
    cfg.field.sdf_hidden = 256
    cfg.field.sdf_layers = 8
    cfg.field.sdf_skip = [4]
    cfg.field.feature_dim = 256
    cfg.field.color_hidden = 256
    cfg.field.color_layers = 4
    cfg.field.color_position_frequencies = 8
    cfg.train.lr = 5e-4
    cfg.train.lr_variance = 1e-3
    cfg.train.inv_s_floor = 0.0  # the paper learns s freely
    cfg.loss.lambda_hull = 0.0  # the paper has no silhouette prior
    cfg.loss.lambda_curvature = 0.0  # nor a smoothness prior
    cfg.train.warmup = 100
    return cfg


PRESETS: dict[str, typing.Callable[[], Config]] = {
    "fast": _fast,
    "quality": _quality,
    "eventneus": _eventneus,
}


def preset_config(name: str) -> Config:
    """Return a fresh :class:`Config` for preset ``name`` (``fast``, ``quality``, ``eventneus``).

    Raises:
        ConfigError: the preset is unknown.
    """
    if name not in PRESETS:
        raise ConfigError(f"--preset {name}: unknown preset; expected one of {sorted(PRESETS)}")
    return PRESETS[name]()


# ---------------------------------------------------------------------------------------
# Typed assignment


# A CPU step's cost grows with the batch; a GPU step's barely does (it is bound by kernel
# launches), and 1,024 pixels gave the best 2-minute H100 fits (docs/benchmarks/training.md).
N_RAYS_BY_DEVICE = {"cpu": 256, "cuda": 1024}


def rays_per_step(cfg: Config, device: Any) -> int:
    """``train.n_rays``, or for 0 the device's default (256 on a CPU, 1024 on CUDA).

    Raises:
        ConfigError: ``train.n_rays`` is negative.
    """
    n = cfg.train.n_rays
    if n < 0:
        raise ConfigError(f"train.n_rays: expected >= 0 (0: the device's default), got {n}")
    if n > 0:
        return n
    return N_RAYS_BY_DEVICE.get(str(device).split(":")[0], N_RAYS_BY_DEVICE["cpu"])


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
        raise ConfigError(f"{key}: expected a number, got {value!r}")
    if tp is str:
        if isinstance(value, str):
            return value
        raise ConfigError(f"{key}: expected a string, got {value!r}")
    raise ConfigError(f"{key}: unsupported type {_type_name(tp)}")


def _section_fields(obj: Any) -> dict[str, Any]:
    hints = typing.get_type_hints(type(obj))
    return {f.name: hints[f.name] for f in dataclasses.fields(obj)}


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


def load_config(path: str | os.PathLike) -> Config:
    """Read a YAML written by :func:`save_config` (or by hand).

    Raises:
        ConfigError: unreadable YAML, unknown key or wrong type (naming the file).
    """
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ConfigError(f"{path}: cannot read config ({first})") from None
    return config_from_dict(data or {}, source=str(path))


def config_table() -> list[tuple[str, str, str, str]]:
    """Rows ``(key, type, default of fast, comment)`` for the documentation table."""
    import inspect

    rows = []
    cfg = Config()
    for section in dataclasses.fields(cfg):
        sub = getattr(cfg, section.name)
        if not dataclasses.is_dataclass(sub):
            rows.append((section.name, "str", repr(sub), "preset the tree started from"))
            continue
        comments = _field_comments(inspect.getsource(type(sub)))
        for name, tp in _section_fields(sub).items():
            rows.append(
                (
                    f"{section.name}.{name}",
                    _type_name(tp),
                    repr(getattr(sub, name)),
                    comments.get(name, ""),
                )
            )
    return rows


def _field_comments(source: str) -> dict[str, str]:
    out = {}
    for line in source.splitlines():
        stripped = line.strip()
        if ":" in stripped and "#" in stripped and not stripped.startswith(("#", '"')):
            name = stripped.split(":", 1)[0].strip()
            out[name] = stripped.split("#", 1)[1].strip()
    return out
