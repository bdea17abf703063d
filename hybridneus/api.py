"""Library entry point: ``fit(dataset, config, callbacks) -> Field``.

Example:
    >>> import numpy as np, hybridneus.api as hn  # doctest: +SKIP
    >>> field = hn.fit("data/real/multimeter", "fast")  # doctest: +SKIP
    >>> field.sdf(np.zeros((1, 3), np.float32))  # numpy in, numpy out  # doctest: +SKIP
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from hybridneus.config import Config, apply_overrides, preset_config
from hybridneus.errors import ConfigError, RunError


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
    """Load ``dataset`` (path or EventDataset) with the config's preset overrides.

    With ``data.offset_from_events`` and no polarity offset stated by the path, ``scene.json``
    or the config, the offset is the one the events' own balance implies
    (:mod:`hybridneus.data.balance`) instead of the fallback's 0; a stated offset that the
    events contradict gets a warning. The offset taken is written into ``cfg.data``.
    With ``data.denoise``, events that no nearby pixel confirms are taken for sensor noise and
    left out of the training split (:mod:`hybridneus.data.denoise`); everything after, the
    crop and the tonemap eps included, sees the kept events.
    With ``data.crop_from_events`` and no crop set in the config, the preset's crop is shrunk
    to the events' visual hull (:func:`hybridneus.data.hull.event_hull_crop`); the crop taken
    (shrunk or kept) is written into ``cfg.data``, so the run's config records it and a
    resume reuses it instead of outlining the object again.
    """
    from hybridneus.data import EventDataset, load_dataset
    from hybridneus.data import apply_overrides as preset_overrides

    if isinstance(dataset, EventDataset):
        if cfg.data.overrides():
            import copy

            dataset = copy.copy(dataset)  # never change the caller's preset
            dataset.preset = preset_overrides(dataset.preset, cfg.data.overrides())
        if not cfg.data.path:
            cfg.data.path = str(dataset.root)
    else:
        path = dataset if dataset is not None else cfg.data.path
        if not path:
            raise ConfigError("data.path: no dataset given")
        cfg.data.path = str(Path(path).resolve())
        dataset = load_dataset(
            path, overrides=cfg.data.overrides() or None, splits=cfg.data.split
        )
    estimate_offset = cfg.data.offset_from_events and cfg.data.polarity_offset is None
    # one pass of the noise filter serves the offset estimate and data.denoise
    denoised = _noise_filtered(cfg, dataset) if estimate_offset or cfg.data.denoise else None
    if estimate_offset:
        dataset = _offset_from_events(cfg, dataset, denoised)
    if cfg.data.denoise:
        dataset = _denoise(cfg, dataset, denoised)
    crop_keys = ("crop_r", "crop_y_min", "crop_y_max")
    if cfg.data.crop_from_events and all(getattr(cfg.data, k) is None for k in crop_keys):
        dataset = _crop_from_events(cfg, dataset, crop_keys)
    if cfg.data.eps_from_events and cfg.data.tonemap_eps is None:
        dataset = _eps_from_events(cfg, dataset)
    return dataset


def _noise_filtered(cfg: Config, dataset: Any) -> tuple[Any, Any]:
    """:func:`hybridneus.data.denoise.denoised_split` of the training split at
    ``data.denoise_slab``: ``(kept split, report)``."""
    from hybridneus.data.denoise import denoised_split

    if not cfg.data.denoise_slab > 0:
        raise ConfigError(f"data.denoise_slab: expected a number of views > 0, got "
                          f"{cfg.data.denoise_slab}")
    return denoised_split(dataset[cfg.data.split], cfg.data.denoise_slab)


def _offset_from_events(cfg: Config, dataset: Any, denoised: tuple[Any, Any]) -> Any:
    """``dataset`` (a copy, when the offset changes) with the polarity offset its events imply
    (:func:`hybridneus.data.balance.polarity_balance`, on the ``denoised`` training split), if
    nothing stated one; a stated offset is kept, with a warning when the events disagree with
    it (:meth:`~hybridneus.data.balance.PolarityBalance.disagrees`)."""
    import copy
    import logging

    from hybridneus.data import apply_overrides as preset_overrides
    from hybridneus.data.balance import polarity_balance

    log = logging.getLogger("hybridneus")
    p = dataset.preset
    balance = polarity_balance(dataset[cfg.data.split], cfg.data.denoise_slab, denoised)
    log.info(balance.line())
    suggested = balance.suggested()
    if suggested is None:
        return dataset
    if "polarity_offset" in dataset.stated:
        if balance.disagrees(p.polarity_offset):
            msg = (f"polarity offset {p.polarity_offset:g} (preset from the "
                   f"{dataset.preset_source}), but the events imply {suggested:g}; --set "
                   f"data.polarity_offset={suggested:g} uses theirs")
            log.warning(msg)
            dataset = copy.copy(dataset)
            dataset.notes = [*dataset.notes, msg]
        return dataset
    cfg.data.polarity_offset = suggested
    if suggested == p.polarity_offset:
        return dataset
    msg = (f"polarity offset {suggested:g} from the events' balance (the preset from the "
           f"{dataset.preset_source} guessed {p.polarity_offset:g}; "
           "data.offset_from_events=false keeps the guess)")
    log.info(msg)
    dataset = copy.copy(dataset)
    dataset.preset = preset_overrides(p, {"polarity_offset": suggested})
    dataset.notes = [*dataset.notes, msg]
    return dataset


def _denoise(cfg: Config, dataset: Any, denoised: tuple[Any, Any]) -> Any:
    """``dataset`` (a copy, when anything goes) with the training split's noise events
    removed: the ``denoised`` split of :func:`_noise_filtered`."""
    import copy
    import logging

    split, report = denoised
    msg = f"{report.line()} (data.denoise)"
    logging.getLogger("hybridneus").info(msg)
    if split is dataset[cfg.data.split]:
        return dataset
    dataset = copy.copy(dataset)
    dataset.splits = {**dataset.splits, cfg.data.split: split}
    dataset.notes = [*dataset.notes, msg]
    return dataset


def _eps_from_events(cfg: Config, dataset: Any) -> Any:
    """``dataset`` (a copy) with its preset's tonemap eps lowered to ``data.eps_max`` and,
    where the events ask for larger log-brightness changes than that eps can render, to the
    eps that can (:mod:`hybridneus.data.contrast`). The eps taken is written into
    ``cfg.data`` so that a resume reuses it."""
    import copy
    import logging

    from hybridneus.data import apply_overrides as preset_overrides
    from hybridneus.data.contrast import event_extent, loss_eps

    p = dataset.preset
    change = event_extent(dataset[cfg.data.split], p)
    eps, why = loss_eps(p.tonemap_eps, change, cfg.data.eps_max)
    cfg.data.tonemap_eps = eps
    if eps == p.tonemap_eps:
        return dataset
    cfg.data.eps_start = float(p.tonemap_eps)
    dataset = copy.copy(dataset)
    dataset.preset = preset_overrides(p, {"tonemap_eps": eps})
    msg = (f"tonemap eps {eps:g} (preset {p.tonemap_eps:g}): {why} (data.eps_from_events=false "
           "keeps the preset's)")
    logging.getLogger("hybridneus").info(msg)
    dataset.notes = [*dataset.notes, msg]
    return dataset


def _crop_from_events(cfg: Config, dataset: Any, crop_keys: tuple[str, ...]) -> Any:
    """``dataset`` (a copy) with its preset's crop shrunk to the event hull, if it shrinks."""
    import copy
    import logging

    from hybridneus.data import apply_overrides as preset_overrides
    from hybridneus.data.hull import NOTHING_OUTLINED, event_hull_crop

    p = dataset.preset
    crop = (p.crop_r, p.crop_y_min, p.crop_y_max)
    log = logging.getLogger("hybridneus")
    log.info("crop: outlining the object from the events (data.crop_from_events) ...")
    tight = event_hull_crop(dataset[cfg.data.split], crop)
    if tight is None or all(abs(a - b) < 1e-6 for a, b in zip(tight, crop, strict=True)):
        why = NOTHING_OUTLINED if tight is None else "it is inside the events' hull"
        log.info(f"crop: keeping the preset's (r {p.crop_r:g}, y {p.crop_y_min:g} .. "
                 f"{p.crop_y_max:g}): {why}")
        # recorded all the same, so that a resume does not outline the object again
        for key, value in zip(crop_keys, crop, strict=True):
            setattr(cfg.data, key, float(value))
        return dataset
    for key, value in zip(crop_keys, tight, strict=True):
        setattr(cfg.data, key, round(float(value), 4))
    values = {k: getattr(cfg.data, k) for k in crop_keys}
    dataset = copy.copy(dataset)
    dataset.preset = preset_overrides(p, values)
    msg = (f"crop from the events' visual hull: r {values['crop_r']}, y {values['crop_y_min']}"
           f" .. {values['crop_y_max']} (preset: r {p.crop_r:g}, y {p.crop_y_min:g} .. "
           f"{p.crop_y_max:g}; data.crop_from_events=false keeps the preset's)")
    log.info(msg)
    dataset.notes = [*dataset.notes, msg]
    return dataset


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
):
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

    Returns:
        The trained :class:`~hybridneus.model.field.HybridField` (a ``Field``); its
        ``sdf(points)`` / ``color(points, dirs)`` take numpy or torch. ``field.run_dir`` is
        the run folder (or ``None``) and ``field.interrupted`` says whether training stopped
        early on KeyboardInterrupt.

    Raises:
        ConfigError: bad config or override. DatasetError: bad dataset. RunError: bad resume.
    """
    trainer, logger = prepare(dataset, config, overrides, out, resume, device)
    field = trainer.fit(callbacks, logger, progress=progress)
    field.run_dir = logger.run_dir if logger is not None else None
    field.interrupted = trainer.interrupted
    field.trainer_step = trainer.step
    return field


def prepare(
    dataset: Any,
    config: Config | str | None,
    overrides: Sequence[str] = (),
    out: str | os.PathLike | None = None,
    resume: str | os.PathLike | None = None,
    device: str = "auto",
):
    """Build the :class:`~hybridneus.training.trainer.Trainer` and run logger of a fit."""
    from hybridneus.device import resolve_device
    from hybridneus.training import runs
    from hybridneus.training.runlog import RunLogger
    from hybridneus.training.trainer import Trainer, default_scene_name

    dev = resolve_device(device)
    state = None
    if resume is not None:
        run_dir = Path(resume)
        state = runs.load_checkpoint(run_dir)
        cfg = runs.load_run_config(run_dir)
        cfg = apply_overrides(cfg, overrides)
        if config is not None and not isinstance(config, str | Config):
            raise ConfigError("config: expected a Config or a preset name")
        data = load_training_data(cfg, dataset)
        trainer = Trainer(cfg, data, dev)
        try:
            trainer.load_state_dict(state)
        except (RuntimeError, KeyError, ValueError) as exc:
            first = (str(exc).splitlines() or [type(exc).__name__])[0]
            raise RunError(f"{run_dir / runs.CHECKPOINT}: cannot resume ({first})") from None
        if cfg.train.iters != state["config"]["train"]["iters"]:
            trainer.total_steps = max(trainer.step + 1, cfg.train.iters)
        runs_root = run_dir.parent
        logger = RunLogger(run_dir, runs_root, resume_step=trainer.step)
        logger.start(trainer)
        return trainer, logger
    cfg = _resolve_config(config, overrides)
    data = load_training_data(cfg, dataset)
    trainer = Trainer(cfg, data, dev)
    logger = None
    if out is not None:
        run_dir = runs.new_run_dir(out, default_scene_name(data.root))
        logger = RunLogger(run_dir, Path(out))
        logger.start(trainer)
    return trainer, logger
