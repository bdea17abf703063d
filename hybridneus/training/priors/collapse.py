"""``priors.collapse_guard``: bring back an earlier state when the field empties
(:class:`hybridneus.config.CollapseGuard`).

Early in a fit the surface can overshoot: grown until nearly every ray is opaque, it is pushed
back by the crop and hull terms, Adam's momentum carries it on, and within ten steps the SDF
is positive on every sample (seen on small objects on a turntable). Nothing then has a
gradient: an empty field renders the background at both ends of every window, and the
occupancy grid stops sampling.

The guard averages the rendered opacity over ``window`` steps. A window whose mean reaches
``healthy`` makes the field at its end a restore point. When a mean falls below ``opacity``
the guard drops the newest restore point (it may already be on its way out), loads the one
before, clears the optimiser's moments, scales the learning rate by ``lr_factor`` and warms
it up again. A field that empties again before a new restore point goes back one point
further each time, down to the state the run started from. The batches after a restore are
new draws, so the run does not replay its collapse. After ``retries`` restores it lets the
run go on.

A step whose loss is NaN or infinite (its update has already poisoned the parameters), or
``explode`` times the median loss of the ``window`` steps before it (a finite blow-up: a
learning rate far too high, a threshold far too low), goes back to the newest restore point
the same way; once the retries are spent, the trainer stops with a message.
"""

from __future__ import annotations

import logging
import math
import statistics
from collections import deque
from typing import Any

import torch

from hybridneus.config import CollapseGuard as GuardConfig
from hybridneus.training.priors.base import Prior
from hybridneus.training.schedules import ramp


class CollapseGuard(Prior):
    """See the module docstring.

    Args:
        cfg: ``priors.collapse_guard``.
        field: the field being trained (its state at construction is the first restore
            point).

    Attributes:
        scale: the learning-rate multiplier the restores have left.
        warm_from: the step of the last restore (its warm-up starts there).
        restores: restores so far.
    """

    name = "collapse_guard"

    def __init__(self, cfg: GuardConfig, field: torch.nn.Module) -> None:
        self.cfg = cfg
        self.field = field
        self.scale = 1.0
        self.warm_from = 0
        self.restores = 0
        self._opacity: list[float] = []
        self._losses: deque[float] = deque(maxlen=max(cfg.window, 1))
        self._points: list[tuple[int, dict[str, torch.Tensor]]] = [(0, _copy(field))]

    def lr_scale(self, trainer) -> float:
        if not self.restores:
            return 1.0
        p_end = trainer.progress(trainer.step + 1)
        return self.scale * ramp(p_end, trainer.progress(self.warm_from), trainer.cfg.train.warmup)

    def after_logs(self, trainer, logs: dict[str, float]) -> None:
        c = self.cfg
        logs["restores"] = float(self.restores)
        diverged = self._diverged(logs["loss/total"])
        if diverged:
            # a step that produced a NaN, an inf or a blow-up has already poisoned the
            # parameters: go back to the newest restore point (the trainer stops once the
            # retries are spent)
            logs["diverged"] = 1.0
            if self.restores < c.retries:
                # the window before stays the yardstick: a blow-up that comes back is caught
                self._restore(trainer, self._points[-1], diverged)
                logs["restores"] = float(self.restores)
                logs["rolled_back"] = 1.0
            return
        self._losses.append(logs["loss/total"])
        self._opacity.append(logs["opacity"])
        if len(self._opacity) < c.window:
            return
        mean = sum(self._opacity) / len(self._opacity)
        self._opacity = []
        points = self._points
        if mean >= c.opacity:
            if mean >= c.healthy:
                points.append((trainer.step, _copy(trainer.field)))
                keep = c.retries + 2  # the first point (the run's start) is the last resort
                if len(points) > keep:
                    del points[1:len(points) - keep + 1]
            return
        if self.restores >= c.retries:
            return
        if len(points) > 1:
            points.pop()
        self._restore(trainer, points[-1],
                      f"the field emptied (mean opacity {mean:.4f} over {c.window} steps)")
        logs["restores"] = float(self.restores)

    def _diverged(self, loss: float) -> str | None:
        """Why the step's loss counts as diverged, or ``None``."""
        if not math.isfinite(loss):
            return f"the loss became {loss}"
        explode = self.cfg.explode
        if explode > 0 and len(self._losses) == self._losses.maxlen:
            median = statistics.median(self._losses)
            if median > 0 and loss > explode * median:
                return (f"the loss jumped to {loss:.4g}, {loss / median:.0f}x the median of "
                        f"the {len(self._losses)} steps before")
        return None

    def _restore(self, trainer, point: tuple[int, dict[str, torch.Tensor]], why: str) -> None:
        back_to, state = point
        trainer.field.load_state_dict(state)
        trainer.optimizer.state.clear()
        trainer.refresh_occupancy()
        self.restores += 1
        self.scale *= self.cfg.lr_factor
        self.warm_from = trainer.step
        logging.getLogger("hybridneus").warning(
            "step %d: %s; restored its state of step %d with the learning rate x%g (restore "
            "%d of at most %d; priors.collapse_guard)",
            trainer.step, why, back_to, self.scale, self.restores, self.cfg.retries,
        )

    def state_dict(self) -> dict[str, Any]:
        return {"lr_scale": self.scale, "warm_from": self.warm_from, "restores": self.restores}

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore the learning-rate state; the field as loaded (at ``state["step"]``, which
        the trainer adds) is the one restore point."""
        self.scale = float(state.get("lr_scale", 1.0))
        self.warm_from = int(state.get("warm_from", 0))
        self.restores = int(state.get("restores", 0))
        self._opacity = []
        self._losses.clear()
        self._points = [(int(state.get("step", 0)), _copy(self.field))]


def _copy(field: torch.nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in field.state_dict().items()}
