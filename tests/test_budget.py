"""A --minutes budget becomes a step count before the first step, recorded, and is re-planned
all through the fit to the pace its steps run at, so that a fit slowed for a while and then
freed still uses its time.

Budget behaviour is tested on a fake clock (the plan's and the trainer's ``clock``), never by
timing real steps: the suite has to pass on a loaded machine.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import pytest
import torch
from fitting import params, tiny

from hybridneus.api import fit, prepare
from hybridneus.training.budget import (
    HEADROOM,
    REPLAN_MIN_STEPS,
    BudgetPlan,
    StepCosts,
    step_seconds,
)
from hybridneus.training.scene import SceneRecord
from hybridneus.training.schedules import Timeline


def test_the_mean_step_interpolates_the_probe_points():
    # 0.4 * (1 + 3) / 2 + 0.5 * (3 + 2) / 2 + 0.1 * 2 = 0.8 + 1.25 + 0.2, plus 1 / 10
    assert StepCosts(1.0, 3.0, 2.0, 1.0, 0.4, 10).mean(0.0) == pytest.approx(2.35)


def test_the_mean_over_part_of_the_schedule_is_the_average_of_the_interpolated_cost():
    costs = StepCosts(1.0, 3.0, 2.0, 0.5, 0.4, 10, overhead=0.25)
    for p0, p1 in [(0.0, 1.0), (0.1, 0.3), (0.35, 0.95), (0.92, 1.0)]:
        grid = torch.linspace(p0, p1, 20001, dtype=torch.float64)
        knots = torch.tensor([0.0, 0.4, 0.9, 1.0], dtype=torch.float64)
        values = torch.tensor([1.0, 3.0, 2.0, 2.0], dtype=torch.float64)
        i = torch.clamp(torch.searchsorted(knots, grid, right=True) - 1, 0, 2)
        w = (grid - knots[i]) / (knots[i + 1] - knots[i])
        numeric = float((values[i] + w * (values[i + 1] - values[i])).mean())
        assert costs.mean(p0, p1) == pytest.approx(numeric + 0.05 + 0.25, rel=1e-3)


class _Clock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


class _Trainer:
    """What a :class:`BudgetPlan` reads and resizes of a trainer."""

    def __init__(self, total: int) -> None:
        self.step = 0
        self.timeline = Timeline(total)
        self.record = SimpleNamespace(steps=total, replans=0, paces=None)

    @property
    def total_steps(self) -> int:
        return self.timeline.total

    def progress(self, step: int) -> float:
        return self.timeline.progress(step)


#: The probe's costs of the simulated fits: their steps get dearer as levels open.
COSTS = StepCosts(0.05, 0.12, 0.1, 0.2, 0.3, 16)


def _budgeted_run(slowdown, plan: bool = True) -> tuple[_Trainer, float, list[float]]:
    """A 100-second budget whose probe planned 1000 steps at :data:`COSTS` (headroom
    included); each step takes what the probe predicted for it times ``slowdown(t)``, ``t``
    the share of the budget gone. Runs to the schedule's end or the deadline, as
    :meth:`Trainer.fit` does. Returns (trainer, share of the budget used, the changes of
    progress at the re-planned steps)."""
    budget = 100.0
    total = int(budget / (COSTS.mean(0.0) * HEADROOM))
    trainer = _Trainer(total)
    clock = _Clock()
    planner = BudgetPlan(COSTS, budget, 0.02 * budget, clock=clock) if plan else None
    if planner is not None:
        planner.start(0)
    jumps = []
    while trainer.step < trainer.total_steps and clock.now < budget:
        p, p_next = trainer.progress(trainer.step), trainer.progress(trainer.step + 1)
        clock.now += slowdown(clock.now / budget) * COSTS.mean(p, p_next)
        trainer.step += 1
        before, p_before = trainer.total_steps, trainer.progress(trainer.step)
        if planner is not None:
            planner.after_step(trainer)
        if trainer.total_steps != before:
            jumps.append(trainer.progress(trainer.step) - p_before)
    return trainer, min(clock.now, budget) / budget, jumps


def _ended_well(trainer: _Trainer, used: float, jumps: list[float]) -> None:
    """The schedule ran to its end within the budget, used at least 95% of it, and its
    progress rose without a jump."""
    assert trainer.step == trainer.total_steps, (trainer.step, trainer.total_steps)
    assert 0.95 <= used <= 1.0, used
    assert jumps and max(abs(j) for j in jumps) < 1e-12
    progress = [trainer.progress(s) for s in range(trainer.total_steps + 1)]
    assert all(b > a for a, b in zip(progress, progress[1:], strict=False))
    assert progress[0] == 0.0 and progress[-1] == pytest.approx(1.0)


@pytest.mark.parametrize("factor", [0.6, 1.3])
def test_a_machine_faster_or_slower_than_the_probe_throughout(factor):
    """A fixed schedule stops at its deadline (slower) or leaves time unused (faster); the
    plan fits the schedule to the pace and ends in time with its budget spent."""
    fixed, used, _ = _budgeted_run(lambda t: factor, plan=False)
    assert (fixed.step < 0.8 * fixed.total_steps) if factor > 1 else used < 0.65
    trainer, used, jumps = _budgeted_run(lambda t: factor)
    _ended_well(trainer, used, jumps)
    assert trainer.total_steps == pytest.approx(fixed.total_steps / factor, rel=0.06)
    assert trainer.record.steps == trainer.total_steps and trainer.record.replans > 0
    assert trainer.record.paces == pytest.approx([factor, factor], rel=0.02)


@pytest.mark.parametrize("factor", [1.5, 2.0, 4.0, 10.0])
@pytest.mark.parametrize(("start", "length"), [(0.0, 0.2), (0.0, 0.5), (0.4, 0.2)])
def test_a_machine_slowed_for_a_while_and_then_freed_gives_the_time_back(factor, start,
                                                                          length):
    """Another program takes the cores for a fifth or half of the budget (at its start, as a
    package install beside a fit does, or in its middle), ``factor`` times slower, then
    leaves: the plan shortens the schedule while the machine is slow and lengthens it once it
    is free, so the fit still uses at least 95% of its budget, ends in time, and runs about
    as many steps as the time at each pace allows."""
    def slowdown(t: float) -> float:
        return factor if start <= t < start + length else 1.0

    quiet, _, _ = _budgeted_run(lambda t: 1.0)
    trainer, used, jumps = _budgeted_run(slowdown)
    _ended_well(trainer, used, jumps)
    expected = quiet.total_steps * (1.0 - length + length / factor)
    assert trainer.total_steps == pytest.approx(expected, rel=0.06)
    assert trainer.record.paces[1] > 0.5 * factor and trainer.record.paces[0] < 1.1


def test_a_fit_slowed_at_its_start_uses_its_time_on_the_real_loop(scene, tmp_path):
    """The trainer's own loop, a fake clock: each step costs what the probe said, three times
    that for the first fifth of the budget. The fit ends at its schedule's end within the
    budget, uses at least 95% of it, and records its re-plans in ``scene.yaml``."""
    from hybridneus.training.scene import FILENAME

    trainer, logger = prepare(scene, tiny("train.iters=10", "train.seed=2"), out=tmp_path,
                              device="cpu")
    costs = StepCosts(0.5, 1.0, 1.0, 0.0, 0.4, trainer.cfg.render.occupancy_every)
    budget = 150.0
    trainer.total_steps = trainer.record.steps = int(budget / (costs.mean(0.0) * HEADROOM))
    planned = trainer.total_steps
    clock = _Clock()
    trainer.clock = clock
    trainer.deadline = budget
    trainer.plan = BudgetPlan(costs, budget, 0.02 * budget, clock=clock)

    def tick(t, logs) -> None:
        p0, p1 = t.progress(t.step - 1), t.progress(t.step)
        clock.now += (3.0 if clock.now < 0.2 * budget else 1.0) * costs.mean(p0, p1)

    trainer.fit([tick], run=logger, progress=False)
    assert not trainer.stopped_early and trainer.step == trainer.total_steps
    assert 0.95 * budget <= clock.now <= budget
    assert trainer.total_steps == pytest.approx(planned * (0.8 + 0.2 / 3), rel=0.1)
    record = SceneRecord.load(logger.run_dir / FILENAME)
    assert record.steps == trainer.step and record.replans >= 2
    assert record.paces[1] == pytest.approx(3.0, rel=0.1)
    assert any("re-planned" in line for line in record.lines())


def test_a_plan_waits_for_a_stretch_of_steps_before_it_measures_a_pace():
    """One slow step does not set the pace: no re-plan before REPLAN_MIN_STEPS steps."""
    trainer = _Trainer(1000)
    clock = _Clock()
    plan = BudgetPlan(COSTS, 100.0, 2.0, clock=clock)
    plan.start(0)
    for _ in range(REPLAN_MIN_STEPS - 1):
        clock.now += 5.0
        trainer.step += 1
        plan.after_step(trainer)
    assert trainer.total_steps == 1000 and trainer.record.replans == 0
    with pytest.raises(RuntimeError, match="start"):
        BudgetPlan(COSTS, 100.0, 2.0, clock=clock).after_step(trainer)


def test_a_replanned_schedule_is_saved_and_resumed_with_its_progress(scene):
    """A checkpoint of a trainer whose schedule was resized holds the knots: the trainer it
    is loaded into has the same progress at every step, and so the same level schedule."""
    cfg = tiny("train.iters=8", "train.seed=3")
    trainer, _ = prepare(scene, cfg, device="cpu")
    for _ in range(3):
        trainer.train_step()
    trainer.timeline.resize(3, 20)
    state = trainer.state_dict()
    other, _ = prepare(scene, cfg, device="cpu")
    other.load_state_dict(state)
    assert other.total_steps == 20 and other.step == 3
    for s in (0, 2, 3, 7, 20):
        assert other.progress(s) == trainer.progress(s)
    assert other.progress(3) == pytest.approx(3 / 8) and other.progress(20) == pytest.approx(1)


def test_a_budgeted_fit_gets_a_plan_on_its_own_clock_and_deadline(scene, tmp_path,
                                                                  monkeypatch):
    """``--minutes``: the probe's count is the schedule, and the plan that re-plans it reads
    the trainer's clock, ends at its deadline and re-plans every fiftieth of the time left
    for training. (The probe's timings are fixed here; no wall-clock time is asserted.)"""
    import hybridneus.training.budget as budget

    monkeypatch.setattr(budget, "step_seconds", lambda trainer: (0.01, 0.01, 0.01, 0.0))
    trainer, logger = prepare(scene, tiny("train.minutes=0.5", "train.seed=1"), out=tmp_path,
                              device="cpu")
    plan = trainer.plan
    assert isinstance(plan, BudgetPlan) and plan.clock is trainer.clock
    assert plan.end == trainer.deadline and 0 < plan.every <= budget.REPLAN_SHARE * 30.0
    assert trainer.total_steps == trainer.record.steps >= 10
    left = plan.every / budget.REPLAN_SHARE  # the seconds the probe's count was made for
    assert abs(trainer.record.steps - left / (plan.costs.mean(0.0) * HEADROOM)) <= 1
    assert "a budget of" in trainer.record.steps_from and trainer.record.replans == 0
    plain, _ = prepare(scene, tiny("train.iters=8"), device="cpu")
    assert plain.plan is None and plain.deadline is None


def test_probing_leaves_the_trainer_as_it_was(scene):
    """A probed trainer trains exactly as one that was never probed."""
    cfg = tiny("train.iters=8", "train.seed=4")
    plain, _ = prepare(scene, cfg, device="cpu")
    probed, _ = prepare(scene, cfg, device="cpu")
    first, full, late, refresh = step_seconds(probed)
    assert min(first, full, late, refresh) > 0
    assert probed.step == 0 and probed.total_steps == 8
    plain.fit(progress=False)
    probed.fit(progress=False)
    a, b = params(plain.field), params(probed.field)
    for k in a:
        assert torch.equal(a[k], b[k]), k


def test_a_budget_is_turned_into_steps_once_and_repeats_with_iters(scene, tmp_path,
                                                                   monkeypatch):
    """The step count is fixed before the first step and recorded; a fit too short to
    re-plan (fewer steps than a re-plan's stretch) given that many steps with --iters follows
    the same schedule and ends with the same field. (The probe's timings are fixed here, so
    that the count does not depend on the machine's speed.)"""
    import hybridneus.training.budget as budget

    monkeypatch.setattr(budget, "step_seconds", lambda trainer: (8.0, 8.0, 8.0, 0.0))
    cfg = tiny("train.minutes=2", "train.seed=2")
    timed = fit(scene, cfg, out=tmp_path / "timed", device="cpu", started=time.perf_counter())
    record = SceneRecord.load(timed.run_dir / "scene.yaml")
    assert "budget" in record.steps_from and "8000.0, 8000.0 and 8000.0 ms" in record.steps_from
    assert 10 <= record.steps < min(REPLAN_MIN_STEPS, 120.0 / (8.0 * HEADROOM))
    assert timed.trainer_step == record.steps and record.replans == 0
    again = fit(scene, tiny(f"train.iters={record.steps}", "train.seed=2"), device="cpu")
    a, b = params(timed), params(again)
    for k in a:
        assert torch.equal(a[k], b[k]), k


def test_a_run_stops_at_its_deadline_and_records_where(scene, caplog, tmp_path):
    trainer, logger = prepare(scene, tiny("train.iters=100000"), out=tmp_path, device="cpu")
    clock = _Clock()
    trainer.clock = clock
    trainer.deadline = 5.0

    def tick(t, logs) -> None:
        clock.now += 1.0

    with caplog.at_level("WARNING", logger="hybridneus"):
        trainer.fit([tick], run=logger, progress=False)
    assert trainer.stopped_early and trainer.step == 5
    assert "the time budget ran out" in caplog.text
    record = SceneRecord.load(logger.run_dir / "scene.yaml")
    assert record.steps == 100000 and record.stopped_at == 5
    assert any("stopped at step" in line for line in record.lines())


def test_a_budget_too_short_to_train_is_refused(scene, tmp_path):
    from hybridneus.errors import ConfigError

    with pytest.raises(ConfigError, match="train.minutes: 0.001 min leave time for"):
        fit(scene, tiny("train.minutes=0.001"), out=tmp_path, device="cpu")
