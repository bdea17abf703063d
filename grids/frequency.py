"""NeuS-style sinusoidal positional encoding with EventNeuS frequency annealing."""

from __future__ import annotations

import math

import torch
from torch import nn

from hybridneus.errors import ConfigError

__all__ = ["FrequencyEncoding", "annealing_weights", "full_bands"]


def annealing_weights(
    step: float | torch.Tensor,
    n_frequencies: int,
    n_fmin: int,
    n_fmax: int,
    n_anneal: int | None,
) -> torch.Tensor:
    """EventNeuS band weights beta_k(n) for k = 0 .. n_frequencies - 1.

    ``beta_k(n) = (1 - cos(pi * clamp(alpha(n) - k + n_fmin, 0, 1))) / 2`` with
    ``alpha(n) = (n_fmax - n_fmin) * n / n_anneal``. ``n_anneal=None`` or 0 gives all ones.

    Args:
        step: the step n, a number or a 0-d tensor; a tensor's device is the result's, and
            its value is never read on the host (no GPU sync).

    Returns:
        beta: (n_frequencies,) float64.
    """
    n = torch.as_tensor(step, dtype=torch.float64)
    k = torch.arange(n_frequencies, dtype=torch.float64, device=n.device)
    if not n_anneal:
        return torch.ones_like(k)
    alpha = n * ((n_fmax - n_fmin) / n_anneal)
    t = (alpha - k + n_fmin).clamp(0.0, 1.0)
    return (1.0 - torch.cos(math.pi * t)) / 2.0


def full_bands(
    step: float, n_frequencies: int, n_fmin: int, n_fmax: int, n_anneal: int | None
) -> int:
    """How many bands :func:`annealing_weights` has at weight 1 at ``step`` (host arithmetic)."""
    if not n_anneal:
        return n_frequencies
    alpha = (n_fmax - n_fmin) * float(step) / n_anneal
    # band k is fully on once alpha - k + n_fmin >= 1
    return max(0, min(n_frequencies, math.floor(alpha + n_fmin)))


class FrequencyEncoding(nn.Module):
    """Sinusoidal encoding ``[x, sin(2^0 x), cos(2^0 x), ..., sin(2^(N-1) x), cos(2^(N-1) x)]``.

    NeuS convention: frequencies ``2**k`` for k = 0 .. N-1 with no factor pi, each block
    ``in_dim`` wide, sin before cos. Band k (both its sin and cos block) is multiplied by the
    EventNeuS annealing weight ``beta_k(n)`` (see :func:`annealing_weights`); the raw input
    block is never weighted. With ``n_fmin = 0`` every band starts at weight 0 and band k is
    fully on once ``n >= (k + 1) * n_anneal / (n_fmax - n_fmin)``. The current step is a buffer,
    so it is saved and restored with ``state_dict``.

    Args:
        n_frequencies: number of bands N. Default: none (required).
        include_input: prepend the raw input. Default: True.
        n_fmin: bands on from the start (N_fmin). Default: 0.
        n_fmax: bands on at the end of annealing (N_fmax). Default: ``n_frequencies``.
        n_anneal: annealing length in steps (N_anneal); None or 0 disables annealing (all
            weights 1). Default: 30000.
        in_dim: input width D. Default: 3.

    Attributes:
        out_dim: ``in_dim * (include_input + 2 * n_frequencies)``.

    Example:
        >>> enc = FrequencyEncoding(6)
        >>> enc.update_step(15000)
        >>> enc(torch.rand(4, 3)).shape
        torch.Size([4, 39])
    """

    def __init__(
        self,
        n_frequencies: int,
        include_input: bool = True,
        n_fmin: int = 0,
        n_fmax: int | None = None,
        n_anneal: int | None = 30000,
        in_dim: int = 3,
    ) -> None:
        super().__init__()
        if n_frequencies < 0 or in_dim < 1:
            raise ConfigError(
                f"FrequencyEncoding: need n_frequencies >= 0 and in_dim >= 1, got "
                f"{n_frequencies} and {in_dim}"
            )
        n_fmax = n_frequencies if n_fmax is None else n_fmax
        if not 0 <= n_fmin <= n_fmax:
            raise ConfigError(
                f"FrequencyEncoding: need 0 <= n_fmin <= n_fmax, got {n_fmin} and {n_fmax}"
            )
        if n_anneal is not None and n_anneal < 0:
            raise ConfigError(f"FrequencyEncoding: n_anneal must be >= 0, got {n_anneal}")
        self.n_frequencies = n_frequencies
        self.include_input = include_input
        self.n_fmin = n_fmin
        self.n_fmax = n_fmax
        self.n_anneal = n_anneal
        self.in_dim = in_dim
        self.out_dim = in_dim * (int(include_input) + 2 * n_frequencies)
        self.register_buffer("freqs", 2.0 ** torch.arange(n_frequencies, dtype=torch.float64))
        self.register_buffer("step", torch.zeros((), dtype=torch.float64))
        self._host_step = 0.0  # the buffer's value, kept on the host

    def update_step(self, step: int) -> None:
        """Set the training step n used by the annealing weights."""
        self.step.fill_(float(step))
        self._host_step = float(step)

    def _load_from_state_dict(self, state_dict, prefix, *args, **kwargs) -> None:
        super()._load_from_state_dict(state_dict, prefix, *args, **kwargs)
        self._host_step = float(self.step)  # once per load: keep per-step reads off the device

    def band_weights(self) -> torch.Tensor:
        """Current beta_k(n): (n_frequencies,) float64, on the encoding's device (computed
        there from the step buffer, so a forward pass never waits for the GPU)."""
        return annealing_weights(
            self.step, self.n_frequencies, self.n_fmin, self.n_fmax, self.n_anneal
        )

    def full_bands(self) -> int:
        """Bands at weight 1 (:func:`full_bands` at the current step), without a device read."""
        return full_bands(
            self._host_step, self.n_frequencies, self.n_fmin, self.n_fmax, self.n_anneal
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Encode.

        Args:
            x: (*, in_dim) float32 or float64.

        Returns:
            encoded: (*, out_dim) in the input's dtype.

        Note:
            Differentiable w.r.t. ``x`` to any order; the weights are constants.
        """
        if x.shape[-1] != self.in_dim:
            raise ValueError(
                f"FrequencyEncoding: expected x of shape (*, {self.in_dim}), got {tuple(x.shape)}"
            )
        parts = [x] if self.include_input else []
        if self.n_frequencies:
            freqs = self.freqs.to(x.dtype)
            beta = self.band_weights().to(x.dtype)
            xb = x.unsqueeze(-2) * freqs.unsqueeze(-1)  # (*, N, D)
            sc = torch.stack((torch.sin(xb), torch.cos(xb)), dim=-2)  # (*, N, 2, D)
            sc = sc * beta.view(-1, 1, 1)
            parts.append(sc.flatten(-3))
        if not parts:
            return x.new_zeros(*x.shape[:-1], 0)
        return torch.cat(parts, dim=-1)

    def extra_repr(self) -> str:
        return (
            f"n_frequencies={self.n_frequencies}, include_input={self.include_input}, "
            f"n_fmin={self.n_fmin}, n_fmax={self.n_fmax}, n_anneal={self.n_anneal}"
        )
