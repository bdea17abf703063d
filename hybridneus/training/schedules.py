"""Every schedule of a fit, as a pure function of its progress ``p`` in [0, 1].

``p = step / total_steps``: the same config gives the same schedule on any machine, and a fit
of a different length stretches it instead of cutting it. Lengths and onsets are fractions
of training too. A budgeted fit whose length is re-planned part-way (:mod:`.budget`) keeps
its progress where it was and changes only its rate from there on (:class:`Timeline`).
"""

from __future__ import annotations

from dataclasses import dataclass, field


def progress(step: int, total: int) -> float:
    """``step / total`` (0 for a schedule of no length)."""
    return step / total if total > 0 else 0.0


@dataclass
class Timeline:
    """A fit's progress by step: ``step / total`` until :meth:`resize` changes the length;
    from then on linear from the progress reached at the resized step to 1 at the new end.

    Setting ``total`` directly changes the length without a knot (a resumed run given more
    steps, or a budget fixed before the first step): at step 0 the two agree.

    Attributes:
        total: the schedule's length in steps.
        knots: ``(step, progress)`` pairs, the first ``(0, 0.0)``; one more per resize.
    """

    total: int
    knots: list[tuple[int, float]] = field(default_factory=lambda: [(0, 0.0)])

    def progress(self, step: float) -> float:
        """The progress at ``step`` (past the end it goes on rising at the last rate)."""
        if len(self.knots) == 1:
            return progress(step, self.total)  # exactly step / total, as before any resize
        # between two knots the progress is where the schedule of that stretch put it
        for (s0, p0), (s1, p1) in zip(self.knots, self.knots[1:], strict=False):
            if step < s1:
                return p0 + (step - s0) * (p1 - p0) / (s1 - s0)
        s0, p0 = self.knots[-1]
        if self.total <= s0:
            return 1.0
        return p0 + (step - s0) * (1.0 - p0) / (self.total - s0)

    def position(self, step: int) -> float:
        """``step`` on a schedule of ``total`` steps never resized, that has the same
        progress: ``step`` itself before any resize (for the step-counted coarse-to-fine
        schedule, :meth:`~hybridneus.model.field.HybridField.update_step`)."""
        if len(self.knots) == 1:
            return float(step)
        return self.progress(step) * self.total

    def resize(self, step: int, total: int) -> None:
        """Make the schedule ``total`` steps long from ``step`` on, with its progress at
        ``step`` unchanged."""
        p = self.progress(step)
        self.knots = [k for k in self.knots if k[0] < step] + [(int(step), float(p))]
        self.total = int(total)


def ramp(p: float, start: float, length: float) -> float:
    """0 before ``start``, then rising linearly to 1 over ``length`` (1 at once when
    ``length <= 0``).

    A term or bound switched on at full strength part-way through training (Adam has scaled
    its steps to the other terms' gradients) jolts the field; one grown from 0 does not.
    """
    if p < start:
        return 0.0
    if length <= 0:
        return 1.0
    return min(1.0, (p - start) / length)


def lr_factor(p: float, warmup: float, decay_start: float, decay_final: float) -> float:
    """Learning-rate multiplier: linear warm-up over ``warmup``, constant, then an exponential
    decay from ``decay_start`` that reaches ``decay_final`` at ``p = 1``.

    The trainer takes it at the end of each step (``p = (step + 1) / total``), so that the
    first step of a warm-up moves the field a little instead of not at all.
    """
    f = ramp(p, 0.0, warmup) if warmup > 0 else 1.0
    if p > decay_start and decay_start < 1.0:
        f *= decay_final ** min(1.0, (p - decay_start) / (1.0 - decay_start))
    return f


def geometric(p: float, start: float, end: float, at: float) -> float:
    """``start`` growing geometrically to ``end`` at ``p = at``, then held."""
    if at <= 0:
        return end
    return start * (end / start) ** min(1.0, p / at)


def sharpness_floor(
    p: float, start: float, floor: float, at: float, delay: float = 0.0, blend: float = 0.0
) -> float:
    """The lowest NeuS sharpness allowed at ``p`` (0.0: no floor).

    None before ``delay``; then the curve :func:`geometric` from ``start`` (the initial
    sharpness) to ``floor`` at ``at``, or ``floor`` itself when it is below ``start``. Over
    ``blend`` after the delay the curve's value ``f`` is replaced by ``f ** w``, ``w`` rising
    linearly from near 0 to 1: the floor grows out of 1 instead of jumping to the curve
    (lifted from 6 to 21 in one step, a bunny's render went transparent and never came back).
    """
    if floor <= 0 or p < delay:
        return 0.0
    value = floor if floor <= start else geometric(p, start, floor, at)
    if blend <= 0:
        return value
    return value ** max(ramp(p, delay, blend), 1e-3)


def eased(p: float, start: float | None, end: float, length: float) -> float:
    """``start`` moving geometrically to ``end`` over ``length``, then ``end`` (``end``
    throughout when ``start`` is ``None``)."""
    if start is None or length <= 0 or p >= length:
        return end
    return start * (end / start) ** (p / length)


def fading(p: float, end: float) -> float:
    """1 falling linearly to 0 at ``end`` (1 throughout when ``end <= 0``)."""
    if end <= 0:
        return 1.0
    return max(0.0, 1.0 - p / end)

