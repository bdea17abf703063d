"""The training loop: event batches -> NeuS renders at both window ends -> losses -> Adam.

One :class:`Trainer` owns the field, the samplers, the optimiser and every random state, so
``state_dict()`` / ``load_state_dict()`` resume a run exactly (same step, same parameters,
same optimiser moments, same random draws).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from hybridneus.config import Config, rays_per_step
from hybridneus.data.hull import NOTHING_OUTLINED, FreeSpace, event_free_space
from hybridneus.errors import ConfigError
from hybridneus.model.field import HybridField, crop_aabb, crop_sdf
from hybridneus.rendering.occupancy import OccupancyGrid
from hybridneus.rendering.renderer import render_rays
from hybridneus.rendering.sampling import NeuSSampler
from hybridneus.training import losses as L

Callback = Callable[["Trainer", dict[str, float]], None]

# Steps after which a --minutes budget re-estimates the total number of steps.
_ESTIMATE_AT = (10, 30, 100)
_ESTIMATE_EVERY = 100


def onset_weight(step: int, start: int, ramp: int) -> float:
    """A linear ramp: 0 before ``start``, then ``(step - start + 1) / ramp`` up to 1 (1 at
    once when ``ramp <= 0``). It weighs the ``hull`` term, warms up the learning rate and
    blends in the sharpness floor.

    A term or bound switched on at full strength part-way through training (Adam has scaled
    its steps to the other terms' gradients) jolts the field; one grown from 0 does not.

    Args:
        step: current step (0-based).
        start: first step with the term.
        ramp: steps from ``start`` until full weight.
    """
    if step < start:
        return 0.0
    if ramp <= 0:
        return 1.0
    return min(1.0, (step - start + 1) / ramp)


def lr_factor(step: int, total: int, warmup: int, decay_start: float, decay_final: float) -> float:
    """Learning-rate multiplier: linear warm-up, constant, then exponential decay.

    Args:
        step: current step (0-based).
        total: total steps.
        warmup: warm-up steps.
        decay_start: fraction of ``total`` after which the decay starts.
        decay_final: multiplier reached at ``total``.
    """
    f = onset_weight(step, 0, warmup)
    progress = step / max(total, 1)
    if progress > decay_start and decay_start < 1.0:
        f *= decay_final ** min(1.0, (progress - decay_start) / (1.0 - decay_start))
    return f


def inv_s_floor(
    step: int,
    total: int,
    start: float,
    floor: float,
    at: float,
    min_steps: int = 0,
    delay: int = 0,
    blend: int = 0,
) -> float:
    """Lowest NeuS sharpness allowed at ``step``: none (0.0) before ``delay``, then ``start``
    growing geometrically from step 0 to ``floor`` at ``max(at * total, min_steps)`` steps and
    held there (``floor <= 0`` switches it off: 0.0). In the ``blend`` steps from ``delay``
    on, the value ``f`` of that curve is replaced by ``f ** w``, ``w`` growing linearly from
    ``1 / blend`` to 1: the floor rises from near 1 to the curve instead of jumping to it.

    Args:
        step: current step.
        total: total steps.
        start: the initial sharpness ``exp(10 v_0)``.
        floor: the final lower bound.
        at: fraction of ``total`` at which ``floor`` is reached.
        min_steps: the step before which ``floor`` is not reached, whatever ``total``.
        delay: steps at the start with no floor.
        blend: steps after ``delay`` over which the floor rises to the curve.
    """
    if floor <= 0 or step < delay:
        return 0.0
    if floor <= start:
        value = floor
    else:
        progress = min(1.0, step / max(at * total, min_steps, 1.0))
        value = start * (floor / start) ** progress
    return value ** onset_weight(step, delay, blend)


def _make_adam(groups: list[dict[str, Any]], cfg: Config) -> torch.optim.Adam:
    kwargs = dict(betas=tuple(cfg.train.betas), eps=cfg.train.adam_eps)
    try:
        return torch.optim.Adam(groups, fused=True, **kwargs)
    except (RuntimeError, TypeError, ValueError):
        return torch.optim.Adam(groups, **kwargs)


class Trainer:
    """Event-supervised training of a :class:`HybridField` on one dataset split.

    Args:
        cfg: the full configuration.
        dataset: an :class:`hybridneus.data.EventDataset` (preset already resolved).
        device: torch device.

    Attributes:
        field: the model being trained.
        step: completed steps.
        total_steps: the schedule length (re-estimated under a time budget).
        interrupted: set when :meth:`fit` stopped on KeyboardInterrupt.
    """

    def __init__(self, cfg: Config, dataset, device: torch.device | str = "cpu") -> None:
        from hybridneus.data import EventWindowSampler

        self.cfg = cfg
        self.device = torch.device(device)
        # Checked before the hull and the samplers are built: a typo should not cost that.
        if cfg.train.supervision not in ("events", "rgb"):
            raise ConfigError(
                f"train.supervision: expected 'events' or 'rgb', got {cfg.train.supervision!r}"
            )
        if not 0.0 < cfg.train.collapse_lr_factor <= 1.0:
            raise ConfigError(
                f"train.collapse_lr_factor: expected a value in (0, 1], got "
                f"{cfg.train.collapse_lr_factor}"
            )
        n_rays = rays_per_step(cfg, self.device)
        if n_rays != cfg.train.n_rays:  # 0: the device's default; config.yaml records it
            cfg.train.n_rays = n_rays
            logging.getLogger("hybridneus").info(
                "%d pixels per step on %s (train.n_rays=0: the device's default)",
                n_rays, self.device.type,
            )
        self.dataset = dataset
        if cfg.data.split not in dataset.splits:
            raise ConfigError(
                f"data.split: {dataset.root} has no split {cfg.data.split!r}; "
                f"found {sorted(dataset.splits)}"
            )
        self.split = dataset.splits[cfg.data.split]
        self.preset = dataset.preset
        if cfg.train.threads > 0:
            torch.set_num_threads(cfg.train.threads)
        torch.manual_seed(cfg.train.seed)
        p = self.preset
        self.scene = {
            "background": [float(c) for c in p.background],
            "crop": [float(p.crop_r), float(p.crop_y_min), float(p.crop_y_max)],
            "tonemap_eps": float(p.tonemap_eps),
            # where the cameras stood: meshing fills the space none of them saw
            "cameras": self.split.c2w[:, :3, 3].astype(float).tolist(),
        }
        self.field = HybridField(
            cfg.grid, cfg.field, tuple(self.scene["background"]), tuple(self.scene["crop"])
        ).to(self.device)
        aabb = crop_aabb(self.field.crop.cpu()).to(self.device)
        self.aabb = aabb
        self.free_space = self._event_free_space()
        r = cfg.render
        self.occupancy = OccupancyGrid(aabb, r.occupancy_resolution).to(self.device)
        self.sampler = NeuSSampler(
            aabb,
            n_coarse=r.n_coarse,
            n_importance=r.n_importance,
            up_rounds=r.up_rounds,
            up_base_inv_s=r.up_base_inv_s,
            occupancy=self.occupancy if r.occupancy else None,
            n_march=r.occupancy_march,
            near_min=r.near_min,
            chunk=r.chunk,
        )
        self.windows = EventWindowSampler(
            self.split, self.preset, seed=cfg.train.seed, window=cfg.train.window,
            device=self.device,
        )
        self.frames = None
        if cfg.train.supervision == "rgb":
            from hybridneus.data.frames import FrameRaySampler

            self.frames = FrameRaySampler(
                self.split, self.preset.width, self.preset.height, seed=cfg.train.seed,
                device=self.device,
            )
        self.generator = torch.Generator(device=self.device).manual_seed(cfg.train.seed + 1)
        variance = [self.field.variance]
        others = [q for name, q in self.field.named_parameters() if name != "variance"]
        self.optimizer = _make_adam(
            [
                {"params": others, "lr": cfg.train.lr, "name": "field"},
                {"params": variance, "lr": cfg.train.lr_variance, "name": "variance"},
            ],
            cfg,
        )
        self.base_lrs = [cfg.train.lr, cfg.train.lr_variance]
        self.step = 0
        self.total_steps = max(1, cfg.train.iters)
        self.elapsed = 0.0
        self.interrupted = False
        self.occupied_fraction = 1.0
        self.time_budget = cfg.train.minutes * 60.0 if cfg.train.minutes > 0 else None
        # The collapse guard (see _guard_collapse): learning-rate multiplier, step of the last
        # restore (its warm-up restarts there), restores so far, and the restore points.
        self.lr_scale = 1.0
        self.warm_from = 0
        self.restores = 0
        self._window_opacity: list[float] = []
        self._snapshots: list[tuple[int, dict[str, torch.Tensor]]] = [(0, self._field_copy())]

    # ------------------------------------------------------------------ state

    def state_dict(self) -> dict[str, Any]:
        """Everything needed to resume: tensors and primitive containers only."""
        rng = self.windows.rng.bit_generator.state
        return {
            "version": 1,
            "step": self.step,
            "total_steps": self.total_steps,
            "elapsed": self.elapsed,
            "model": self.field.state_dict(),
            "occupancy": self.occupancy.occupied.clone(),
            "optimizer": self.optimizer.state_dict(),
            "torch_rng": torch.get_rng_state(),
            "generator": self.generator.get_state(),
            "window_rng": _to_primitive(rng),
            "frame_rng": None if self.frames is None
            else _to_primitive(self.frames.rng.bit_generator.state),
            "scene": dict(self.scene),
            "config": self.cfg.to_dict(),
            "guard": {"lr_scale": self.lr_scale, "warm_from": self.warm_from,
                      "restores": self.restores},
        }

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a state written by :meth:`state_dict`."""
        self.field.load_state_dict(state["model"])
        self.occupancy.occupied.copy_(state["occupancy"])
        self.optimizer.load_state_dict(state["optimizer"])
        torch.set_rng_state(state["torch_rng"])
        try:
            self.generator.set_state(state["generator"])
        except RuntimeError:
            # Saved on the other kind of device: CPU and CUDA generator states differ in
            # size and cannot be carried across, so the sample draws continue from a new
            # stream (everything else resumes exactly).
            self.generator.manual_seed(self.cfg.train.seed + 1 + int(state["step"]))
            logging.getLogger("hybridneus").info(
                "resumed on %s; the checkpoint's sampler state does not fit this device (saved "
                "on another kind of device?): ray jitter and random points continue from a "
                "new random stream",
                self.device.type,
            )
        self.windows.rng.bit_generator.state = state["window_rng"]
        if self.frames is not None and state.get("frame_rng") is not None:
            self.frames.rng.bit_generator.state = state["frame_rng"]
        self.step = int(state["step"])
        self.total_steps = int(state["total_steps"])
        self.elapsed = float(state.get("elapsed", 0.0))
        guard = state.get("guard", {})
        self.lr_scale = float(guard.get("lr_scale", 1.0))
        self.warm_from = int(guard.get("warm_from", 0))
        self.restores = int(guard.get("restores", 0))
        self._window_opacity = []
        self._snapshots = [(self.step, self._field_copy())]
        self.field.update_step(self.step, self.total_steps)

    # ------------------------------------------------------------------ one step

    def _schedules(self) -> float:
        t = self.cfg.train
        factor = lr_factor(self.step, self.total_steps, t.warmup, t.decay_start, t.decay_final)
        if self.restores:
            factor *= self.lr_scale * onset_weight(self.step, self.warm_from, t.warmup)
        for group, base in zip(self.optimizer.param_groups, self.base_lrs, strict=True):
            group["lr"] = base * factor
        self.field.update_step(self.step, self.total_steps)
        anneal_at = self.cfg.render.cos_anneal_at * self.total_steps
        self.field.cos_anneal = 1.0 if anneal_at <= 0 else min(1.0, self.step / anneal_at)
        return factor

    def _apply_inv_s_floor(self) -> None:
        """Keep the learned sharpness on or above the scheduled floor.

        Where events leave geometry ambiguous (grey, event-poor regions, thin parts) the
        learned sharpness can sink and the fit turn to fog: a thick semi-transparent
        envelope, or hollows, whose zero level is far from the object. Projecting ``v`` up
        to the floor after each Adam step keeps its gradient, so it can still rise above it.
        The floor grows from the initial sharpness; it is not applied in the first
        ``inv_s_floor_delay`` steps, where the sharpness dips while the surface leaves the
        initial sphere (blocking that dip flipped a 400-step test fit from 0.035 to 0.092
        mean |SDF| on the true surface). It then rises to its curve over
        ``inv_s_floor_blend`` steps: lifted from about 6 to 21 in one step, a bunny's render
        went transparent (mean opacity 0.41 -> 0.002) and never came back. It reaches its
        value no earlier than
        ``inv_s_floor_min_steps``: forced sharp before its surface has arrived, a short fit
        freezes it in the wrong place.
        """
        t = self.cfg.train
        start = math.exp(10.0 * self.cfg.field.inv_s_init)
        floor = inv_s_floor(
            self.step, self.total_steps, start, t.inv_s_floor, t.inv_s_floor_at,
            t.inv_s_floor_min_steps, t.inv_s_floor_delay, t.inv_s_floor_blend,
        )
        if floor <= 0:
            return
        with torch.no_grad():
            self.field.variance.clamp_(min=math.log(floor) / 10.0)

    def _event_free_space(self) -> FreeSpace | None:
        """The events' visual hull over the crop box, for the ``hull`` term (or ``None``).

        Events say nothing where nothing changes: matter the cameras never see against the
        background, such as the space under a flat object seen from above, costs no event
        error, and fits fill it (a 15-minute xylophone grew a sag to the crop floor, 23% of
        its surface). Views at the horizon do see that space against the background, and
        the hull of the event silhouettes records it as empty.
        """
        lw = self.cfg.loss
        if lw.lambda_hull <= 0:
            return None
        lo, hi = (a.cpu().numpy().astype(np.float64) for a in (self.aabb[:3], self.aabb[3:]))
        free = event_free_space(
            self.split, lo, hi, lw.hull_resolution, lw.hull_grow, device=self.device
        )
        log = logging.getLogger("hybridneus")
        if free is None:
            log.info(f"hull: {NOTHING_OUTLINED}; no hull term")
        else:
            log.info(f"hull: the events' visual hull calls {free.free_fraction:.0%} of the "
                     "crop box empty (loss.lambda_hull)")
        return free

    def _random_points(self, n: int) -> torch.Tensor:
        """Uniform points in the crop box grown by ``loss.random_box_margin``, within [-1, 1]^3."""
        lo, hi = self.aabb[:3], self.aabb[3:]
        pad = (hi - lo) * self.cfg.loss.random_box_margin
        lo, hi = (lo - pad).clamp(-1.0, 1.0), (hi + pad).clamp(-1.0, 1.0)
        u = torch.rand((n, 3), generator=self.generator, device=self.device)
        return lo + u * (hi - lo)

    @staticmethod
    def _surface_points(
        out, origins: torch.Tensor, dirs: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The rendered surface point (expected depth) of every ray, and which rays hit
        something (opacity > 0.5) as a 0/1 weight. Every ray keeps a point, so that no step
        waits for the number of hits (a GPU would stall on it); a miss's point is the mean of
        its samples' depths, or its origin where it has no opacity at all."""
        opacity = out.opacity.detach()
        depth = out.depth.detach() / opacity.clamp_min(1e-6)
        return origins + depth[:, None] * dirs, (opacity > 0.5).to(origins.dtype)

    def _curvature(
        self, points: torch.Tensor, hit: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Normal change over ``loss.curvature_step`` at the surface ``points`` with ``hit``
        1, and the SDF gradients it evaluated (at the points and their shifted copies, for the
        Eikonal term).

        Where the events say nothing (a flat face of one colour is seen only at its outline)
        the data leave the surface free to wrinkle; this prior prefers the smooth one.
        """
        lw = self.cfg.loss
        offset = torch.randn(points.shape, generator=self.generator, device=self.device)
        shifted = points + lw.curvature_step * torch.nn.functional.normalize(offset, dim=-1)
        _, grad, _ = self.field.sdf_gradient_features(torch.cat([points, shifted]), True)
        grad_p, grad_s = grad.chunk(2)
        return L.curvature_loss(grad_p, grad_s, hit), grad

    def tonemap_eps(self) -> float:
        """The event loss's eps at this step: ``data.eps_start`` eased geometrically into the
        scene's eps over ``data.eps_anneal_steps``. A small eps from the first step lets the
        largest event targets pull hard on dark colours before there is a surface to colour,
        and a 256-pixel xylophone fit lost its surface by step 100 that way; a large one
        never reaches those targets."""
        d = self.cfg.data
        end = self.scene["tonemap_eps"]
        if not d.eps_start or d.eps_anneal_steps <= 0 or self.step >= d.eps_anneal_steps:
            return end
        return d.eps_start * (end / d.eps_start) ** (self.step / d.eps_anneal_steps)

    def curvature_weight(self) -> float:
        """Multiplier of ``loss.lambda_curvature`` at this step: 1, or with
        ``loss.curvature_end`` a linear fall to 0 at that fraction of training. Smoothing early
        keeps surfaces that no event constrains from wrinkling while the shape forms, and
        letting go later gives the fine detail the events do support back to the data."""
        lw = self.cfg.loss
        if lw.lambda_curvature <= 0:
            return 0.0
        if lw.curvature_end <= 0:
            return 1.0
        return max(0.0, 1.0 - self.step / (lw.curvature_end * self.total_steps))

    def _background_matter_on(self) -> bool:
        """The background-matter term waits until the surface and its colours have formed: the
        initial sphere's colour is the untrained head's, and nothing defends it yet."""
        lw = self.cfg.loss
        return lw.lambda_background_matter > 0 and (
            self.step >= lw.background_matter_start * self.total_steps
        )

    def train_step(self) -> dict[str, float]:
        """Run one optimisation step; return the logged scalars."""
        cfg = self.cfg
        t_start = time.perf_counter()
        factor = self._schedules()
        r = cfg.render
        refresh = self.step % max(r.occupancy_every, 1) == 0 or self.step == self.warm_from
        if r.occupancy and refresh:
            self.occupied_fraction = self.occupancy.update(
                self.field.raw_sdf, float(self.field.inv_s().detach()), r.occupancy_band, r.chunk
            )
        lw = cfg.loss
        terms: dict[str, torch.Tensor] = {}
        if self.frames is None:
            batch = self.windows.sample(cfg.train.n_rays).to(self.device)
            n = batch.target.shape[0]
            origins = torch.cat([batch.origins0, batch.origins1])
            dirs = torch.cat([batch.dirs0, batch.dirs1])
        else:
            frame_batch = self.frames.sample(2 * cfg.train.n_rays)
            origins, dirs = frame_batch.origins, frame_batch.dirs
        matter_on = self._background_matter_on()
        out = render_rays(
            self.field, origins, dirs, self.sampler, self.generator, True, r.crop_softness,
            fixed_s_opacity=matter_on,
        )
        if self.frames is None:
            c0, c1 = out.color[:n], out.color[n:]
            terms["event"] = L.event_loss(
                c0, c1, batch.target, batch.bayer, self.tonemap_eps()
            )
        else:
            terms["rgb"] = L.rgb_loss(out.color, frame_batch.color)
        if matter_on:
            match = L.background_match(
                out.color, out.opacity, self.field.background(), lw.background_matter_sigma
            )
            terms["background_matter"] = L.background_matter_loss(out.opacity_fixed_s, match)
        need_random = lw.n_random_points > 0 and (
            lw.lambda_eikonal > 0 or lw.lambda_sparsity > 0 or lw.lambda_outside > 0
            or self.free_space is not None
        )
        # SDF gradients for the Eikonal term, each block with its per-point weights (None: all
        # count); only the hits' curvature points count.
        grads: list[tuple[torch.Tensor, torch.Tensor | None]] = [(out.gradients, None)]
        curvature = self.curvature_weight()
        if curvature > 0:
            surface, hit = self._surface_points(out, origins, dirs)
            value, grad_c = self._curvature(surface, hit)
            terms["curvature"] = curvature * value
            grads.append((grad_c, torch.cat([hit, hit])))
        if need_random:
            pts = self._random_points(lw.n_random_points)
            sdf_r, grad_r, _ = self.field.sdf_gradient_features(pts, create_graph=True)
            grads.append((grad_r, None))
            outside = crop_sdf(pts, self.field.crop) > 0
            if lw.lambda_sparsity > 0:
                terms["sparsity"] = L.sparsity_loss(sdf_r[~outside], lw.sparsity_tau)
            if lw.lambda_outside > 0:
                terms["outside"] = L.outside_loss(sdf_r, outside)
            ramp = onset_weight(self.step, lw.hull_start, lw.hull_ramp)
            if self.free_space is not None and ramp > 0:
                terms["hull"] = ramp * L.outside_loss(sdf_r, self.free_space.free(pts) & ~outside)
        if lw.lambda_eikonal > 0:
            weights = None
            if any(w is not None for _, w in grads):
                weights = torch.cat([torch.ones(len(g), device=g.device) if w is None else w
                                     for g, w in grads])
            terms["eikonal"] = L.eikonal_loss(torch.cat([g for g, _ in grads]), weights)
        total = sum(getattr(lw, f"lambda_{name}") * value for name, value in terms.items())
        self.optimizer.zero_grad(set_to_none=True)
        # Only the trained parameters: the sample points are leaves that require grad (for
        # the Eikonal term's d sdf / dx), and a plain backward() would also compute their
        # gradient, through the grid's interpolation weights, for nothing.
        total.backward(inputs=[q for group in self.optimizer.param_groups
                               for q in group["params"] if q.requires_grad])
        self.optimizer.step()
        self._apply_inv_s_floor()
        self.step += 1
        scalars = {f"loss/{k}": v for k, v in terms.items()}
        scalars.update(
            {"loss/total": total, "inv_s": self.field.inv_s(), "opacity": out.opacity.mean()}
        )
        # One device-to-host copy for all of them: on a GPU each float() would wait for the
        # device. The copy also ends the step's GPU work, so step_seconds counts it.
        values = torch.stack([v.detach().float().reshape(()) for v in scalars.values()])
        logs = dict(zip(scalars, values.tolist(), strict=True))
        self._guard_collapse(logs["opacity"])
        logs["restores"] = float(self.restores)
        seconds = time.perf_counter() - t_start
        self.elapsed += seconds
        logs.update(
            {
                "lr": cfg.train.lr * factor,
                "levels": float(self.field.active_levels()),
                "occupied": self.occupied_fraction,
                "step_seconds": seconds,
            }
        )
        return logs

    def _field_copy(self) -> dict[str, torch.Tensor]:
        return {k: v.detach().clone() for k, v in self.field.state_dict().items()}

    def _guard_collapse(self, opacity: float) -> None:
        """Bring back an earlier state when the field empties.

        Early in a fit the surface can overshoot: grown until nearly every ray is opaque, it
        is pushed back by the hull and crop terms, Adam's momentum carries it on, and within
        ten steps the SDF is positive on every sample (seen on small objects on a turntable,
        at half of the seeds). Nothing then has a gradient: an empty field renders the
        background at both ends of every window, and the occupancy grid stops sampling. The
        guard averages the rendered opacity over ``train.collapse_window`` steps. A window
        whose mean reaches ``train.collapse_healthy`` makes the field at its end a restore
        point; when a mean falls below ``train.collapse_opacity`` the guard drops the newest
        restore point (it may already be on its way out), loads the one before, clears the
        optimiser's moments, scales the learning rate by ``train.collapse_lr_factor`` and
        warms it up again. A field that empties again before a new restore point goes back
        one point further each time, down to the state the run started from: a state whose
        opacity was already sinking (0.13 -> 0.03 over the next 50 steps on a turntable) had
        emptied again after every restore. The batches after a restore are new draws, so the
        run does not replay its collapse. After ``train.collapse_retries`` restores it lets
        the run go on.
        """
        t = self.cfg.train
        if t.collapse_opacity <= 0 or t.collapse_window <= 0:
            return
        self._window_opacity.append(opacity)
        if len(self._window_opacity) < t.collapse_window:
            return
        mean = sum(self._window_opacity) / len(self._window_opacity)
        self._window_opacity = []
        points = self._snapshots
        if mean >= t.collapse_opacity:
            if mean >= t.collapse_healthy:
                points.append((self.step, self._field_copy()))
                # the first point (where the run started) is kept as the last resort
                keep = t.collapse_retries + 2
                if len(points) > keep:
                    del points[1:len(points) - keep + 1]
            return
        if self.restores >= t.collapse_retries:
            return
        if len(points) > 1:
            points.pop()
        back_to, state = points[-1]
        self.field.load_state_dict(state)
        self.optimizer.state.clear()
        self.restores += 1
        self.lr_scale *= t.collapse_lr_factor
        self.warm_from = self.step
        logging.getLogger("hybridneus").warning(
            "step %d: the field emptied (mean opacity %.4f over %d steps); restored its state "
            "of step %d with the learning rate x%g (restore %d of at most %d)",
            self.step, mean, t.collapse_window, back_to, self.lr_scale, self.restores,
            t.collapse_retries,
        )

    def _maybe_reestimate(self, start_wall: float, start_step: int) -> None:
        if self.time_budget is None:
            return
        done = self.step - start_step
        if done in _ESTIMATE_AT or (done > 0 and done % _ESTIMATE_EVERY == 0):
            per_step = (time.perf_counter() - start_wall) / max(done, 1)
            remaining = self.time_budget - self.elapsed
            estimate = self.step + max(0, int(remaining / max(per_step, 1e-6)))
            self.total_steps = max(self.step + 1, min(self.cfg.train.iters, estimate))

    # ------------------------------------------------------------------ loop

    def fit(
        self,
        callbacks: Iterable[Callback] = (),
        run=None,
        progress: bool = True,
    ) -> HybridField:
        """Train until ``total_steps`` or the time budget; return the field.

        Args:
            callbacks: called as ``callback(trainer, logs)`` after every step.
            run: a :class:`~hybridneus.training.logging.RunLogger` (checkpoints, metrics,
                previews), or ``None`` for no files.
            progress: show a rich progress bar on stderr.

        A ``KeyboardInterrupt`` (Ctrl-C, or raised by a callback) saves a checkpoint at the
        last completed step, sets :attr:`interrupted` and returns the field.
        """
        from hybridneus.progress import make_progress

        callbacks = list(callbacks)
        start_wall, start_step = time.perf_counter(), self.step
        with make_progress("it", disable=not progress) as bar:
            task = bar.add_task("fit", total=self.total_steps, completed=self.step)
            try:
                while self.step < self.total_steps:
                    if self.time_budget is not None and self.elapsed >= self.time_budget:
                        break
                    logs = self.train_step()
                    self._maybe_reestimate(start_wall, start_step)
                    if run is not None:
                        run.after_step(self, logs)
                    for cb in callbacks:
                        cb(self, logs)
                    bar.update(
                        task,
                        completed=self.step,
                        total=self.total_steps,
                        info=f"loss {logs['loss/total']:.4g} inv_s {logs['inv_s']:.0f} "
                        f"lv {int(logs['levels'])}",
                    )
                    if not math.isfinite(logs["loss/total"]):
                        from hybridneus.errors import RunError

                        raise RunError(
                            f"training diverged at step {self.step} (loss {logs['loss/total']});"
                            " lower train.lr or check data.threshold"
                        )
            except KeyboardInterrupt:
                self.interrupted = True
        if run is not None:
            run.finish(self)
        self.field.eval()
        return self.field


def _to_primitive(value: Any) -> Any:
    """numpy scalars/arrays inside a bit-generator state -> Python ints/lists."""
    if isinstance(value, dict):
        return {k: _to_primitive(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.integer):
        return int(value)
    return value


def default_scene_name(path: str | Path) -> str:
    """Run-folder prefix from a dataset path (its last component)."""
    return Path(path).resolve().name or "scene"
