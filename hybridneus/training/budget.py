"""A wall-clock budget (``--minutes``) turned into a number of steps before training, and
re-planned during it when the steps run at another pace than measured.

The schedules are fractions of training, so a fit must know its length before its first
step. A step's cost depends on how far training is: a two-core CPU took 53 ms per step with
4 of 16 grid levels open, 92 ms with all 16 and the curvature prior on, and 85 ms once that
prior had faded. :func:`budget_steps` times a few steps at three points of the schedule (the
start, where all levels are open, and near the end) on the trainer's own data, and then puts
everything back (parameters, optimiser, random states), so the fit starts exactly as if it had
not been probed. The step count is recorded in the run's ``scene.yaml``; ``--iters`` with it
repeats the run's schedule on any machine.

A fresh field is cheaper to step than a trained one (on a 2-core Intel Xeon, late steps of
trained fields took 2 to 2.5 times the probe's time for the same number of samples, most of
it on subnormal floats, which the field and renderer now hold at zero: docs/training.md),
and a machine's speed drifts: on a 2-core AMD EPYC the probe's mean step varied by 6% to 13%
(coefficient of variation) between probes a few seconds apart, with 5, 10 or 20 timed steps
per point (docs/training.md), and more over a fit's minutes. Fits stopped at their deadline
with 72-78% of their schedule done when the probe was too fast (the learning rate never
decayed, the late priors never faded) and ended with up to 15% of the budget unused when it
was too slow.
:class:`BudgetPlan` therefore re-plans at a few points of training (``train.replan_at``): it
compares the wall-clock time the last stretch of steps took with what the probe predicted
for them and, if the rest would overrun, shortens the schedule to what the time left allows
at the measured pace; with ``train.replan_lengthen`` it also lengthens a schedule that would
end early. A re-plan changes the rate at which progress grows from that step on, not the
progress reached (:class:`~hybridneus.training.schedules.Timeline`), so no schedule jumps.
Each re-plan is logged and recorded in ``scene.yaml``; ``--iters`` with the final count
follows the re-planned schedule's length but not its change of rate, so it repeats such a
run closely rather than exactly.
"""

from __future__ import annotations

import copy
import logging
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from hybridneus.training.schedules import Timeline

#: Steps timed per probe point, after the warm-up steps.
PROBE_STEPS = 5
PROBE_WARMUP = 3
#: Where the last probe point sits.
LATE = 0.9
#: Headroom for what the probe does not time (the loop's logging, the progress bar) and for
#: timing noise: the deadline stops a fit that runs over, so the estimate errs low.
HEADROOM = 1.03
#: The nominal schedule length the probe steps are taken in (only their progress matters).
_NOMINAL = 100_000


def _timed_steps(trainer, p: float) -> float:
    """Median seconds of a training step at progress ``p`` (no occupancy refresh)."""
    every = max(trainer.cfg.render.occupancy_every, 1)
    trainer.timeline = Timeline(_NOMINAL)
    trainer.step = int(p * _NOMINAL) // every * every + 1
    times = []
    for i in range(PROBE_WARMUP + PROBE_STEPS):
        if trainer.step % every == 0:
            trainer.step += 1
        start = time.perf_counter()
        trainer.train_step()
        if i >= PROBE_WARMUP:
            times.append(time.perf_counter() - start)
    return statistics.median(times)


def step_seconds(trainer) -> tuple[float, float, float, float]:
    """``(first, full, late, refresh)``: seconds per step at the start, where all grid levels
    have opened, and at ``LATE`` of training, and per occupancy refresh. The trainer's state
    is restored afterwards."""
    saved = copy.deepcopy(trainer.state_dict())
    try:
        first = _timed_steps(trainer, 0.0)
        full = _timed_steps(trainer, _full_at(trainer))
        late = _timed_steps(trainer, LATE)
        refreshes = []
        for _ in range(3):
            start = time.perf_counter()
            trainer.refresh_occupancy()
            refreshes.append(time.perf_counter() - start)
        refresh = statistics.median(refreshes)
    finally:
        trainer.load_state_dict(saved)
        trainer.refresh_occupancy()
    return first, full, late, refresh


def _full_at(trainer) -> float:
    return min(max(trainer.cfg.grid.opened_at, 0.0), LATE)


def mean_step_seconds(first: float, full: float, late: float, refresh: float, full_at: float,
                      occupancy_every: int) -> float:
    """The mean cost of a step over a whole schedule, the cost interpolated linearly between
    the probe points (0, ``first``), (``full_at``, ``full``), (``LATE``, ``late``) and held
    after the last; one refresh every ``occupancy_every`` steps."""
    return StepCosts(first, full, late, refresh, full_at, occupancy_every).mean(0.0)


