"""Choosing the torch device from the ``--device auto|cpu|cuda`` option."""

from __future__ import annotations

import torch

from hybridneus.errors import ConfigError


def resolve_device(name: str = "auto") -> torch.device:
    """Map ``auto`` / ``cpu`` / ``cuda`` / ``cuda:N`` to a :class:`torch.device`.

    ``auto`` picks CUDA when it is available and the CPU otherwise. Asking for CUDA on a
    machine without it is a :class:`~hybridneus.errors.ConfigError`, not a silent fallback.
    """
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cpu":
        return torch.device("cpu")
    if name.startswith("cuda"):
        if not torch.cuda.is_available():
            raise ConfigError(f"--device {name}: CUDA is not available on this machine")
        return torch.device(name)
    raise ConfigError(f"--device {name}: expected auto, cpu, cuda or cuda:N")
