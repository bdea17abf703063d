"""A --minutes budget becomes a step count before the first step, recorded and repeatable,
and is re-planned during the fit when the steps run at another pace than the probe measured."""

from __future__ import annotations

import time
from types import SimpleNamespace

import pytest
import torch
from fitting import params, tiny

from hybridneus.api import fit, prepare
from hybridneus.training.budget import BudgetPlan, StepCosts, mean_step_seconds, step_seconds
from hybridneus.training.scene import SceneRecord
from hybridneus.training.schedules import Timeline


def test_the_mean_step_interpolates_the_probe_points():
    # 0.4 * (1 + 3) / 2 + 0.5 * (3 + 2) / 2 + 0.1 * 2 = 0.8 + 1.25 + 0.2, plus 1 / 10
    assert mean_step_seconds(1.0, 3.0, 2.0, 1.0, 0.4, 10) == pytest.approx(2.35)


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
        self.record = SimpleNamespace(steps=total, steps_from="budget")

    @property
    def total_steps(self) -> int:
        return self.timeline.total

    def progress(self, step: int) -> float:
        return self.timeline.progress(step)


def _budgeted_run(pace, at: tuple[float, ...], lengthen: bool = False
                  ) -> tuple[_Trainer, bool, BudgetPlan]:
    """Steps that each take ``pace`` times what the probe predicted for them (a number, or a
    function of the step's index), on a planned 1000-step schedule whose probe said it fills
    100 s exactly; runs to the schedule's end or the deadline. Returns (trainer, whether it
    ended by the deadline, plan); the plan's ``jumps`` are the changes of progress at the
    re-planned steps, its ``used`` the share of the budget spent."""
    costs = StepCosts(0.05, 0.12, 0.1, 0.2, 0.3, 16)
    total = 1000
    end = costs.mean(0.0) * total
    trainer = _Trainer(total)
    clock = _Clock()
    plan = BudgetPlan(costs, end, at, lengthen=lengthen, clock=clock)
    plan.start(0)
    plan.jumps = []
    while trainer.step < trainer.total_steps and clock.now < end:
        p, p_next = trainer.progress(trainer.step), trainer.progress(trainer.step + 1)
        factor = pace(trainer.step) if callable(pace) else pace
        clock.now += factor * costs.mean(p, p_next)
        trainer.step += 1
        before, p_before = trainer.total_steps, trainer.progress(trainer.step)
        plan.after_step(trainer)
        if trainer.total_steps != before:
            plan.jumps.append(trainer.progress(trainer.step) - p_before)
    plan.used = clock.now / end
    return trainer, clock.now <= end, plan


def test_a_plan_shortens_an_overrunning_schedule_so_that_it_ends_in_time():
    """At 1.3x the probe's step time a fixed schedule stops at its deadline near 77%; the plan
    shortens it once it has measured the pace, and the fit reaches the schedule's end in time,
    its progress never jumping."""
    fixed, _, _ = _budgeted_run(1.3, at=())
    assert fixed.step < 0.8 * fixed.total_steps
    trainer, in_time, plan = _budgeted_run(1.3, at=(0.05, 0.15, 0.3, 0.5, 0.7))
    assert trainer.step == trainer.total_steps and in_time
    assert 700 <= trainer.total_steps < 1000 and trainer.record.steps == trainer.total_steps
    assert plan.replans and "re-planned at step" in trainer.record.steps_from
    assert "1.30x the probe's time" in plan.replans[0]
    assert plan.jumps and max(abs(j) for j in plan.jumps) < 1e-12
    assert trainer.progress(trainer.step) == pytest.approx(1.0) and plan.used > 0.95


def test_a_plan_follows_a_machine_that_slows_part_way():
    """A machine three times slower from step 300 on, and one step after that slower still:
    the plan shortens at the points after the slow-down, the fit ends in time with most of
    its budget used, and its progress rises without a jump to 1 at the end."""
    def pace(index: int) -> float:
        return 6.0 if index == 486 else 3.0 if index >= 300 else 1.0

    trainer, in_time, plan = _budgeted_run(pace, at=(0.05, 0.15, 0.3, 0.5, 0.7))
    assert in_time and trainer.step == trainer.total_steps < 700
    assert len(plan.replans) >= 2 and plan.used > 0.9
    assert max(abs(j) for j in plan.jumps) < 1e-12
    steps = range(trainer.total_steps + 1)
    progress = [trainer.progress(s) for s in steps]
    assert all(b > a for a, b in zip(progress, progress[1:], strict=False))
    assert progress[0] == 0.0 and progress[-1] == pytest.approx(1.0)


def test_a_plan_never_lengthens_a_schedule_unless_told():
    trainer, _, plan = _budgeted_run(0.7, at=(0.05, 0.15, 0.3, 0.5, 0.7))
    assert trainer.total_steps == 1000 and not plan.replans
    assert plan.used < 0.75  # a quarter of the budget left unused


def test_a_plan_told_to_lengthen_uses_the_time_it_gains_and_ends_in_time():
    """At 0.7x the probe's step time, train.replan_lengthen lets the plan lengthen the
    schedule from its first point on, without moving the progress reached; the fit ends in
    time with (nearly) all of its budget used. A slow fit is shortened as before."""
    trainer, in_time, plan = _budgeted_run(0.7, at=(0.05, 0.15, 0.3, 0.5, 0.7), lengthen=True)
    assert in_time and trainer.step == trainer.total_steps > 1300
    assert plan.replans[0].startswith("re-planned at step 50:")
    assert max(abs(j) for j in plan.jumps) < 1e-12 and plan.used > 0.95
    slow, in_time, _ = _budgeted_run(1.3, at=(0.05, 0.15, 0.3, 0.5, 0.7), lengthen=True)
    assert in_time and slow.step == slow.total_steps < 1000


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


