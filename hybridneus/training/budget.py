"""A wall-clock budget (``--minutes``) turned into a number of steps, once, before training.

The schedules are fractions of training, so a fit must know its length before its first
step. A step's cost depends on how far training is: a two-core CPU took 53 ms per step with
4 of 16 grid levels open, 92 ms with all 16 and the curvature prior on, and 85 ms once that
prior had faded. :func:`budget_steps` times a few steps at three points of the schedule (the
start, where all levels are open, and near the end) on the trainer's own data, and then puts
everything back (parameters, optimiser, random states), so the fit starts exactly as if it had
not been probed. The step count is recorded in the run's ``scene.yaml``; ``--iters`` with it
repeats the run's schedule on any machine.
"""

from __future__ import annotations

import copy
import statistics
import time

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
    trainer.total_steps = _NOMINAL
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
    return min(max(trainer.cfg.grid.levels_full_at, 0.0), LATE)


def mean_step_seconds(first: float, full: float, late: float, refresh: float, full_at: float,
                      occupancy_every: int) -> float:
    """The mean cost of a step over a whole schedule, the cost interpolated linearly between
    the probe points (0, ``first``), (``full_at``, ``full``), (``LATE``, ``late``) and held
    after the last; one refresh every ``occupancy_every`` steps."""
    per_step = (full_at * (first + full) / 2.0 + (LATE - full_at) * (full + late) / 2.0
                + (1.0 - LATE) * late)
    return per_step + refresh / max(occupancy_every, 1)


def budget_steps(trainer, seconds: float, overhead: float = 0.0) -> tuple[int, str]:
    """The number of steps that fit ``seconds`` of training, and one line on how.

    Args:
        trainer: a freshly built (or just resumed) trainer; probed, then restored.
        seconds: wall-clock seconds left for training.
        overhead: seconds per step spent outside the step itself (previews, checkpoints).
    """
    first, full, late, refresh = step_seconds(trainer)
    per_step = mean_step_seconds(first, full, late, refresh, _full_at(trainer),
                                 trainer.cfg.render.occupancy_every) + overhead
    steps = max(1, int(seconds / (per_step * HEADROOM)))
    how = (f"a budget of {seconds:.0f} s at {per_step * 1000:.1f} ms per step (probed: "
           f"{first * 1000:.1f}, {full * 1000:.1f} and {late * 1000:.1f} ms at the start, "
           f"with all grid levels and late)")
    return steps, how
