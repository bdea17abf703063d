"""Checks of the values a fit cannot run with, and the device's default batch."""

from __future__ import annotations

import dataclasses
import typing
from typing import Any

from hybridneus.config.tree import Config
from hybridneus.errors import ConfigError

# A CPU step's cost grows with the batch; a GPU step's barely does (it is bound by kernel
# launches), so a larger batch is nearly free there.
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


def _fraction(v: float) -> bool:
    return 0.0 <= v <= 1.0


#: (key, test, what the value must be): checked by :func:`validate`.
_RULES: list[tuple[str, typing.Callable[[Any], bool], str]] = [
    ("grid.kind", lambda v: v in ("hash", "dense", "frequency"), "hash, dense or frequency"),
    ("grid.n_levels", lambda v: v >= 1, ">= 1"),
    ("grid.n_features", lambda v: v >= 1, ">= 1"),
    ("grid.base_resolution", lambda v: v >= 2, ">= 2"),
    ("grid.max_resolution", lambda v: v >= 2, ">= 2"),
    ("grid.start_levels", lambda v: v >= 1, ">= 1"),
    ("render.n_coarse", lambda v: v >= 1, ">= 1"),
    ("render.n_importance", lambda v: v >= 0, ">= 0"),
    ("render.up_rounds", lambda v: v >= 0, ">= 0"),
    ("render.up_base_inv_s", lambda v: v > 0, "> 0"),
    ("render.occupancy_resolution", lambda v: v >= 2, ">= 2"),
    ("render.occupancy_every", lambda v: v >= 1, ">= 1"),
    ("render.occupancy_band", lambda v: v > 0, "> 0"),
    ("render.occupancy_march", lambda v: v >= 1, ">= 1"),
    ("render.chunk", lambda v: v >= 1, ">= 1"),
    ("render.near_min", lambda v: v >= 0, ">= 0"),
    ("render.crop_softness", lambda v: v >= 0, ">= 0"),
    ("train.iters", lambda v: v >= 1, ">= 1"),
    ("train.minutes", lambda v: v >= 0, ">= 0 (0: no budget)"),
    ("train.n_rays", lambda v: v >= 0, ">= 0 (0: the device's default)"),
    ("train.lr", lambda v: v > 0, "> 0"),
    ("train.lr_variance", lambda v: v >= 0, ">= 0"),
    ("train.warmup", _fraction, "a fraction of training in [0, 1]"),
    ("train.decay_start", _fraction, "a fraction of training in [0, 1]"),
    ("train.decay_final", lambda v: v > 0, "> 0"),
    ("train.threads", lambda v: v >= 0, ">= 0"),
    ("train.seed", lambda v: 0 <= v < 2**32, "in [0, 2^32)"),
    ("train.log_every", lambda v: v >= 1, ">= 1"),
    ("train.preview_every", lambda v: v >= 0, ">= 0 (0: never)"),
    ("train.checkpoint_every", lambda v: v >= 0, ">= 0 (0: only at the end)"),
    ("train.checkpoint_seconds", lambda v: v >= 0, ">= 0 (0: by steps only)"),
    ("train.window", lambda v: v in ("per_iteration", "per_load"), "per_iteration or per_load"),
    ("train.supervision", lambda v: v in ("events", "rgb"), "'events' or 'rgb'"),
    ("loss.n_random_points", lambda v: v >= 0, ">= 0"),
    ("estimate.eps_max", lambda v: v >= 0, ">= 0 (0: no cap)"),
    ("estimate.eps_ease", _fraction, "a fraction of training in [0, 1]"),
    ("priors.hull.resolution", lambda v: v >= 8, ">= 8"),
    ("priors.hull.ramp", _fraction, "a fraction of training in [0, 1]"),
    ("priors.curvature.step", lambda v: v > 0, "> 0"),
    ("priors.curvature.end", _fraction, "a fraction of training in [0, 1]"),
    ("priors.sharpness_ceiling.per_cell", lambda v: v > 0, "> 0"),
    ("priors.sharpness_floor.at", lambda v: 0 < v <= 1, "a fraction of training in (0, 1]"),
    ("priors.sharpness_floor.delay", _fraction, "a fraction of training in [0, 1]"),
    ("priors.sharpness_floor.blend", _fraction, "a fraction of training in [0, 1]"),
    ("priors.collapse_guard.window", lambda v: v >= 1, ">= 1"),
    ("priors.collapse_guard.retries", lambda v: v >= 0, ">= 0"),
    ("priors.collapse_guard.lr_factor", lambda v: 0 < v <= 1, "in (0, 1]"),
    ("priors.collapse_guard.explode", lambda v: v == 0 or v > 1, "> 1 (0: off)"),
    ("refine.pose_smoothing", lambda v: v >= -1, ">= -1 (0: off, -1: chosen from the track)"),
    ("refine.pose_smoothing_order", lambda v: v >= 1, ">= 1"),
]


def _get(cfg: Config, key: str) -> Any:
    obj: Any = cfg
    for part in key.split("."):
        obj = getattr(obj, part)
    return obj


def validate(cfg: Config) -> Config:
    """Check the values a fit cannot run with (ranges, choices); return ``cfg`` unchanged.

    Every ``lambda_*`` and prior ``weight`` must be >= 0. Types are checked on assignment
    (:func:`set_value`); this checks what a type cannot say.

    Raises:
        ConfigError: the first bad value, naming its key.
    """
    for key, ok, what in _RULES:
        value = _get(cfg, key)
        if not ok(value):
            raise ConfigError(f"{key}: expected {what}, got {value!r}")
    _check_pose_smoothing(cfg.refine.pose_smoothing, cfg.refine.pose_smoothing_order)
    weights = [f"loss.{f.name}" for f in dataclasses.fields(cfg.loss)
               if f.name.startswith("lambda_")]
    weights += [f"priors.{f.name}.weight" for f in dataclasses.fields(cfg.priors)
                if hasattr(getattr(cfg.priors, f.name), "weight")]
    for key in weights:
        value = _get(cfg, key)
        if not (value >= 0 and value == value):
            raise ConfigError(f"{key}: expected a weight >= 0, got {value!r}")
    return cfg


def _check_pose_smoothing(window: int, order: int) -> None:
    """A window whose filter scipy cannot compute exactly would shrink the track instead of
    smoothing it (:func:`hybridneus.data.track.filter_is_exact`): refuse it before the load."""
    from hybridneus.data.track import exact_windows, filter_is_exact

    odd = window - (1 - window % 2)
    if odd < order + 2 or filter_is_exact(odd, order):
        return
    longest = max(exact_windows(order, odd - 2), default=0)
    raise ConfigError(f"refine.pose_smoothing: a {window}-view window of order {order} is "
                      f"numerically unstable; use at most {longest} views, or a lower "
                      "refine.pose_smoothing_order")
