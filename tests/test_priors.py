"""The priors: each one's effect, its switch, and its hooks in a training step."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from fitting import params, stop_at, tiny

from hybridneus.api import fit, prepare
from hybridneus.errors import ConfigError
from hybridneus.training import losses as L
from hybridneus.training.priors import (
    CollapseGuard,
    CurvaturePrior,
    HullPrior,
    SharpnessCeiling,
    SharpnessFloor,
)
from hybridneus.training.priors.curvature import surface_points
from hybridneus.training.runs import load_checkpoint
from hybridneus.training.schedules import sharpness_floor


def _prior(trainer, kind):
    found = [p for p in trainer.priors if isinstance(p, kind)]
    return found[0] if found else None


def test_each_prior_has_one_switch(scene):
    every = prepare(scene, tiny("train.iters=1"), device="cpu")[0]
    names = ["hull", "curvature", "sharpness_floor", "sharpness_ceiling", "collapse_guard"]
    assert [p.name for p in every.priors] == names
    off = [f"priors.{n}.enabled=false" for n in names]
    assert prepare(scene, tiny("train.iters=1", *off), device="cpu")[0].priors == []
    paper = prepare(scene, tiny("train.iters=1", preset="eventneus"), device="cpu")[0]
    assert [p.name for p in paper.priors] == ["collapse_guard"]


# --------------------------------------------------------------------------- sharpness ceiling


def test_the_sharpness_ceiling_holds_a_runaway_sharpness_at_its_bound(scene):
    """A sharpness far past the finest cell is brought down to per_cell / cell by the first
    step and kept at or below it; without the prior it stays where it was (the field's own
    clamp at 1e6 leaves it no gradient)."""
    import math

    def sharpness_after(*extra: str) -> tuple[float, object]:
        trainer, _ = prepare(scene, tiny("train.iters=3", *extra), device="cpu")
        with torch.no_grad():
            trainer.field.variance.fill_(math.log(5e6) / 10.0)
        trainer.fit(progress=False)
        return float(trainer.field.inv_s()), trainer

    capped, trainer = sharpness_after()
    ceiling = _prior(trainer, SharpnessCeiling).ceiling
    side = float((trainer.aabb[3:] - trainer.aabb[:3]).max())
    assert ceiling == pytest.approx(4.0 * 64 / side)  # TINY's grid.max_resolution is 64
    # projected onto the bound after each step; Adam's next step (at most lr = 0.01 on v)
    # may lower it by up to a factor exp(-0.1) before the last projection
    assert 0.85 * ceiling < capped <= ceiling * (1 + 1e-5)
    free, _ = sharpness_after("priors.sharpness_ceiling.enabled=false")
    assert free == pytest.approx(1e6)
    wider, _ = sharpness_after("priors.sharpness_ceiling.per_cell=8")
    assert 0.85 * 2 * ceiling < wider <= 2 * ceiling * (1 + 1e-5)


# --------------------------------------------------------------------------- curvature


def test_curvature_loss_is_zero_for_equal_normals_and_grows_with_their_angle():
    g = torch.nn.functional.normalize(torch.randn(100, 3), dim=-1)
    assert float(L.curvature_loss(g, 3.0 * g)) == pytest.approx(0.0, abs=1e-10)
    tilted = g + 0.1 * torch.nn.functional.normalize(torch.randn(100, 3), dim=-1)
    more = g + 0.5 * torch.nn.functional.normalize(torch.randn(100, 3), dim=-1)
    assert 0 < float(L.curvature_loss(g, tilted)) < float(L.curvature_loss(g, more))


def test_curvature_term_sits_on_the_rendered_surface(scene):
    """The curvature prior acts at the expected-depth points of rays that hit the surface."""
    from hybridneus.rendering.renderer import render_rays

    trainer, _ = prepare(scene, tiny("train.iters=1"), device="cpu")
    batch = trainer.windows.sample(64)
    o = torch.cat([batch.origins0, batch.origins1])
    d = torch.cat([batch.dirs0, batch.dirs1])
    out = render_rays(trainer.field, o, d, trainer.sampler, None, False)
    points, hit = surface_points(out, o, d)
    hits = int((out.opacity > 0.5).sum())
    assert 0 < hits < len(o) and points.shape == (len(o), 3) and int(hit.sum()) == hits
    assert torch.isfinite(points).all()
    with torch.no_grad():
        # Expected depth without dividing by the opacity would fall up to half the camera
        # distance short of the surface.
        assert float(trainer.field.sdf(points[hit > 0]).abs().max()) < 0.05
    logs = trainer.train_step()
    assert "loss/curvature" in logs and np.isfinite(logs["loss/curvature"])
    off = prepare(scene, tiny("train.iters=1", "priors.curvature.enabled=false"),
                  device="cpu")[0]
    assert "loss/curvature" not in off.train_step()


def test_curvature_weight_falls_linearly_to_zero_by_its_end(scene):
    """``end`` 0 keeps the weight; else it falls linearly, and once it reaches 0 the step
    skips the term (and its extra gradient pass) altogether."""
    const = CurvaturePrior(tiny("priors.curvature.end=0").priors.curvature)
    fade = CurvaturePrior(tiny("priors.curvature.end=0.5").priors.curvature)
    w = fade.cfg.weight
    assert [const.weight(p) for p in (0, 0.25, 0.5, 0.75)] == [w] * 4
    assert [fade.weight(p) for p in (0, 0.25, 0.5, 0.75)] == pytest.approx([w, w / 2, 0, 0])
    trainer, _ = prepare(scene, tiny("train.iters=20", "priors.curvature.end=0.5"),
                         device="cpu")
    trainer.step = 12
    assert "loss/curvature" not in trainer.train_step()
    trainer.step = 4
    logs = trainer.train_step()
    assert "loss/curvature" in logs and logs["loss/curvature"] > 0


# --------------------------------------------------------------------------- sharpness floor


def test_the_sharpness_floor_holds_the_sharpness_up_and_lets_it_rise(scene):
    """With the sharpness's own learning rate at zero only the floor can move it: it must
    stay at its initial value through the delay, then follow the floor; with its learning
    rate on, the floor is a bound, not a value."""
    # the ceiling (315 on TINY's 64-cell grid) would cut a floor of 400: off here
    cfg = tiny("train.iters=20", "train.lr_variance=0.0", "priors.sharpness_floor.floor=400",
               "priors.sharpness_floor.at=0.5", "priors.sharpness_floor.delay=0.3",
               "priors.sharpness_floor.blend=0", "priors.sharpness_ceiling.enabled=false")
    trainer, _ = prepare(scene, cfg, device="cpu")
    start = trainer.field.inv_s().item()
    seen: list[tuple[int, float]] = []
    trainer.fit([lambda t, lg: seen.append((t.step, lg["inv_s"]))], progress=False)
    for step, value in seen:
        p = (step - 1) / 20
        expected = start if p < 0.3 else sharpness_floor(p, start, 400.0, 0.5)
        assert value == pytest.approx(expected, rel=1e-4)
    assert seen[-1][1] == pytest.approx(400.0, rel=1e-4)

    free = tiny("train.iters=20", "train.lr_variance=0.05", "priors.sharpness_floor.floor=30",
                "priors.sharpness_floor.delay=0", "priors.sharpness_floor.blend=0")
    trainer, _ = prepare(scene, free, device="cpu")
    values = []
    trainer.fit([lambda t, lg: values.append(lg["inv_s"])], progress=False)
    floors = [sharpness_floor(i / 20, start, 30.0, 0.5) for i in range(20)]
    assert all(v >= f * (1 - 1e-5) for v, f in zip(values, floors, strict=True))
    assert max(values) > 30.0 * 1.05
    off = prepare(scene, tiny("train.iters=1", "priors.sharpness_floor.enabled=false"),
                  device="cpu")[0]
    assert _prior(off, SharpnessFloor) is None


# --------------------------------------------------------------------------- hull


def test_hull_prior_empties_the_space_the_event_hull_calls_free(scene):
    """The initial sphere grows into space that no event rules out but the event silhouettes
    call empty; the hull prior pushes the SDF there positive (measured without the curvature
    prior, whose smoothing also moves the surface in these 40 steps, and without the sharpness
    floor, which would freeze the surface by step 20). A 40-step fit's share
    of matter there swings between seeds and CPUs, so the test compares medians over three
    seeds, at a weight that makes the term count within 40 steps."""
    def fitted(on: bool, seed: int):
        trainer, _ = prepare(scene, tiny("train.iters=40", f"train.seed={seed}",
                                         f"priors.hull.enabled={str(on).lower()}",
                                         "priors.hull.weight=5", "priors.hull.ramp=0",
                                         "priors.curvature.enabled=false",
                                         "priors.sharpness_floor.enabled=false"), device="cpu")
        trainer.fit(progress=False)
        return trainer

    arms = {"off": [fitted(False, s) for s in range(3)], "on": [fitted(True, s) for s in range(3)]}
    assert _prior(arms["off"][0], HullPrior) is None
    hull = _prior(arms["on"][0], HullPrior)
    from hybridneus.training.objective import random_points

    pts = random_points(arms["on"][0].aabb, 20000, 0.15, torch.Generator().manual_seed(0))
    free = hull.free_space.free(pts)
    assert free.float().mean() > 0.1
    share = {}
    for name, trainers in arms.items():
        with torch.no_grad():
            share[name] = [float((t.field.sdf(pts[free]) < 0).float().mean()) for t in trainers]
    assert np.median(share["off"]) > 0.05
    assert np.median(share["on"]) < 0.5 * np.median(share["off"])


def test_hull_weight_grows_over_its_ramp(scene):
    from hybridneus.training.objective import random_points
    from hybridneus.training.priors import RandomPoints, StepContext

    trainer, _ = prepare(scene, tiny("train.iters=100", "priors.hull.ramp=0.5"), device="cpu")
    hull = _prior(trainer, HullPrior)
    pts = random_points(trainer.aabb, 512, 0.15, trainer.generator)
    random = RandomPoints(pts, trainer.field.raw_sdf(pts), torch.zeros(512, dtype=torch.bool))
    ctx = StepContext(trainer.field, None, None, None, 0.0, trainer.generator,
                      random=random)
    weights = []
    for p in (0.0, 0.25, 0.5, 0.9):
        ctx.p = p
        terms = hull.terms(ctx)
        weights.append(terms["hull"][0] if terms else 0.0)
    assert weights == pytest.approx([0.0, 0.5, 1.0, 1.0])


# --------------------------------------------------------------------------- collapse guard


def _empty(field) -> None:
    """Push the SDF up by 5 everywhere: nothing is left on any ray."""
    with torch.no_grad():
        field.sdf_net.layers[-1].bias[0] += 5.0


def _empty_after(trainer, steps: int) -> dict[str, torch.Tensor]:
    """Train ``steps`` steps, then :func:`_empty` the field; return the field as it was
    after ``steps // 2`` steps."""
    for _ in range(steps // 2):
        trainer.train_step()
    earlier = params(trainer.field)
    for _ in range(steps - steps // 2):
        trainer.train_step()
    _empty(trainer.field)
    return earlier


GUARD = ("train.iters=200", "priors.collapse_guard.window=5", "train.decay_start=1.0",
         "train.warmup=0.05")


def test_an_emptied_field_is_restored_from_two_windows_back(scene, caplog):
    trainer, _ = prepare(scene, tiny(*GUARD), device="cpu")
    guard = _prior(trainer, CollapseGuard)
    earlier = _empty_after(trainer, 10)  # healthy windows end at steps 5 and 10
    with caplog.at_level("WARNING", logger="hybridneus"):
        opacity = [trainer.train_step()["opacity"] for _ in range(5)]
    assert max(opacity) < 0.01  # the push did empty it
    assert guard.restores == 1 and guard.scale == 0.5
    assert "the field emptied" in caplog.text and "state of step 5" in caplog.text
    now = params(trainer.field)
    for k in earlier:
        assert torch.equal(now[k], earlier[k]), k
    assert not trainer.optimizer.state  # fresh moments
    logs = [trainer.train_step() for _ in range(10)]
    # the warm-up (5% of 200 steps) starts again at the restore
    assert logs[0]["lr"] == pytest.approx(trainer.cfg.train.lr * 0.5 / 10)
    assert logs[-1]["lr"] == pytest.approx(trainer.cfg.train.lr * 0.5)
    assert np.mean([lg["opacity"] for lg in logs]) > 0.05


def test_a_field_that_empties_again_goes_one_restore_point_further_back(scene, caplog):
    trainer, _ = prepare(scene, tiny(*GUARD), device="cpu")
    guard = _prior(trainer, CollapseGuard)
    start = params(trainer.field)
    at_5 = _empty_after(trainer, 10)  # restore points: the start, steps 5 and 10
    for _ in range(5):
        trainer.train_step()
    assert guard.restores == 1  # step 10 dropped, step 5 loaded
    assert all(torch.equal(v, at_5[k]) for k, v in params(trainer.field).items())
    _empty(trainer.field)  # empty again before the next window can be a restore point
    with caplog.at_level("WARNING", logger="hybridneus"):
        for _ in range(5):
            trainer.train_step()
    assert guard.restores == 2 and guard.scale == 0.25
    assert "state of step 0" in caplog.text  # not step 5 a second time
    assert all(torch.equal(v, start[k]) for k, v in params(trainer.field).items())


def test_only_windows_with_healthy_opacity_are_restore_points(scene, caplog):
    # no window reaches this bar: an emptied field goes back to where the run started
    trainer, _ = prepare(scene, tiny(*GUARD, "priors.collapse_guard.healthy=1.01"),
                         device="cpu")
    start = params(trainer.field)
    _empty_after(trainer, 10)
    with caplog.at_level("WARNING", logger="hybridneus"):
        for _ in range(5):
            trainer.train_step()
    assert _prior(trainer, CollapseGuard).restores == 1 and "state of step 0" in caplog.text
    assert all(torch.equal(v, start[k]) for k, v in params(trainer.field).items())


def test_without_the_guard_an_emptied_field_stays_empty(scene):
    trainer, _ = prepare(scene, tiny(*GUARD, "priors.collapse_guard.enabled=false"),
                         device="cpu")
    _empty_after(trainer, 10)
    opacity = [trainer.train_step()["opacity"] for _ in range(15)]
    assert max(opacity[-5:]) < 0.01


def test_the_guard_gives_up_after_its_retries(scene):
    trainer, _ = prepare(scene, tiny(*GUARD, "priors.collapse_guard.retries=1"), device="cpu")
    guard = _prior(trainer, CollapseGuard)
    _empty_after(trainer, 10)
    for _ in range(5):
        trainer.train_step()
    assert guard.restores == 1
    for _ in range(10):
        trainer.train_step()
    _empty(trainer.field)
    for _ in range(10):
        trainer.train_step()
    assert guard.restores == 1 and guard.scale == 0.5


def test_a_bad_guard_lr_factor_is_a_config_error(scene):
    with pytest.raises(ConfigError, match="priors.collapse_guard.lr_factor"):
        prepare(scene, tiny("priors.collapse_guard.lr_factor=0"), device="cpu")


def test_resume_keeps_the_guards_learning_rate(scene, tmp_path):
    cfg = tiny("train.iters=40", "priors.collapse_guard.window=5", "train.checkpoint_every=20")

    def empty_at_10(trainer, logs):
        if trainer.step == 10:
            _empty(trainer.field)

    first = fit(scene, cfg, [empty_at_10, stop_at(20)], out=tmp_path, device="cpu")
    assert first.interrupted
    state = load_checkpoint(first.run_dir)
    assert state["priors"]["collapse_guard"] == {"lr_scale": 0.5, "warm_from": 15,
                                                 "restores": 1}
    resumed, _ = prepare(None, None, resume=first.run_dir, device="cpu")
    guard = _prior(resumed, CollapseGuard)
    assert (guard.scale, guard.warm_from, guard.restores) == (0.5, 15, 1)
