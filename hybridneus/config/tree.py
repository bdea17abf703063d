"""The config tree: one dataclass per component, and the presets that fill it."""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from typing import Any

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

    @property
    def opened_at(self) -> float:
        """The fraction of training at which coarse-to-fine has opened everything: every
        grid level, or for kind=frequency every band."""
        return self.frequency_anneal_at if self.kind == "frequency" else self.levels_full_at


@dataclass
class FieldConfig:
    """SDF head, colour head, NeuS variance and background."""

    sdf_hidden: int = 64  # width of the SDF head's hidden layers
    sdf_layers: int = 1  # number of hidden layers in the SDF head
    sdf_skip: list[int] = field(default_factory=list)  # layers that re-receive the input
    feature_dim: int = 15  # geometric features passed from the SDF head to the colour head
    softplus_beta: float = 100.0  # Softplus sharpness in the SDF head
    init_radius: float = 0.5  # initial sphere radius (world units; capped by the crop radius)
    color_hidden: int = 64  # width of the colour head's hidden layers
    color_layers: int = 2  # number of hidden layers in the colour head
    sh_degree: int = 4  # spherical-harmonics degree of the view encoding (degree**2 values)
    color_position_frequencies: int = 0  # PE(x) bands fed to the colour head (0: none)
    inv_s_init: float = 0.3  # NeuS variance parameter v; inv_s = exp(10 v)


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
    chunk: int = 65536  # points per chunk when rendering without gradients
    near_min: float = 0.05  # smallest ray start distance from the camera


@dataclass
class LossConfig:
    """Weights ``lambda_<name>`` of the loss terms every fit has (0 switches a term off).

    The priors, each with its own weight and switch, are under ``priors``.
    """

    lambda_event: float = 1.0  # event loss (EventNeRF/EventNeuS, Bayer-masked log difference)
    lambda_rgb: float = 1.0  # squared colour error (only with train.supervision = rgb)
    lambda_eikonal: float = 0.1  # (|grad sdf| - 1)^2 on samples and random volume points
    lambda_outside: float = 1.0  # relu(-sdf) at random points outside the crop (no caps there)
    n_random_points: int = 1024  # random volume points per step for Eikonal and the priors
    random_box_margin: float = 0.15  # random points fill the crop box grown by this fraction


@dataclass
class TrainConfig:
    """Optimiser, length and logging. Schedules are fractions of training."""

    iters: int = 2000  # steps, unless train.minutes sets a budget
    minutes: float = 0.0  # wall-clock budget of the whole fit (0: none); turned into steps
    n_rays: int = 0  # pixels per step, each at both window ends (0: 256 on CPU, 1024 on CUDA)
    lr: float = 0.01  # grid and heads
    lr_variance: float = 0.01  # NeuS variance parameter (sharpness)
    betas: list[float] = field(default_factory=lambda: [0.9, 0.99])  # Adam betas
    adam_eps: float = 1e-15  # Adam epsilon
    # A tenth: warmed up over 0.005, fields emptied or ran away in sharpness while only the
    # coarse levels were open (commit 733ccb8, result lines in suite.jsonl).
    warmup: float = 0.1  # fraction of training over which the learning rate warms up
    decay_start: float = 0.5  # fraction of training after which the lr decays exponentially
    decay_final: float = 0.1  # lr multiplier reached at the last step
    seed: int = 0  # seeds torch, the ray jitter and the event-window sampler
    threads: int = 0  # torch CPU threads (0: leave torch's default)
    log_every: int = 10  # steps between metrics.csv rows / TensorBoard scalars
    preview_every: int = 500  # steps between preview PNGs (0: never)
    checkpoint_every: int = 500  # steps between checkpoints (and always at the end)
    checkpoint_seconds: float = 60.0  # a checkpoint at least this often, wall seconds (0: off)
    window: str = "per_iteration"  # event-window sampling: per_iteration | per_load
    supervision: str = "events"  # events, or rgb: the rgb/ frames (2 * n_rays pixels per step)


@dataclass
class DataConfig:
    """The dataset and overrides of its scene preset (``None``: the preset's value).

    A value set here is used as given: the fit estimates none of it from the events.
    """

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
    width: int | None = None  # image width in pixels (the files do not say it)
    height: int | None = None  # image height in pixels

    def overrides(self) -> dict[str, Any]:
        """The preset overrides that are set, as ``{name: value}`` for the data module."""
        out = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            if f.name not in ("path", "split") and value is not None:
                out[f.name] = tuple(value) if isinstance(value, list) else value
        return out


@dataclass
class EstimateConfig:
    """What a fit may take from the events when neither the config nor the dataset states it.

    Each estimate is recorded with how it was made in the run's ``scene.yaml``
    (docs/data.md, "What a fit estimates from the events").
    """

    hot_pixels: bool = True  # leave out pixels firing far above their neighbours (data.hot)
    denoise: bool = True  # train on the events the noise filter keeps (data.denoise)
    crop: bool = True  # shrink the crop cylinder to the events' visual hull (no data.crop_*)
    threshold: bool = False  # C (and ON/OFF) the rgb/ frames imply, if no C is stated
    polarity_offset: bool = True  # the offset the events' balance implies, if none is stated
    pixel_offsets: bool = True  # with polarity_offset: each pixel's own, from its balance
    tonemap_eps: bool = True  # cap eps at eps_max and at what the events' changes need
    eps_max: float = 1e-3  # tonemap_eps: the largest eps the loss uses
    eps_ease: float = 0.05  # fraction of training over which eps eases in from the preset's


