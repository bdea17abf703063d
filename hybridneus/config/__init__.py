"""Every training default in one dataclass tree, with presets, YAML and dotted overrides.

``Config`` holds one sub-tree per component (``grid``, ``field``, ``render``, ``loss``,
``train``, ``data``), what a fit may estimate from the events (``estimate``) and the priors
(``priors.<name>``, each with an ``enabled`` switch). Presets (``fast``, ``quality``,
``eventneus``) are functions that return a full ``Config``; the CLI applies
``--set section.key=value`` overrides on top, and each run saves the tree it was given as
``config.yaml``. The tree is an input: nothing the fit estimates or measures is written into
it (those values go to the run's ``scene.yaml``, :mod:`hybridneus.training.scene`). An
unknown key or a value of the wrong type or range raises
:class:`~hybridneus.errors.ConfigError` naming the key.
"""

from hybridneus.config.checks import N_RAYS_BY_DEVICE, rays_per_step, validate
from hybridneus.config.overrides import (
    LEGACY_KEYS,
    apply_overrides,
    config_from_dict,
    load_config,
    save_config,
    set_value,
)
from hybridneus.config.table import config_markdown, config_table
from hybridneus.config.tree import (
    PRESETS,
    CollapseGuard,
    Config,
    CurvaturePrior,
    DataConfig,
    EstimateConfig,
    FieldConfig,
    GridConfig,
    HullPrior,
    LossConfig,
    PriorsConfig,
    RefineConfig,
    RenderConfig,
    SharpnessCeiling,
    SharpnessFloor,
    TrainConfig,
    preset_config,
)

__all__ = [
    "LEGACY_KEYS", "N_RAYS_BY_DEVICE", "PRESETS", "CollapseGuard", "Config", "CurvaturePrior",
    "DataConfig", "EstimateConfig", "FieldConfig", "GridConfig", "HullPrior", "LossConfig",
    "PriorsConfig", "RefineConfig", "RenderConfig", "SharpnessCeiling", "SharpnessFloor",
    "TrainConfig", "apply_overrides",
    "config_from_dict", "config_markdown", "config_table", "load_config", "preset_config",
    "rays_per_step", "save_config", "set_value", "validate",
]
