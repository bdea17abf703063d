"""Choosing the torch device from the ``--device auto|cpu|cuda`` option, and the CPU's
floating-point mode for training and meshing."""

from __future__ import annotations

import os

import torch

from hybridneus.errors import ConfigError

#: Set to 1 to keep subnormal floats (see :func:`flush_denormals`).
KEEP_DENORMALS = "HYBRIDNEUS_KEEP_DENORMALS"
_flushed: bool | None = None


def flush_denormals() -> bool:
    """Have the CPU treat subnormal floats as zero (flush-to-zero), once per process; return
    whether the CPU supports it.

    A trained field's networks are full of subnormal values (Softplus(100) of a clearly
    negative pre-activation underflows into them), and x86 CPUs compute with those far more
    slowly than with normal floats: late in a fit a step on two cores took 0.36 s where the
    same step with them flushed took 0.16 s (docs/benchmarks.md, "A trained field's step").
    Values below 1.2e-38 change nothing a fit can see. The mode is per thread, and torch's
    worker threads take it only when they start after it is set, so :func:`resolve_device`
    sets it before a fit or a field load does any work; in a process that ran parallel torch
    operations before, only the calling thread gets it. ``HYBRIDNEUS_KEEP_DENORMALS=1``
    leaves the CPU as it is.
    """
    global _flushed
    if _flushed is None:
        _flushed = False if os.environ.get(KEEP_DENORMALS) == "1" else bool(
            torch.set_flush_denormal(True))
    return _flushed


def resolve_device(name: str = "auto") -> torch.device:
    """Map ``auto`` / ``cpu`` / ``cuda`` / ``cuda:N`` to a :class:`torch.device`.

    ``auto`` picks CUDA when it is available and the CPU otherwise. Asking for CUDA on a
    machine without it is a :class:`~hybridneus.errors.ConfigError`, not a silent fallback.
    Sets the CPU's flush-to-zero mode (:func:`flush_denormals`) on the first call.
    """
    flush_denormals()
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cpu":
        return torch.device("cpu")
    if name.startswith("cuda"):
        if not torch.cuda.is_available():
            raise ConfigError(f"--device {name}: CUDA is not available on this machine")
        return torch.device(name)
    raise ConfigError(f"--device {name}: expected auto, cpu, cuda or cuda:N")
