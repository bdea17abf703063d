"""Library entry point: ``fit(dataset, config, callbacks) -> Field``.

Example:
    >>> import numpy as np, hybridneus.api as hn  # doctest: +SKIP
    >>> field = hn.fit("data/real/multimeter", "fast")  # doctest: +SKIP
    >>> field.sdf(np.zeros((1, 3), np.float32))  # numpy in, numpy out  # doctest: +SKIP
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hybridneus.config import Config, apply_overrides, preset_config, rays_per_step, validate
from hybridneus.errors import ConfigError, RunError

if TYPE_CHECKING:
    from hybridneus.model.field import HybridField


def _resolve_config(config: Config | str | None, overrides: Sequence[str]) -> Config:
    if config is None:
        cfg = preset_config("fast")
    elif isinstance(config, str):
        cfg = preset_config(config)
    elif isinstance(config, Config):
        import copy

        cfg = copy.deepcopy(config)
    else:
        raise ConfigError(f"config: expected a Config, a preset name or None, got {type(config)}")
    return apply_overrides(cfg, overrides)


def load_training_data(cfg: Config, dataset: Any = None):
    """The dataset a fit trains on (a path or an EventDataset), with ``cfg.data``'s overrides
    of its scene preset (the caller's dataset is never changed)."""
    from hybridneus.data import EventDataset, load_dataset
    from hybridneus.data import apply_overrides as preset_overrides

    if isinstance(dataset, EventDataset):
        if cfg.data.overrides():
            import copy

            dataset = copy.copy(dataset)
            dataset.preset = preset_overrides(dataset.preset, cfg.data.overrides())
        return dataset
    path = dataset if dataset is not None else cfg.data.path
    if not path:
        raise ConfigError("data.path: no dataset given")
    return load_dataset(path, overrides=cfg.data.overrides() or None, splits=cfg.data.split)


def fit(
    dataset: Any,
    config: Config | str | None = None,
    callbacks: Iterable = (),
    *,
    overrides: Sequence[str] = (),
    out: str | os.PathLike | None = None,
    resume: str | os.PathLike | None = None,
    device: str = "auto",
    progress: bool = False,
    started: float | None = None,
    report: bool = True,
) -> HybridField:
    """Train a hybrid NeuS field from an event dataset and return it.

    Args:
        dataset: dataset folder (EventNeRF layout) or a loaded
            :class:`hybridneus.data.EventDataset`; ignored when resuming (the run's
            ``data.path`` is used) unless given.
        config: a :class:`~hybridneus.config.Config`, a preset name (``fast``, ``quality``,
            ``eventneus``) or ``None`` (``fast``).
        callbacks: callables ``callback(trainer, logs)`` run after every step; raising
            ``KeyboardInterrupt`` stops training with a checkpoint.
        overrides: ``"section.key=value"`` strings applied on top of ``config``.
        out: runs root; a run folder ``<out>/<scene>-<timestamp>`` gets the config,
            checkpoints, metrics and previews. ``None`` writes nothing.
        resume: a run folder to continue from its last checkpoint (identical state).
        device: ``auto``, ``cpu``, ``cuda``.
        progress: show a progress bar on stderr.
        started: the ``time.perf_counter()`` from which a ``train.minutes`` budget counts
            (default: the call); the CLI passes its own start.
        report: write the run's ``report.html`` at the end (:mod:`hybridneus.report`; also
            after a resume). A report that cannot be written is a warning, never an error.

    Returns:
        The trained :class:`~hybridneus.model.field.HybridField` (a ``Field``); its
        ``sdf(points)`` / ``color(points, dirs)`` take numpy or torch. ``field.run_dir`` is
        the run folder (or ``None``) and ``field.interrupted`` says whether training stopped
        early on KeyboardInterrupt.

    Raises:
        ConfigError: bad config or override. DatasetError: bad dataset. RunError: bad resume.
    """
    trainer, logger = prepare(dataset, config, overrides, out, resume, device, started)
    field = trainer.fit(callbacks, logger, progress=progress)
    field.run_dir = logger.run_dir if logger is not None else None
    if report and logger is not None:
        _write_report(logger.run_dir)
    field.interrupted = trainer.interrupted
    field.trainer_step = trainer.step
    return field


def _write_report(run_dir: Path) -> None:
    """The run's report; any failure is logged as a warning (a report never fails a fit)."""
    import logging

    log = logging.getLogger("hybridneus")
    try:
        from hybridneus.report import write_report

        path = write_report(run_dir)
    except Exception as exc:  # whatever broke, the fit's work stands
        log.warning("%s: report not written (%s: %s)", run_dir, type(exc).__name__, exc)
        return
    log.info("report: %s", path)


def prepare(
    dataset: Any,
    config: Config | str | None,
    overrides: Sequence[str] = (),
    out: str | os.PathLike | None = None,
    resume: str | os.PathLike | None = None,
    device: str = "auto",
    started: float | None = None,
):
    """Build the :class:`~hybridneus.training.trainer.Trainer` and run logger of a fit.

    A new fit loads the dataset, runs the estimators and prepares the data the trainer
    receives (:mod:`hybridneus.data.estimate`), fixes the schedule's length (``train.iters``,
    or a ``train.minutes`` budget turned into steps by :mod:`hybridneus.training.budget`) and
    writes the scene record (:mod:`hybridneus.training.scene`); a resumed one reads that record
    back and prepares the same data from it, estimating nothing. ``started``: the
    ``time.perf_counter()`` at which the fit began (a budget counts from there; default: now).
    """
    import logging
    import time

    from hybridneus import __version__
    from hybridneus.data.estimate import estimate_scene, training_data
    from hybridneus.device import resolve_device
    from hybridneus.training import runs
    from hybridneus.training.runlog import RunLogger
    from hybridneus.training.scene import FILENAME, SceneRecord, save_pixel_offsets
    from hybridneus.training.trainer import Trainer, default_scene_name

    started = time.perf_counter() if started is None else started
    dev = resolve_device(device)
    log = logging.getLogger("hybridneus")
    if resume is not None:
        return _prepare_resume(Path(resume), dataset, config, overrides, dev)
    cfg = validate(_resolve_config(config, overrides))
    if out is not None:
        runs.check_runs_root(out)
    _set_threads(cfg)
    data = load_training_data(cfg, dataset)
    cfg.data.path = cfg.data.path or str(Path(data.root).resolve())
    found = estimate_scene(data, cfg.estimate, cfg.data, cfg.refine)
    record = SceneRecord(
        dataset=str(Path(data.root).resolve()), split=cfg.data.split,
        preset_source=data.preset_source, preset=found.dataset.preset.to_dict(),
        estimated=found.taken, eps_start=found.eps_start, steps=cfg.train.iters,
        n_rays=rays_per_step(cfg, dev), device=str(dev), version=__version__,
        pose_window=found.pose_window, hot_pixels=[list(xy) for xy in found.hot_pixels],
    )
    offsets = found.dataset[cfg.data.split].pixel_offset
    trainer = Trainer(cfg, training_data(found.dataset, cfg, found.pose_window, dev), record,
                      dev)
    logger = None
    if out is not None:
        logger = RunLogger(runs.new_run_dir(out, default_scene_name(data.root)), Path(out))
        if offsets is not None:
            record.pixel_offsets = save_pixel_offsets(logger.run_dir, offsets)
    if cfg.train.minutes > 0:
        _fix_budget(trainer, logger, started + 60.0 * cfg.train.minutes)
    if logger is not None:
        logger.start(trainer)
        if not (logger.run_dir / runs.CHECKPOINT).is_file():
            # A step-0 checkpoint: a run killed before its first scheduled save can still
            # be resumed, without loading and estimating again.
            logger.checkpoint(trainer)
        log.info("run: %s (config.yaml, %s)", logger.run_dir, FILENAME)
    for line in record.lines():
        log.info(line)
    return trainer, logger


#: A budget that leaves fewer steps than this is refused rather than trained on.
MIN_BUDGET_STEPS = 10
#: Seconds a budget keeps, beyond the final checkpoint, for what follows the last step (the
#: training curve, the scene record, the command's exit): a fit re-planned to its deadline
#: otherwise ends a second past its budget.
FINISH_SECONDS = 2.0


def _set_threads(cfg: Config) -> None:
    """``train.threads`` for everything the fit computes, its data preparation included."""
    if cfg.train.threads > 0:
        import torch

        torch.set_num_threads(cfg.train.threads)


def _fix_budget(trainer, logger, end: float) -> None:
    """Turn the time to ``end`` into the trainer's step count (recorded), re-planned to the
    pace of its steps as it goes and stopped at ``end`` should the last steps run over. With
    a logger, the step-0 preview and checkpoint are written first and timed, so that their
    share of the budget is known."""
    import time

    from hybridneus.training.budget import REPLAN_SHARE, BudgetPlan, budget_steps
    from hybridneus.training.runlog import VIEWS

    t = trainer.cfg.train
    overhead, save, finish = 0.0, 0.0, FINISH_SECONDS
    if logger is not None:
        tick = time.perf_counter()
        logger.checkpoint(trainer)
        save = time.perf_counter() - tick
        if t.checkpoint_every > 0:
            overhead += save / t.checkpoint_every
        if t.preview_every > 0:
            tick = time.perf_counter()
            logger.preview(trainer)
            shot = time.perf_counter() - tick
            overhead += shot / t.preview_every
            finish += VIEWS * shot  # the report's view windows, rendered at the end
    # the final checkpoint, curve, view windows and record come after the last step
    left = end - time.perf_counter() - 2.0 * save - finish
    steps, how, costs = budget_steps(trainer, max(left, 0.0), overhead)
    if steps < MIN_BUDGET_STEPS:
        spent = t.minutes * 60.0 - (end - time.perf_counter())
        raise ConfigError(f"train.minutes: {t.minutes:g} min leave time for {steps} steps after "
                          f"{spent:.0f} s of loading and probing; give a longer budget or "
                          "--iters")
    trainer.total_steps = trainer.record.steps = steps
    trainer.record.steps_from = how
    trainer.deadline = end - save - finish
    trainer.plan = BudgetPlan(costs, trainer.deadline, REPLAN_SHARE * max(left, 0.0),
                              clock=trainer.clock)


def _same_dataset(run_dir: Path, recorded: str, given: Any) -> None:
    """Refuse to continue a run on another dataset than the one it was fitted on (a moved
    dataset, whose recorded folder is gone, is taken as the same)."""
    if given is None or not isinstance(given, str | os.PathLike):
        return
    was, now = Path(recorded), Path(given)
    if was.exists() and was.resolve() != now.resolve():
        raise RunError(f"{run_dir}: was fitted on {was}; resuming it on {now} would train one "
                       f"field on two datasets (fit {now} without --resume, or leave DATA out)")


def _prepare_resume(run_dir: Path, dataset: Any, config: Any, overrides: Sequence[str], dev):
    """A trainer that continues ``run_dir`` from its last checkpoint, on the scene record's
    values (nothing is estimated again)."""
    from hybridneus.data import load_dataset
    from hybridneus.data.estimate import training_data, with_split
    from hybridneus.training import runs
    from hybridneus.training.runlog import RunLogger
    from hybridneus.training.scene import FILENAME, SceneRecord
    from hybridneus.training.trainer import Trainer

    if config is not None and not isinstance(config, str | Config):
        raise ConfigError("config: expected a Config or a preset name")
    state = runs.load_checkpoint(run_dir)
    saved = runs.load_run_config(run_dir)
    cfg = validate(apply_overrides(runs.load_run_config(run_dir), overrides))
    if cfg.train.minutes > 0 and cfg.train.minutes != saved.train.minutes:
        raise ConfigError("train.minutes: a resumed run keeps its schedule; give --iters to "
                          "change its length")
    record = SceneRecord.load(run_dir / FILENAME)
    _same_dataset(run_dir, record.dataset, dataset)
    path = dataset if dataset is not None else record.dataset
    _set_threads(cfg)
    data = load_dataset(path, overrides=record.preset_overrides(), splits=record.split)
    if record.hot_pixels:
        from hybridneus.data.hot import without_pixels

        data = with_split(data, without_pixels(data[record.split], record.hot_pixels))
    if record.pixel_offsets:
        import dataclasses

        from hybridneus.training.scene import load_pixel_offsets

        split = data[record.split]
        offsets = load_pixel_offsets(run_dir, record, split.width * split.height)
        data = with_split(data, dataclasses.replace(split, pixel_offset=offsets))
    trainer = Trainer(cfg, training_data(data, cfg, record.pose_window, dev), record, dev)
    try:
        trainer.load_state_dict(state)
    except (RuntimeError, KeyError, ValueError) as exc:
        first = (str(exc).splitlines() or [type(exc).__name__])[0]
        raise RunError(f"{run_dir / runs.CHECKPOINT}: cannot resume ({first})") from None
    asked = any(str(o).replace(" ", "").startswith("train.iters=") for o in overrides or ())
    if asked and cfg.train.iters <= trainer.step:
        raise ConfigError(
            f"train.iters {cfg.train.iters}: {run_dir} is already at step {trainer.step}; the "
            "count is of all steps, so ask for more")
    if cfg.train.iters != saved.train.iters:
        trainer.total_steps = record.steps = cfg.train.iters
        record.steps_from = "train.iters (changed on resume)"
    logging.getLogger("hybridneus").info("resuming %s from step %d of %d", run_dir,
                                         trainer.step, trainer.total_steps)
    trainer.deadline = None
    record.stopped_at = None  # the resumed run goes on to the schedule's end
    logger = RunLogger(run_dir, run_dir.parent, resume_step=trainer.step)
    logger.start(trainer)
    return trainer, logger
