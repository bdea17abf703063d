"""A wall-clock budget (``--minutes``) turned into a number of steps before training, and
re-planned during it to the pace the steps actually run at.

The schedules are fractions of training, so a fit must know its length before its first
step. A step's cost depends on how far training is (a two-core CPU took 53 ms per step with 4
of 16 grid levels open, 92 ms with all 16 and the curvature prior on, and 85 ms once that
prior had faded), so :func:`budget_steps` times a few steps at three points of the schedule
(the start, where all levels are open, and near the end) on the trainer's own data, and then
puts everything back (parameters, optimiser, random states): the fit starts exactly as if it
had not been probed.

That first count is a guess. A trained field steps at another pace than the fresh one the
probe timed, a machine's speed drifts, and other programs take the cores for a while and give
them back. :class:`BudgetPlan` therefore re-plans all through the fit: every few seconds it
compares the time the last stretch of steps took with what the probe predicted for them and
resizes the schedule so that the steps left, at that pace, fill the time left. A machine that
slows shortens the schedule, one that speeds up again lengthens it, and the fit ends at its
deadline with its schedule done. A re-plan changes the rate at which progress grows from
that step on, not the progress reached (:class:`~hybridneus.training.schedules.Timeline`),
so warm-up, level opening and decay never jump. The count of re-plans and the range of paces
go into ``scene.yaml``; ``--iters`` with the final step count follows the re-planned
schedule's length but not its changes of rate, so it repeats such a run closely rather than
exactly.
"""

from __future__ import annotations

import copy
import logging
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass

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


#: A re-plan's stretch: at least this share of the budget's training time (or a quarter of
#: the time left, near the end) and this many steps, so that one slow step does not set it.
REPLAN_SHARE = 0.02
REPLAN_MIN_STEPS = 16


@dataclass
class BudgetPlan:
    """Re-plans a budgeted fit's length to the pace its steps run at.

    Call :meth:`start` before the first step and :meth:`after_step` after every step. Once a
    stretch of ``every`` seconds (or a quarter of the time left, whichever is shorter) and at
    least :data:`REPLAN_MIN_STEPS` steps has passed, it measures the seconds the stretch took
    against the ``costs`` predicted for it, and resizes the trainer's
    :class:`~hybridneus.training.schedules.Timeline` (and its scene record's ``steps``) to
    the steps that fit the time to ``end`` (a ``clock()`` value) at that pace. The progress
    reached stays where it is: every schedule goes on from there at the new rate. The record
    counts the re-plans that changed the length (``replans``) and keeps the slowest and
    fastest pace measured (``paces``, multiples of the probe's time).
    """

    costs: StepCosts
    end: float
    every: float
    clock: Callable[[], float] = time.perf_counter
    _mark: tuple[int, float, float] | None = None

    def start(self, step: int, p: float = 0.0) -> None:
        """Begin timing at ``step`` (the fit's first, at progress ``p``)."""
        self._mark = (step, self.clock(), p)

    def after_step(self, trainer) -> None:
        """Re-plan if the stretch since the last re-plan is long enough."""
        if self._mark is None:
            raise RuntimeError("BudgetPlan.start() was not called before the first step")
        if trainer.step >= trainer.total_steps:
            return  # the schedule is done: the fit ends here
        step0, t0, p0 = self._mark
        now = self.clock()
        left = self.end - now
        done = trainer.step - step0
        if done < REPLAN_MIN_STEPS or now - t0 < min(self.every, max(left, 0.0) / 4.0):
            return
        p = trainer.progress(trainer.step)
        self._mark = (trainer.step, now, p)
        predicted = self.costs.mean(p0, p) * done
        pace = (now - t0) / predicted if predicted > 0 else 1.0
        lo, hi = trainer.record.paces or (pace, pace)
        trainer.record.paces = [round(min(lo, pace), 3), round(max(hi, pace), 3)]
        rest = self.costs.mean(p) * pace * HEADROOM
        fits = trainer.step + max(1, int(left / rest)) if left > 0 else trainer.step + 1
        if fits == trainer.total_steps:
            return
        logging.getLogger("hybridneus").debug(
            "re-planned at step %d: %d -> %d steps (the last %d took %.2fx the probe's time)",
            trainer.step, trainer.total_steps, fits, done, pace)
        trainer.timeline.resize(trainer.step, fits)
        trainer.record.steps = fits
        trainer.record.replans += 1


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