@dataclass
class StepCosts:
    """The probe's seconds per step as a function of progress (see :func:`step_seconds`),
    plus the seconds per step spent outside it (``overhead``: previews, checkpoints)."""

    first: float
    full: float
    late: float
    refresh: float
    full_at: float
    occupancy_every: int
    overhead: float = 0.0

    def _knots(self) -> list[tuple[float, float]]:
        return [(0.0, self.first), (self.full_at, self.full), (LATE, self.late), (1.0, self.late)]

    def _integral(self, p: float) -> float:
        """The integral of the interpolated step cost from 0 to ``p``."""
        total = 0.0
        knots = self._knots()
        for (p0, c0), (p1, c1) in zip(knots, knots[1:], strict=False):
            if p <= p0:
                break
            end = min(p, p1)
            if end > p0:
                c_end = c0 + (c1 - c0) * (end - p0) / (p1 - p0)
                total += (end - p0) * (c0 + c_end) / 2.0
        return total

    def mean(self, p0: float, p1: float = 1.0) -> float:
        """The mean seconds per step between progress ``p0`` and ``p1`` (refresh and overhead
        included)."""
        p0, p1 = min(max(p0, 0.0), 1.0), min(max(p1, 0.0), 1.0)
        if p1 - p0 < 1e-9:
            p1 = min(1.0, p0 + 1e-6)
            p0 = p1 - 1e-6
        step = (self._integral(p1) - self._integral(p0)) / (p1 - p0)
        return step + self.refresh / max(self.occupancy_every, 1) + self.overhead


@dataclass
class BudgetPlan:
    """Re-plans a budgeted fit's length when its steps run slower than the probe said (and,
    with ``lengthen``, when they run faster).

    Call :meth:`after_step` after every step; at each progress point of ``at`` it measures
    the seconds the steps since the previous point took against the ``costs`` predicted for
    them and, when the remaining steps at that pace would end after ``end`` (a ``clock()``
    value), or with ``lengthen`` well before it, resizes the trainer's
    :class:`~hybridneus.training.schedules.Timeline` (and its scene record's ``steps``) to
    what fits. The progress reached stays where it is: every schedule goes on from there at
    the new rate, without a jump.

    Attributes:
        replans: one line per re-plan that changed the schedule.
    """

    costs: StepCosts
    end: float
    at: tuple[float, ...]
    lengthen: bool = False
    clock: Callable[[], float] = time.perf_counter
    replans: list[str] = field(default_factory=list)
    _mark: tuple[int, float, float] | None = None
    _next: int = 0

    def start(self, step: int, p: float = 0.0) -> None:
        """Begin timing at ``step`` (the fit's first, at progress ``p``)."""
        self._mark = (step, self.clock(), p)

    def after_step(self, trainer) -> None:
        """Re-plan if ``trainer`` has just passed the next point of ``at``."""
        if self._mark is None:
            raise RuntimeError("BudgetPlan.start() was not called before the first step")
        p = trainer.progress(trainer.step)
        if self._next >= len(self.at) or p < self.at[self._next]:
            return
        while self._next < len(self.at) and p >= self.at[self._next]:
            self._next += 1
        now = self.clock()
        step0, t0, p0 = self._mark
        self._mark = (trainer.step, now, p)
        done = trainer.step - step0
        if done <= 0:
            return
        predicted = self.costs.mean(p0, p) * done
        pace = (now - t0) / predicted if predicted > 0 else 1.0
        left = self.end - now
        rest = self.costs.mean(p) * pace * HEADROOM
        total = trainer.total_steps
        fits = trainer.step + max(1, int(left / rest)) if left > 0 else trainer.step + 1
        if fits == total or (fits > total and not self.lengthen):
            return
        line = (f"re-planned at step {trainer.step}: {total} -> {fits} steps (the last "
                f"{done} took {pace:.2f}x the probe's time)")
        trainer.timeline.resize(trainer.step, fits)
        trainer.record.steps = fits
        trainer.record.steps_from += f"; {line}"
        self.replans.append(line)
        logging.getLogger("hybridneus").info(line)


def budget_steps(trainer, seconds: float,
                 overhead: float = 0.0) -> tuple[int, str, StepCosts]:
    """The number of steps that fit ``seconds`` of training, one line on how, and the probed
    costs (for a :class:`BudgetPlan`).

    Args:
        trainer: a freshly built (or just resumed) trainer; probed, then restored.
        seconds: wall-clock seconds left for training.
        overhead: seconds per step spent outside the step itself (previews, checkpoints).
    """
    first, full, late, refresh = step_seconds(trainer)
    costs = StepCosts(first, full, late, refresh, _full_at(trainer),
                      trainer.cfg.render.occupancy_every, overhead)
    per_step = costs.mean(0.0)
    steps = max(1, int(seconds / (per_step * HEADROOM)))
    how = (f"a budget of {seconds:.0f} s at {per_step * 1000:.1f} ms per step (probed: "
           f"{first * 1000:.1f}, {full * 1000:.1f} and {late * 1000:.1f} ms at the start, "
           f"with all grid levels and late)")
    return steps, how, costs
