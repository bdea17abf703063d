"""What a fit takes from the data when nothing states it (threshold, polarity offset, crop,
eps, the track's smoothing window), and the data it trains on, prepared from those.

Each estimator is switched by ``estimate.<name>`` (:class:`hybridneus.config.EstimateConfig`)
and never overrides a value the config sets (``data.<name>``). The sensor-noise filter runs
once and serves the offset estimate; the event silhouettes are outlined once and shared by
the crop and the hull prior's free space (they are cached on the event stream). The values
taken, with one line each on how, go into the run's ``scene.yaml``; ``hybridneus info``
prints the same. :func:`training_data` then prepares what the trainer receives: the training
split with its track smoothed (``refine.pose_smoothing``) and the free space of the events'
visual hull (``priors.hull``). A resumed fit prepares the same from its ``scene.yaml``,
estimating nothing again.

- **Hot pixels** (:mod:`hybridneus.data.hot`): pixels firing far more than their neighbours
  are left out of the training split before anything else is estimated (one hot pixel can
  set the eps estimate, and its events ask for a brightness change no surface makes).
- **Sensor noise** (:mod:`hybridneus.data.denoise`): the fit trains on the events the
  background-activity filter keeps (``estimate.denoise``). Rays are drawn among the pixels
  that fired in a window; on a noisy sensor nearly every pixel has, and most rays would go
  to the empty background. A clean stream is kept whole.
- **Threshold** (:mod:`hybridneus.data.threshold`, off by default): the ON and OFF thresholds
  whose replay of the sensor over the split's ``rgb/`` frames fires the stream's events, when
  neither the path, ``scene.json`` nor the config states C, a tonemap eps is stated (the
  frames' log mapping) and the replay explains the events (the events alone fix only the
  ON/OFF ratio). Without usable frames the preset's C stays, and a line says so.
- **Polarity offset** (:mod:`hybridneus.data.balance`): the median per-pixel polarity balance
  after the noise filter, when neither the path, ``scene.json`` nor the config states an
  offset and the cameras come back to their start. A stated one that the events contradict
  gets a warning.
- **Crop** (:func:`hybridneus.data.hull.event_hull_crop`): the crop cylinder shrunk to the
  visual hull of the event silhouettes, when the config sets no ``data.crop_*``.
- **Tonemap eps** (:mod:`hybridneus.data.contrast`): the preset's eps capped at
  ``estimate.eps_max`` and at what the events' largest log-brightness changes need; the loss
  eases into it from the preset's over ``estimate.eps_ease`` of training.
- **Track window** (:func:`hybridneus.data.track.choose_window`): with
  ``refine.pose_smoothing=-1``, the window the track's own jitter and motion support.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
from dataclasses import dataclass, field
from typing import Any

from hybridneus.config import Config, DataConfig, EstimateConfig, RefineConfig
from hybridneus.data.dataset import EventDataset, SplitData
from hybridneus.data.presets import apply_overrides
from hybridneus.errors import DatasetError

log = logging.getLogger("hybridneus")

#: The noise filter's time slab, in views (:func:`hybridneus.data.denoise.denoised_split`).
NOISE_SLAB = 2.0
CROP_KEYS = ("crop_r", "crop_y_min", "crop_y_max")


@dataclass
class Estimates:
    """What :func:`estimate_scene` found.

    Attributes:
        dataset: the dataset whose preset holds the values taken (the input itself when
            nothing changed).
        taken: preset field -> one line on how its value was estimated (only the values the
            fit took from the events).
        eps_start: the eps the loss eases from (the preset's) when the estimate lowered it.
        lines: one line per finding (noise, balance, crop, eps), for the log and ``info``.
        warnings: findings that contradict a stated value.
        noise: the noise filter's one-line report, when the offset estimate ran it.
        balance: the :class:`~hybridneus.data.balance.PolarityBalance`, likewise.
        pose_window: the views the training track is to be smoothed over, chosen from the
            track (``refine.pose_smoothing=-1``; 0: too short to smooth), else ``None``.
        hot: the :class:`~hybridneus.data.hot.HotPixels` of the training split as given,
            when ``estimate.hot_pixels`` looked for them; those found are left out of
            ``dataset``'s split.
    """

    dataset: EventDataset
    taken: dict[str, str] = field(default_factory=dict)
    eps_start: float | None = None
    lines: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    noise: str | None = None
    balance: Any = None
    pose_window: int | None = None
    hot: Any = None

    @property
    def hot_pixels(self) -> list[tuple[int, int]]:
        """The ``(x, y)`` pixels left out of the training split, loudest first."""
        return self.hot.pixels() if self.hot is not None else []

    def take(self, values: dict[str, Any], why: str) -> None:
        """Put ``values`` into the dataset's preset (on a copy) and record ``why``."""
        self.dataset = copy.copy(self.dataset)
        self.dataset.preset = apply_overrides(self.dataset.preset, values)
        self.dataset.notes = [*self.dataset.notes, why]
        for key in values:
            self.taken[key] = why


def estimate_scene(
    dataset: EventDataset, cfg: EstimateConfig, data: DataConfig | None = None,
    refine: RefineConfig | None = None,
) -> Estimates:
    """Run the estimators ``cfg`` switches on over ``dataset``'s training split.

    Args:
        dataset: the loaded dataset; its preset already holds ``data``'s overrides.
        cfg: which estimators run, and their settings.
        data: the config's dataset section: a value set there is never estimated, and
            ``data.split`` names the split the events come from. Default: nothing set.
        refine: the config's ``refine`` section: ``pose_smoothing=-1`` chooses the track's
            window. Default: no smoothing.

    Returns:
        The :class:`Estimates`; ``dataset`` itself is not changed.
    """
    data = data if data is not None else DataConfig()
    found = Estimates(dataset)
    split = dataset[data.split]
    ev = split.events
    if len(ev) and ev.n_positive in (0, len(ev)):
        raise DatasetError(
            f"{ev.path}: every event has polarity {'+1' if ev.n_positive else '-1'} (stored as "
            f"{ev.polarity_note}); a recording holds both, and a fit needs both (a polarity "
            "column of another convention, or a filtered file?)")
    if cfg.hot_pixels:
        split = _hot_pixels(found, split)
    from hybridneus.data.orientation import transposed_events

    transposed = transposed_events(split)
    if transposed is not None:
        found.warnings.append(transposed)
    if cfg.threshold and data.threshold is None and "threshold" not in dataset.stated:
        _threshold(found, split, take_offset=cfg.polarity_offset and data.polarity_offset is None)
    if (cfg.polarity_offset and data.polarity_offset is None
            and "polarity_offset" not in found.taken):
        _polarity_offset(found, split, cfg.pixel_offsets)
        split = found.dataset[data.split]
    if cfg.crop and all(getattr(data, k) is None for k in CROP_KEYS):
        _crop(found, split)
    if cfg.tonemap_eps and data.tonemap_eps is None:
        _tonemap_eps(found, split, cfg.eps_max)
    if refine is not None and refine.pose_smoothing < 0:
        from hybridneus.data.track import choose_window

        found.pose_window = choose_window(split.c2w, refine.pose_smoothing_order)
        found.lines.append(
            f"track: smoothed over {found.pose_window} views, chosen from the track"
            if found.pose_window else "track: too short to smooth; poses as given")
    for line in found.lines:
        log.info(line)
    for line in found.warnings:
        log.warning(line)
    return found


def noise_and_balance(split, filtered: tuple[Any, Any] | None = None) -> tuple[str, Any]:
    """The noise filter's one-line report and the :class:`PolarityBalance` after it.
    ``filtered``: what ``denoised_split(split, NOISE_SLAB)`` returned, if the caller has it."""
    from hybridneus.data.balance import polarity_balance
    from hybridneus.data.denoise import denoised_split

    if filtered is None:
        filtered = denoised_split(split, NOISE_SLAB)
    return filtered[1].line(), polarity_balance(split, NOISE_SLAB, filtered)


def _hot_pixels(found: Estimates, split) -> SplitData:
    from hybridneus.data.hot import split_hot_pixels, without_pixels

    found.hot = split_hot_pixels(split)
    if not found.hot.n:
        return split
    found.lines.append(f"{found.hot.line()}; left out of the fit (estimate.hot_pixels=false "
                       "keeps them)")
    split = without_pixels(split, found.hot_pixels)
    found.dataset = with_split(found.dataset, split)
    return split


def with_split(dataset: EventDataset, split: SplitData) -> EventDataset:
    """A shallow copy of ``dataset`` holding ``split`` in place of its namesake."""
    out = copy.copy(dataset)
    out.splits = {**dataset.splits, split.name: split}
    return out


def _threshold(found: Estimates, split, take_offset: bool) -> None:
    from hybridneus.data.threshold import estimate_thresholds

    p = found.dataset.preset
    if "tonemap_eps" in found.dataset.stated:
        est, reason = estimate_thresholds(split, p)
    else:  # the frames' log mapping is unknown, and C would take its error
        est, reason = None, "no tonemap eps states the frames' log mapping"
    if est is None:
        found.lines.append(
            f"threshold: C {p.threshold:g} is the {found.dataset.preset_source}'s guess, stated "
            f"nowhere ({reason}); the events alone fix only the ON/OFF ratio, so a wrong C "
            "scales the fitted colours' contrast (--set data.threshold=C if it is known)")
        return
    found.lines.append(est.line())
    values = {"threshold": round(est.threshold, 5)}
    offset = ""
    if take_offset and "polarity_offset" not in found.dataset.stated:
        values["polarity_offset"] = round(est.polarity_offset, 4)
        offset = f", polarity offset {values['polarity_offset']:g}"
    found.take(values, f"C {values['threshold']:g}{offset} from the rgb/ frames' log-brightness "
               f"changes (the {found.dataset.preset_source} guessed C {p.threshold:g}; "
               "estimate.threshold=false keeps the guess)")


def _polarity_offset(found: Estimates, split, pixels: bool = False) -> None:
    from hybridneus.data.balance import between_views, closed_path, closed_span, pixel_offsets
    from hybridneus.data.denoise import denoised_split

    closed, gap = closed_path(split.c2w)
    span = None if closed else closed_span(split.c2w)
    counted = split if span is None else between_views(split, *span)
    filtered = denoised_split(counted, NOISE_SLAB)  # the pixels' own offsets count after it too
    noise, balance = noise_and_balance(counted, filtered)
    found.noise, found.balance = noise, balance
    where = "" if span is None else (f", over views {span[0]} .. {span[1]}, where the cameras "
                                     "come back to where they were")
    found.lines += [noise, balance.line() + where]
    suggested = balance.suggested()
    p = found.dataset.preset
    if suggested is None:
        return
    if not closed and span is None:
        if suggested == p.polarity_offset:  # agrees anyway: nothing to explain
            return
        found.lines.append(
            f"polarity: the cameras end {gap:.0f} steps between views from where they started "
            "(an open path), over which a pixel's events need not balance: the offset stays "
            f"{p.polarity_offset:g} ({found.dataset.preset_source}; --set "
            "data.polarity_offset=O states it)")
        return
    if "polarity_offset" in found.dataset.stated:
        if balance.disagrees(p.polarity_offset):
            found.warnings.append(
                f"polarity offset {p.polarity_offset:g} (preset from the "
                f"{found.dataset.preset_source}), but the events imply {suggested:g}; --set "
                f"data.polarity_offset={suggested:g} uses theirs")
        return
    found.take({"polarity_offset": suggested},
               f"{suggested:g} from the events' balance (the {found.dataset.preset_source} "
               f"guessed {p.polarity_offset:g}; estimate.polarity_offset=false keeps the guess)")
    if pixels:
        own = pixel_offsets(filtered[0].events, split.width, split.height, suggested)
        found.dataset = with_split(found.dataset, dataclasses.replace(split, pixel_offset=own))
        found.lines.append(
            f"polarity: each pixel's own offset from its balance (spread {own.std():.3f}, "
            f"{own.min():+.2f} .. {own.max():+.2f})")


def _crop(found: Estimates, split) -> None:
    from hybridneus.data.hull import NOTHING_OUTLINED, background_fires, event_hull_crop

    p = found.dataset.preset
    crop = (p.crop_r, p.crop_y_min, p.crop_y_max)
    clutter = background_fires(split)
    if clutter is not None:
        found.lines.append(f"crop: keeping the preset's (r {p.crop_r:g}, y {p.crop_y_min:g} .. "
                           f"{p.crop_y_max:g}): {clutter}")
        found.warnings.append(
            f"{clutter}; the crop is not taken from the events and the hull prior is off. "
            "Give the object's region: hybridneus convert --box X0,Y0,Z0,X1,Y1,Z1, or --set "
            "data.crop_r=R --set data.crop_y_min=Y0 --set data.crop_y_max=Y1")
        return
    tight = event_hull_crop(split, crop)
    if tight is None or all(abs(a - b) < 1e-6 for a, b in zip(tight, crop, strict=True)):
        why = NOTHING_OUTLINED if tight is None else "it is inside the events' hull"
        found.lines.append(f"crop: keeping the preset's (r {p.crop_r:g}, y {p.crop_y_min:g} .. "
                           f"{p.crop_y_max:g}): {why}")
        return
    values = {k: round(float(v), 4) for k, v in zip(CROP_KEYS, tight, strict=True)}
    why = (f"r {values['crop_r']}, y {values['crop_y_min']} .. {values['crop_y_max']} from the "
           f"events' visual hull (preset: r {p.crop_r:g}, y {p.crop_y_min:g} .. "
           f"{p.crop_y_max:g}; estimate.crop=false keeps the preset's)")
    found.lines.append(f"crop: {why}")
    found.take(values, why)


def _tonemap_eps(found: Estimates, split, eps_max: float) -> None:
    from hybridneus.data.contrast import event_extent, loss_eps

    p = found.dataset.preset
    eps, reason = loss_eps(p.tonemap_eps, event_extent(split, p), eps_max)
    if eps == p.tonemap_eps:
        found.lines.append(f"tonemap eps: {eps:g}, {reason}")
        return
    why = (f"{eps:g} (preset {p.tonemap_eps:g}): {reason}; estimate.tonemap_eps=false keeps "
           "the preset's")
    found.lines.append(f"tonemap eps: {why}")
    found.eps_start = float(p.tonemap_eps)
    found.take({"tonemap_eps": eps}, why)


@dataclass
class TrainingData:
    """What a fit trains on, prepared before the trainer is built (:func:`training_data`).

    Attributes:
        dataset: the dataset, its preset holding the values the fit uses.
        split: the training split as trained on (its track smoothed where asked).
        given_c2w: (n_views, 4, 4) the training track as the data states it.
        smoothed: whether ``split``'s track was smoothed.
        free_space: where the events' visual hull says there is no matter, over the crop's
            box (``priors.hull``), or ``None`` (the prior off, or nothing outlined).
        frame: a converted recording's own frame (``scene.json``), which meshes go back to,
            or ``None``.
    """

    dataset: EventDataset
    split: SplitData
    given_c2w: Any
    smoothed: bool = False
    free_space: Any = None
    frame: dict | None = None


def training_data(dataset: EventDataset, cfg: Config, pose_window: int | None = None,
                  device: Any = "cpu") -> TrainingData:
    """Prepare ``dataset`` for a fit of ``cfg``: smooth the training track over
    ``refine.pose_smoothing`` views (``pose_window`` where that is -1: the window
    :func:`estimate_scene` chose), keep the events the noise filter keeps
    (``estimate.denoise``; a clean stream is kept whole) and outline the hull's free space
    over the crop's box, its votes counted on ``device``. Nothing is estimated here;
    ``dataset`` is not changed."""
    import numpy as np
    import torch

    from hybridneus.data.crop import crop_aabb
    from hybridneus.recordings.frame import read_scene_frame

    split = dataset[cfg.data.split]
    given = split.c2w
    window = cfg.refine.pose_smoothing
    if window < 0:
        if pose_window is None:
            raise ValueError("training_data: refine.pose_smoothing=-1 needs the chosen window")
        window = pose_window
    if window:
        from hybridneus.data.track import smooth_track

        split = dataclasses.replace(
            split, c2w=smooth_track(split.c2w, window, cfg.refine.pose_smoothing_order))
    if cfg.estimate.denoise:
        from hybridneus.data.denoise import denoised_split

        split, report = denoised_split(split, NOISE_SLAB)
        if report.kept < report.total:
            log.info(f"{report.line()}; the fit trains on those (estimate.denoise=false "
                     "trains on every event)")
    free = None
    clutter = None
    if cfg.priors.hull.enabled:
        from hybridneus.data.hull import background_fires

        clutter = background_fires(split)
        if clutter is not None:
            log.warning(f"hull: off, {clutter}")
    if cfg.priors.hull.enabled and clutter is None:
        from hybridneus.data.hull import NOTHING_OUTLINED, event_free_space

        p = dataset.preset
        box = crop_aabb(torch.tensor([float(p.crop_r), float(p.crop_y_min),
                                      float(p.crop_y_max)]))
        lo, hi = (a.numpy().astype(np.float64) for a in (box[:3], box[3:]))
        free = event_free_space(split, lo, hi, cfg.priors.hull.resolution, device=device)
        log.info(f"hull: {NOTHING_OUTLINED}; no hull prior" if free is None else
                 f"hull: the events' visual hull calls {free.free_fraction:.0%} of the crop "
                 "box empty (priors.hull)")
    root = getattr(dataset, "root", None)
    frame = read_scene_frame(root) if root is not None else None
    return TrainingData(dataset, split, given, bool(window), free,
                        frame.to_json() if frame is not None else None)
