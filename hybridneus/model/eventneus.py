"""MLP building blocks shared by the hybrid heads and the paper's ``eventneus`` network.

The ``eventneus`` preset is :class:`~hybridneus.model.field.HybridField` with these settings
(EventNeuS, Sec. 4.4): an SDF MLP of 8 hidden layers x 256 with Softplus(beta=100) and a skip
connection re-injecting the input after layer 4, on NeuS-style positional encoding whose bands
are annealed (:class:`hybridneus.grids.FrequencyEncoding`); a 256-wide feature vector; a colour
MLP of 4 hidden layers x 256 (ReLU) on SH(view dir), normal, features and PE(x, 8 bands).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
import torch.nn.functional as F
from torch import nn

# Softplus, sigmoid and their derivatives fall below float32's smallest normal number (1.2e-38)
# far out in their negative tails; x86 CPUs compute with such subnormal numbers many times
# slower, and a trained SDF head was full of them (docs/training.md, "One training step").
# Tails below exp(-TAIL_CUTOFF) = 8.8e-27 are held at 0. The cut lies that far out because
# Adam with eps 1e-15 turns gradients down to about 1e-17 into sizeable steps: what it drops
# is at most 8.8e-27 times its upstream gradient, which no Adam step can see; at exp(-30) a
# dead unit's last gradient (1e-13 times upstream) was cut as well.
TAIL_CUTOFF = 60.0


class FlushedSoftplus(nn.Module):
    """``Softplus(beta)`` held at 0 where ``beta * x < -TAIL_CUTOFF``.

    It is Softplus of ``x`` clamped there, less Softplus of the clamp point (``8.8e-27 /
    beta``): the tail is 0, which keeps subnormal floats out of the matrix products that
    follow, forward and backward; elsewhere the value moves by that constant and the
    derivatives not at all. (One clamp and one subtraction cost less than masking the tail
    with a comparison and a product.)

    Args:
        beta: sharpness.

    Example:
        >>> FlushedSoftplus(100.0)(torch.tensor([-1.0, 0.0])).tolist()
        [0.0, 0.006931471638381481]
    """

    def __init__(self, beta: float = 1.0) -> None:
        super().__init__()
        self.beta = float(beta)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(...) -> (...)."""
        low = -TAIL_CUTOFF / self.beta
        return F.softplus(x.clamp_min(low), self.beta) - F.softplus(x.new_full((), low), self.beta)

    def extra_repr(self) -> str:
        return f"beta={self.beta}"


class MLP(nn.Module):
    """Fully connected network with optional skip connections that re-append the input.

    Layer ``i`` in ``skips`` receives ``cat([h, input]) / sqrt(2)`` (NeuS convention).

    Args:
        in_dim: input width.
        hidden: hidden width.
        n_hidden: number of hidden layers (0 gives a single linear layer).
        out_dim: output width.
        skips: indices of linear layers (1 .. n_hidden) that get the input re-appended.
        activation: module applied after every hidden layer.

    Note:
        Differentiable to any order when the activation is (Softplus, not ReLU, for SDFs).
    """

    def __init__(
        self,
        in_dim: int,
        hidden: int,
        n_hidden: int,
        out_dim: int,
        skips: Sequence[int] = (),
        activation: nn.Module | None = None,
    ) -> None:
        super().__init__()
        self.skips = tuple(int(s) for s in skips if 0 < int(s) <= n_hidden)
        dims = [in_dim] + [hidden] * n_hidden + [out_dim]
        layers = []
        for i in range(len(dims) - 1):
            d_in = dims[i] + (in_dim if i in self.skips else 0)
            layers.append(nn.Linear(d_in, dims[i + 1]))
        self.layers = nn.ModuleList(layers)
        self.activation = activation if activation is not None else nn.ReLU()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(n, in_dim) -> (n, out_dim)."""
        h = x
        last = len(self.layers) - 1
        for i, layer in enumerate(self.layers):
            if i in self.skips:
                h = torch.cat([h, x], dim=-1) / math.sqrt(2.0)
            h = layer(h)
            if i < last:
                h = self.activation(h)
        return h


def make_mlp(
    in_dim: int,
    hidden: int,
    n_hidden: int,
    out_dim: int,
    skips: Sequence[int] = (),
    activation: nn.Module | None = None,
) -> MLP:
    """Build an :class:`MLP` (see its arguments)."""
    return MLP(in_dim, hidden, n_hidden, out_dim, skips, activation)


@torch.no_grad()
def geometric_init_(
    mlp: MLP, n_inputs_xyz: int = 3, radius: float = 0.5, skips: Sequence[int] = ()
) -> None:
    """Initialise an SDF MLP so that output 0 approximates ``|x| - radius`` (SAL / NeuS).

    Weights that read the encoding (all inputs after the first ``n_inputs_xyz``) start at 0,
    so the initial SDF depends on ``x`` alone; the other outputs (features) start small.

    Args:
        mlp: network whose input starts with the raw coordinates.
        n_inputs_xyz: number of raw coordinate inputs.
        radius: sphere radius.
        skips: the skip layers (their re-appended encoding part is zeroed too).
    """
    n = len(mlp.layers)
    in_dim = mlp.layers[0].in_features
    for i, layer in enumerate(mlp.layers):
        out_dim = layer.out_features
        if i == n - 1:
            nn.init.normal_(layer.weight, mean=math.sqrt(math.pi) / math.sqrt(layer.in_features),
                            std=1e-4)
            nn.init.zeros_(layer.bias)
            layer.bias[0] = -radius
            if out_dim > 1:
                std = math.sqrt(2.0) / math.sqrt(layer.in_features)
                nn.init.normal_(layer.weight[1:], 0.0, std)
            continue
        nn.init.normal_(layer.weight, 0.0, math.sqrt(2.0) / math.sqrt(out_dim))
        nn.init.zeros_(layer.bias)
        if i == 0:
            layer.weight[:, n_inputs_xyz:] = 0.0
        elif i in mlp.skips and in_dim > n_inputs_xyz:
            # The re-appended input sits last: zero its encoding part.
            layer.weight[:, -(in_dim - n_inputs_xyz):] = 0.0