@dataclass
class HullPrior:
    """The events' visual hull marks free space.

    Assumes a constant background, so that only the object fires events: a point that most
    views see outside the outline of their events is empty, and the term pushes the SDF
    there positive. It keeps matter out of space no event defends (under a flat object seen
    from above). Costs one hull build at the start (about a second on two cores) and a
    lookup per random point. Switch it off when the background fires events too (a
    cluttered room, a moving background).
    """

    enabled: bool = True
    weight: float = 1.0  # weight of relu(-sdf) at the random points the hull calls free
    resolution: int = 96  # hull grid points along the crop box's longest side
    ramp: float = 0.03  # fraction of training over which the weight grows from 0


@dataclass
class CurvaturePrior:
    """Smooth surfaces where the events say nothing.

    Assumes surfaces are smooth at the scale of ``step``: the term penalises the change of
    the normal between each rendered surface point and a point ``step`` away. A flat face of
    one colour fires events only along its outline, and without the term it wrinkles. Costs
    one extra SDF gradient pass on two points per ray. Its weight falls to 0 by ``end``, so
    that late training gives fine detail back to the data; switch it off for objects made
    of wires or fine detail (a cage, fur, foliage): it smooths a wire a few pixels thick away.
    """

    enabled: bool = True
    weight: float = 0.05  # weight of the mean squared normal change
    step: float = 0.01  # distance to the shifted point (world units)
    end: float = 0.5  # fraction of training at which the weight has fallen to 0 (0: constant)


@dataclass
class SharpnessFloor:
    """A lower bound on the NeuS sharpness ``inv_s`` that rises over training.

    Assumes the object is solid: where events leave the geometry ambiguous (faint surfaces,
    thin parts) the learned sharpness can sink, and the fit turns into a thick,
    semi-transparent envelope. The floor grows geometrically from the initial sharpness to
    ``floor`` at ``at``; the sharpness stays free to rise above it. It costs nothing. Switch
    it off for semi-transparent or fuzzy objects.
    """

    enabled: bool = True
    floor: float = 200.0  # the final lower bound of inv_s
    at: float = 0.5  # fraction of training at which the floor reaches its value
    delay: float = 0.01  # fraction of training at the start without a floor
    blend: float = 0.01  # fraction after the delay over which the floor rises to its curve


@dataclass
class SharpnessCeiling:
    """An upper bound on the NeuS sharpness ``inv_s``, from the finest grid cell.

    Assumes the surface cannot be placed more precisely than a fraction of the finest grid
    cell (the crop box's longest side over ``grid.max_resolution``). Where the events favour
    ever crisper edges, the learned sharpness can run away past that, and the sampler's
    occupancy band (``render.occupancy_band / inv_s``) shrinks below the field's own error:
    cells the surface crosses are skipped, rays miss the object and the field empties. Two of
    116 benchmark fits ran away so (to 31,000 and 1,000,000) and failed; none of the others
    ended above 890. Costs nothing; binds only a runaway. Switch it off to let the sharpness
    grow freely (the paper's NeuS).
    """

    enabled: bool = True
    per_cell: float = 4.0  # the bound is per_cell / (finest grid cell): about 2200 for fast


@dataclass
class CollapseGuard:
    """Bring back an earlier state when the field empties.

    Assumes the object fills part of most views: a mean rendered opacity below ``opacity``
    over ``window`` steps means the surface has gone (an early overshoot, pushed back by the
    crop and hull terms), and nothing would bring it back. The guard then reloads the last
    healthy state with a lower learning rate, as it does after a step whose loss is NaN,
    infinite or ``explode`` times the median of the window before (far above a healthy
    fit's spikes). Costs a copy of the field every ``window``
    steps (12 MiB for ``fast``). Switch it off for scenes that really are nearly empty in
    every view.
    """

    enabled: bool = True
    opacity: float = 0.01  # mean opacity over a window below this: restore
    window: int = 25  # steps per opacity mean, and between restore points
    retries: int = 3  # restores before the run goes on as it is
    healthy: float = 0.1  # a window's mean opacity from this on makes a restore point
    lr_factor: float = 0.5  # learning-rate multiplier after each restore
    explode: float = 100.0  # a loss this many times the last window's median diverged (0: off)


@dataclass
class PriorsConfig:
    """Assumptions about the object that the events alone do not support (docs/training.md,
    "Priors"). Each has one ``enabled`` switch."""

    hull: HullPrior = dataclasses.field(default_factory=HullPrior)
    curvature: CurvaturePrior = dataclasses.field(default_factory=CurvaturePrior)
    sharpness_floor: SharpnessFloor = dataclasses.field(default_factory=SharpnessFloor)
    sharpness_ceiling: SharpnessCeiling = dataclasses.field(default_factory=SharpnessCeiling)
    collapse_guard: CollapseGuard = dataclasses.field(default_factory=CollapseGuard)


@dataclass
class RefineConfig:
    """What a capture states imperfectly, mended before the fit (docs/training.md, "Jittery
    poses"). Off by default: an exact track has nothing to mend."""

    # views: filter the given track's jitter before the fit (0: off)
    pose_smoothing: int = 0  # window of the track's polynomial fit, views (odd; -1: from the track)
    pose_smoothing_order: int = 5  # degree of that polynomial


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
    estimate: EstimateConfig = dataclasses.field(default_factory=EstimateConfig)
    priors: PriorsConfig = dataclasses.field(default_factory=PriorsConfig)
    refine: RefineConfig = dataclasses.field(default_factory=RefineConfig)

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
    cfg.priors.sharpness_floor.enabled = False  # the paper learns s freely
    cfg.priors.sharpness_ceiling.enabled = False
    cfg.priors.hull.enabled = False  # the paper has no silhouette prior
    cfg.priors.curvature.enabled = False  # nor a smoothness prior
    cfg.train.warmup = 0.01
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