def test_a_budgeted_fit_slower_than_its_probe_is_replanned_and_finishes(scene, tmp_path,
                                                                        monkeypatch):
    """A probe that claims 5 ms per step plans far too many steps for a 15 s budget (about
    3000, of which a real step time allows a fifth); the fit shortens its schedule, records
    the re-plan, and gets through (nearly) all of the shortened one. The deadline may still
    cut the last few steps when the machine slows after the last re-plan point, which a
    shared CI machine does, so the test asks for 90% rather than the exact end."""
    import hybridneus.training.budget as budget

    monkeypatch.setattr(budget, "step_seconds", lambda trainer: (0.005, 0.005, 0.005, 0.0))
    started = time.perf_counter()
    field = fit(scene, tiny("train.minutes=0.25", "train.seed=1"), out=tmp_path,
                device="cpu", started=started)
    record = SceneRecord.load(field.run_dir / "scene.yaml")
    assert "re-planned at step" in record.steps_from, record.steps_from
    assert record.steps < 0.6 * round(15.0 / 0.005)
    if record.stopped_at is None:
        assert field.trainer_step == record.steps
    else:
        assert record.stopped_at >= 0.9 * record.steps, (record.stopped_at, record.steps)
    assert time.perf_counter() - started < 15.0 + 5.0


def test_a_budgeted_fit_faster_than_its_probe_is_lengthened_when_told(scene, tmp_path,
                                                                      monkeypatch):
    """A probe that claims 1 s per step plans about 15 steps for an 18 s budget; with
    train.replan_lengthen the first re-plan (at 10% of them) lengthens the schedule to what
    the real pace allows, and the fit spends its budget on the longer schedule and reaches
    (nearly) its end, its progress near 1."""
    import re

    import hybridneus.training.budget as budget

    monkeypatch.setattr(budget, "step_seconds", lambda trainer: (1.0, 1.0, 1.0, 0.0))
    seen = {}

    def watch(trainer, logs) -> None:
        seen["last"] = trainer.progress(trainer.step)

    field = fit(scene, tiny("train.minutes=0.3", "train.seed=1", "train.replan_lengthen=true",
                            "train.replan_at=[0.1,0.5]"),
                [watch], out=tmp_path, device="cpu", started=time.perf_counter())
    record = SceneRecord.load(field.run_dir / "scene.yaml")
    planned, lengthened = map(int, re.search(r"re-planned at step \d+: (\d+) -> (\d+)",
                                             record.steps_from).groups())
    assert planned <= 18 and lengthened > 3 * planned, record.steps_from
    ran = field.trainer_step if record.stopped_at is None else record.stopped_at
    assert ran >= 0.8 * record.steps > 2 * planned, (ran, record.steps)
    assert seen["last"] > 0.8


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
    """The step count is fixed before the first step and recorded; a fit given that many
    steps with --iters follows the same schedule and ends with the same field. (The probe's
    timings are fixed here, so that the count does not depend on the machine's speed; at
    2 s a probed step is far slower than a real one, so a loaded machine still finishes.)"""
    import hybridneus.training.budget as budget

    monkeypatch.setattr(budget, "step_seconds", lambda trainer: (2.0, 2.0, 2.0, 0.0))
    cfg = tiny("train.minutes=0.5", "train.seed=2")
    started = time.perf_counter()
    timed = fit(scene, cfg, out=tmp_path / "timed", device="cpu", started=started)
    left = 30.0 - (time.perf_counter() - started)
    record = SceneRecord.load(timed.run_dir / "scene.yaml")
    assert "budget" in record.steps_from and "2000.0, 2000.0 and 2000.0 ms" in record.steps_from
    assert 5 <= record.steps < 30.0 / (2.0 * budget.HEADROOM)
    assert timed.trainer_step == record.steps and left > 0
    again = fit(scene, tiny(f"train.iters={record.steps}", "train.seed=2"), device="cpu")
    a, b = params(timed), params(again)
    for k in a:
        assert torch.equal(a[k], b[k]), k


def test_a_run_stops_at_its_deadline_and_records_where(scene, caplog, tmp_path):
    trainer, logger = prepare(scene, tiny("train.iters=100000"), out=tmp_path, device="cpu")
    trainer.deadline = time.perf_counter() + 0.5
    with caplog.at_level("WARNING", logger="hybridneus"):
        trainer.fit(run=logger, progress=False)
    assert trainer.stopped_early and 0 < trainer.step < 100000
    assert "the time budget ran out" in caplog.text
    record = SceneRecord.load(logger.run_dir / "scene.yaml")
    assert record.steps == 100000 and record.stopped_at == trainer.step
    assert any("stopped at step" in line for line in record.lines())


def test_a_budget_too_short_to_train_is_refused(scene, tmp_path):
    from hybridneus.errors import ConfigError

    with pytest.raises(ConfigError, match="train.minutes: 0.001 min leave time for"):
        fit(scene, tiny("train.minutes=0.001"), out=tmp_path, device="cpu")
