"""How large a log-brightness change the events ask for, and the tonemap eps that can render it.

The event loss compares ``log(c1**2.2 + eps) - log(c0**2.2 + eps)`` of rendered colours in
[0, 1] with ``C * E``. Whatever the colours, that difference lies within
``+-log((1 + eps) / eps)``: with the ``nerf`` group's eps = 0.1 no render can make a change
larger than 2.4. Data simulated with a smaller eps (dark objects fire many more events) then
asks for changes no colour can give, and the fit chases them with floaters (a xylophone
made with eps = 0.001 and fitted with 0.1 scored Chamfer 0.099, with 0.001 0.033). A smaller
eps in the loss only remaps the colours the fit learns (any change within range has a colour
that makes it), so lowering eps is safe where keeping it is not; it was better even on data
made with eps = 0.1 (docs/data.md).
"""

from __future__ import annotations

import math

import numpy as np

from hybridneus.data.dataset import SplitData
from hybridneus.data.presets import ScenePreset

__all__ = ["event_extent", "reachable_eps", "loss_eps"]


def event_extent(
    split: SplitData, preset: ScenePreset, n_windows: int = 64, percentile: float = 99.9
) -> float | None:
    """The largest log-brightness change the events ask for within one window, ``C * |E|``.

    Accumulates ``n_windows`` windows of the preset's longest length (``max_window`` views,
    polarity offset included) ending at evenly spaced views, and takes ``percentile`` of
    ``|E|`` over their pixels with events, so that a few hot pixels do not decide it.

    Args:
        split: the split to read.
        preset: threshold C, polarity offset and max window.
        n_windows: windows to accumulate.
        percentile: percentile of ``|E|`` over the pixels with events, in (0, 100].

    Returns:
        ``C * |E|`` at the percentile, or ``None`` when no window holds an event.
    """
    from hybridneus.data.windows import event_frame, offset_of

    n = split.n_views
    if n < 2:
        return None
    dt = split.t_max / (n - 1)
    span = min(preset.max_window, n - 1)
    ends = np.unique(np.linspace(span, n - 1, num=max(1, n_windows)).round().astype(int))
    values = []
    for i in ends:
        frame = event_frame(split, (i - span) * dt, i * dt, offset_of(split, preset))
        values.append(np.abs(frame[frame != 0]))
    counts = np.concatenate(values)
    if counts.size == 0:
        return None
    return float(preset.threshold * np.percentile(counts, percentile))


def reachable_eps(change: float, margin: float = 1.2) -> float:
    """The largest eps whose range ``log((1 + eps) / eps)`` is ``margin * change``.

    Args:
        change: log-brightness change to reach (e.g. from :func:`event_extent`), > 0.
        margin: headroom factor, >= 1.

    Returns:
        eps > 0.
    """
    return 1.0 / math.expm1(margin * change)


def loss_eps(preset_eps: float, change: float | None, eps_max: float = 1e-3) -> tuple[float, str]:
    """The tonemap eps training uses: the preset's, capped at ``eps_max`` and at
    :func:`reachable_eps` of the events' ``change`` (2 significant digits), and why.

    Args:
        preset_eps: the preset's ``tonemap_eps``.
        change: :func:`event_extent` of the training split (``None``: no bound from events).
        eps_max: cap on the preset's eps; <= 0 for none.

    Returns:
        ``(eps, reason)``: ``reason`` is one line saying which bound decided it.
    """
    need = reachable_eps(change) if change else math.inf
    cap = min(need, eps_max) if eps_max > 0 else need
    if cap >= preset_eps:
        return float(preset_eps), "the preset's (within estimate.eps_max and what the events need)"
    if need <= cap:
        why = f"the events ask for log-brightness changes up to {change:.2f} in one window"
    else:
        why = f"capped at estimate.eps_max {eps_max:g}"
    return float(f"{cap:.2g}"), why
