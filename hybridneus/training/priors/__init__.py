"""The priors of a fit: one module per prior, each switched by ``priors.<name>.enabled``.

- ``hull`` (:mod:`.hull`): a constant background, so the events' visual hull is free space;
- ``curvature`` (:mod:`.curvature`): smooth surfaces where the events are silent;
- ``sharpness_floor`` (:mod:`.sharpness`): a solid, opaque object;
- ``sharpness_ceiling`` (:mod:`.sharpness`): a surface placed no finer than the grid's cells;
- ``collapse_guard`` (:mod:`.collapse`): the object fills part of most views.

:func:`build_priors` makes the enabled ones; the trainer calls their hooks
(:class:`~hybridneus.training.priors.base.Prior`) and knows none of them by name.
"""

from __future__ import annotations

import math

from hybridneus.config import Config
from hybridneus.training.priors.base import Prior, RandomPoints, StepContext
from hybridneus.training.priors.collapse import CollapseGuard
from hybridneus.training.priors.curvature import CurvaturePrior
from hybridneus.training.priors.hull import HullPrior
from hybridneus.training.priors.sharpness import SharpnessCeiling, SharpnessFloor


def build_priors(cfg: Config, field, free_space, aabb) -> list[Prior]:
    """The priors ``cfg.priors`` enables, in the order their hooks run.

    Args:
        cfg: the fit's config.
        field: the field being trained (fresh: the guard's first restore point).
        free_space: the hull's free space (:class:`hybridneus.data.hull.FreeSpace`, prepared
            with the data), or ``None``: no hull prior.
        aabb: (6,) the crop box.
    """
    p = cfg.priors
    out: list[Prior] = []
    if p.hull.enabled and free_space is not None:
        out.append(HullPrior(p.hull, free_space))
    if p.curvature.enabled:
        out.append(CurvaturePrior(p.curvature))
    if p.sharpness_floor.enabled:
        out.append(SharpnessFloor(p.sharpness_floor, math.exp(10.0 * cfg.field.inv_s_init)))
    if p.sharpness_ceiling.enabled:
        side = float((aabb[3:] - aabb[:3]).max())
        out.append(SharpnessCeiling(p.sharpness_ceiling, side / cfg.grid.max_resolution))
    if p.collapse_guard.enabled:
        out.append(CollapseGuard(p.collapse_guard, field))
    return out


__all__ = ["CollapseGuard", "CurvaturePrior", "HullPrior", "Prior", "RandomPoints",
           "SharpnessCeiling", "SharpnessFloor", "StepContext", "build_priors"]
