"""The training loop: batches -> NeuS renders -> the objective -> Adam -> the priors' hooks.

One :class:`Trainer` owns the field, the samplers, the optimiser, the priors and every random
state, so that :meth:`Trainer.state_dict` / :meth:`Trainer.load_state_dict` resume a run
exactly (:mod:`hybridneus.training.state`). What it trains on is fixed before it is built:
the config (an input), the prepared data (:class:`hybridneus.data.estimate.TrainingData`:
the split as trained on, the hull's free space) and the scene record (what the fit
estimated, the schedule's length, the pixels per step; :mod:`hybridneus.training.scene`).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import torch

from hybridneus.config import Config
from hybridneus.data.crop import crop_aabb
from hybridneus.data.estimate import TrainingData
from hybridneus.data.frames import FrameBatch
from hybridneus.data.windows import RayBatch
from hybridneus.errors import RunError
from hybridneus.model.field import HybridField
from hybridneus.rendering.occupancy import OccupancyGrid
from hybridneus.rendering.renderer import render_rays
from hybridneus.rendering.sampling import NeuSSampler
from hybridneus.training import schedules
from hybridneus.training.objective import Objective, batch_rays
from hybridneus.training.priors import StepContext, build_priors
from hybridneus.training.scene import SceneRecord
from hybridneus.training.state import load_trainer_state, trainer_state

Callback = Callable[["Trainer", dict[str, float]], None]
log = logging.getLogger("hybridneus")


def make_optimizer(field: HybridField, cfg: Config) -> torch.optim.Adam:
    """Adam over the field, the NeuS variance in a group of its own learning rate."""
    t = cfg.train
    others = [q for name, q in field.named_parameters() if name != "variance"]
    groups = [{"params": others, "lr": t.lr, "name": "field"},
              {"params": [field.variance], "lr": t.lr_variance, "name": "variance"}]
    kwargs = dict(betas=tuple(cfg.train.betas), eps=cfg.train.adam_eps)
    try:
        return torch.optim.Adam(groups, fused=True, **kwargs)
    except (RuntimeError, TypeError, ValueError):
        return torch.optim.Adam(groups, **kwargs)


class Trainer:
    """Event-supervised training of a :class:`HybridField` on one dataset split.

    Args:
        cfg: the full configuration (read only).
        data: the prepared data (:func:`hybridneus.data.estimate.training_data`), whose
            dataset's preset holds the values of ``record`` (see :func:`hybridneus.api.prepare`).
        record: the scene record: schedule length, pixels per step, the eps to ease from.
        device: torch device.

    Attributes:
        field: the model being trained.
        priors: the enabled priors (:mod:`hybridneus.training.priors`).
        step: completed steps.
        total_steps: the schedule's length (:attr:`timeline`'s ``total``).
        timeline: progress by step (:class:`~hybridneus.training.schedules.Timeline`); a
            budget re-plan changes its length without moving the progress reached.
        clock: the wall clock the deadline is read from (``time.perf_counter``).
        deadline: a :attr:`clock` value by which :meth:`fit` stops (a wall-clock budget), or
            ``None``.
        plan: a :class:`~hybridneus.training.budget.BudgetPlan` that re-plans the length of a
            budgeted fit to the pace its steps run at, or ``None``.
        interrupted: set when :meth:`fit` stopped on KeyboardInterrupt.
        stopped_early: set when :meth:`fit` stopped at the deadline before the last step.
    """

    def __init__(self, cfg: Config, data: TrainingData, record: SceneRecord,
                 device: torch.device | str = "cpu") -> None:
        from hybridneus.data import EventWindowSampler

        self.cfg, self.record, self.data = cfg, record, data
        self.device = torch.device(device)
        self.split = data.split
        self.preset = data.dataset.preset
        torch.manual_seed(cfg.train.seed)
        p = self.preset
        self.scene = {
            "background": [float(c) for c in p.background],
            "crop": [float(p.crop_r), float(p.crop_y_min), float(p.crop_y_max)],
            "tonemap_eps": float(p.tonemap_eps),
            "grey": p.mosaic == "mono",  # a monochrome sensor: the field renders grey
            "frame": data.frame,  # meshes go back to a recording's own frame
            # where the cameras stood: meshing fills the space none of them saw
            "cameras": self.split.c2w[:, :3, 3].astype(float).tolist(),
        }
        self.field = HybridField(cfg.grid, cfg.field, tuple(self.scene["background"]),
                                 tuple(self.scene["crop"]), grey=self.scene["grey"]
                                 ).to(self.device)
        self.aabb = crop_aabb(self.field.crop.cpu()).to(self.device)
        r = cfg.render
        self.occupancy = OccupancyGrid(self.aabb, r.occupancy_resolution).to(self.device)
        self.sampler = NeuSSampler(
            self.aabb, n_coarse=r.n_coarse, n_importance=r.n_importance,
            up_rounds=r.up_rounds, up_base_inv_s=r.up_base_inv_s,
            occupancy=self.occupancy if r.occupancy else None, n_march=r.occupancy_march,
            near_min=r.near_min, chunk=r.chunk,
        )
        self.windows = EventWindowSampler(self.split, self.preset, seed=cfg.train.seed,
                                          window=cfg.train.window, device=self.device)
        self.frames = None
        if cfg.train.supervision == "rgb":
            from hybridneus.data.frames import FrameRaySampler

            self.frames = FrameRaySampler(self.split, self.preset.width, self.preset.height,
                                          seed=cfg.train.seed, device=self.device)
        self.generator = torch.Generator(device=self.device).manual_seed(cfg.train.seed + 1)
        self.optimizer = make_optimizer(self.field, cfg)
        # the rates the schedule scales (a loaded optimizer state brings its last ones)
        self.base_lrs = [g["lr"] for g in self.optimizer.param_groups]
        self.params = [q for g in self.optimizer.param_groups for q in g["params"]]
        self.priors = build_priors(cfg, self.field, data.free_space, self.aabb)
        self.objective = Objective(cfg.loss, self.priors, self.aabb)
        self.step = 0
        self.timeline = schedules.Timeline(max(1, record.steps))
        self.elapsed = 0.0
        self.clock: Callable[[], float] = time.perf_counter
        self.deadline: float | None = None
        self.plan = None
        self.interrupted = self.stopped_early = False
        self.occupied_fraction = 1.0

    @property
    def total_steps(self) -> int:
        return self.timeline.total

    @total_steps.setter
    def total_steps(self, total: int) -> None:
        self.timeline.total = int(total)

    def progress(self, step: int) -> float:
        """The schedules' progress at ``step`` (:class:`.schedules.Timeline`)."""
        return self.timeline.progress(step)

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume (:func:`hybridneus.training.state.trainer_state`)."""
        return trainer_state(self)

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a state written by :meth:`state_dict`."""
        load_trainer_state(self, state)

    # ------------------------------------------------------------------ one step

    def tonemap_eps(self) -> float:
        """The event loss's eps at this step: the record's ``eps_start`` eased geometrically
        into the scene's over ``estimate.eps_ease``. A small eps from the first step lets the
        largest event targets pull hard on dark colours before there is a surface to colour,
        and a 256-pixel xylophone fit lost its surface by step 100 that way."""
        p = self.progress(self.step)
        return schedules.eased(p, self.record.eps_start, self.scene["tonemap_eps"],
                               self.cfg.estimate.eps_ease)

    def refresh_occupancy(self) -> None:
        """Mark the occupancy grid's cells near the field's surface (sampling skips the rest)."""
        r = self.cfg.render
        if r.occupancy:
            self.occupied_fraction = self.occupancy.update(
                self.field.raw_sdf, float(self.field.inv_s().detach()), r.occupancy_band, r.chunk)

    def next_batch(self) -> RayBatch | FrameBatch:
        """The step's pixels: those of one event window, or (RGB supervision) a frame's."""
        if self.frames is not None:
            return self.frames.sample(2 * self.record.n_rays)
        return self.windows.sample(self.record.n_rays).to(self.device)

    def _set_learning_rate(self) -> float:
        t = self.cfg.train
        p_end = self.progress(self.step + 1)
        factor = schedules.lr_factor(p_end, t.warmup, t.decay_start, t.decay_final)
        for prior in self.priors:
            factor *= prior.lr_scale(self)
        for group, base in zip(self.optimizer.param_groups, self.base_lrs, strict=True):
            group["lr"] = base * factor
        return factor

    def train_step(self) -> dict[str, float]:
        """Run one optimisation step; return the logged scalars."""
        t_start = time.perf_counter()
        cfg = self.cfg
        p = self.progress(self.step)
        factor = self._set_learning_rate()
        self.field.update_step(self.timeline.position(self.step), self.total_steps)
        if self.step % max(cfg.render.occupancy_every, 1) == 0:
            self.refresh_occupancy()
        batch = self.next_batch()
        origins, dirs = batch_rays(batch)
        out = render_rays(self.field, origins, dirs, self.sampler, self.generator, True,
                          cfg.render.crop_softness)
        ctx = StepContext(self.field, out, origins, dirs, p, self.generator, batch)
        terms = self.objective(ctx, batch, self.tonemap_eps())
        total = sum(weight * value for weight, value in terms.values())
        self.optimizer.zero_grad(set_to_none=True)
        # Only the trained parameters: the sample points are leaves that require grad (for
        # the Eikonal term's d sdf / dx), and a plain backward() would also compute their
        # gradient, through the grid's interpolation weights, for nothing.
        total.backward(inputs=[q for q in self.params if q.requires_grad])
        self.optimizer.step()
        for prior in self.priors:
            prior.after_update(self, p)
        self.step += 1
        scalars = {f"loss/{k}": v for k, (_, v) in terms.items()}
        scalars.update({"loss/total": total, "inv_s": self.field.inv_s(),
                        "opacity": out.opacity.mean()})
        # One device-to-host copy for all of them: on a GPU each float() would wait for the
        # device. The copy also ends the step's GPU work, so step_seconds counts it.
        values = torch.stack([v.detach().float().reshape(()) for v in scalars.values()])
        logs = dict(zip(scalars, values.tolist(), strict=True))
        for prior in self.priors:
            prior.after_logs(self, logs)
        seconds = time.perf_counter() - t_start
        self.elapsed += seconds
        logs.update({"lr": cfg.train.lr * factor, "levels": float(self.field.active_levels()),
                     "occupied": self.occupied_fraction, "step_seconds": seconds})
        return logs

    def trained_poses(self):
        """(n_views, 4, 4) training poses as trained where they differ from the data's (a
        smoothed track), or ``None``."""
        return self.split.c2w if self.data.smoothed else None

    # ------------------------------------------------------------------ loop

    def fit(self, callbacks: Iterable[Callback] = (), run=None,
            progress: bool = True) -> HybridField:
        """Train until ``total_steps`` (or the deadline); return the field.

        Args:
            callbacks: called as ``callback(trainer, logs)`` after every step.
            run: a :class:`~hybridneus.training.runlog.RunLogger` (checkpoints, metrics,
                previews), or ``None`` for no files.
            progress: show a rich progress bar on stderr.

        A ``KeyboardInterrupt`` (Ctrl-C, or raised by a callback) saves a checkpoint at the
        last completed step, sets :attr:`interrupted` and returns the field.

        Raises:
            RunError: the loss stopped being finite.
        """
        from hybridneus.progress import make_progress

        callbacks = list(callbacks)
        with make_progress("it", disable=not progress) as bar:
            task = bar.add_task("fit", total=self.total_steps, completed=self.step)
            if self.plan is not None:
                self.plan.start(self.step, self.progress(self.step))
            try:
                while self.step < self.total_steps:
                    if self.deadline is not None and self.clock() >= self.deadline:
                        self.stopped_early = True
                        log.warning("stopped at step %d of %d: the time budget ran out (the "
                                    "machine ran slower than measured at the start)",
                                    self.step, self.total_steps)
                        break
                    logs = self.train_step()
                    if run is not None:
                        run.after_step(self, logs)
                    for cb in callbacks:
                        cb(self, logs)
                    if self.plan is not None:
                        self.plan.after_step(self)
                    bar.update(task, completed=self.step, total=self.total_steps,
                               info=f"loss {logs['loss/total']:.4g} inv_s {logs['inv_s']:.0f} "
                               f"lv {int(logs['levels'])}")
                    diverged = logs.get("diverged") or not math.isfinite(logs["loss/total"])
                    if diverged and not logs.get("rolled_back"):
                        raise RunError(f"training diverged at step {self.step} (loss "
                                       f"{logs['loss/total']:.4g}) after {_restores(self)} "
                                       "roll-back(s); lower train.lr or check data.threshold")
            except KeyboardInterrupt:
                self.interrupted = True
        if run is not None:
            run.finish(self)
        self.field.eval()
        return self.field


def _restores(trainer) -> int:
    return sum(int(getattr(p, "restores", 0)) for p in trainer.priors)


def default_scene_name(path: str | Path) -> str:
    """Run-folder prefix from a dataset path (its last component)."""
    return Path(path).resolve().name or "scene"
