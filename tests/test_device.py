"""The CPU floating-point mode a fit and a field load set (subnormals flushed to zero)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

_PROBE = """
import torch
from hybridneus.device import flush_denormals, resolve_device
resolve_device("cpu")
x = torch.full((4,), 1e-39) * 1.0001
print(flush_denormals(), float(x.max()) > 0)
"""


def _run(keep: bool) -> str:
    env = dict(os.environ)
    env.pop("HYBRIDNEUS_KEEP_DENORMALS", None)
    if keep:
        env["HYBRIDNEUS_KEEP_DENORMALS"] = "1"
    out = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True,
                         text=True, check=True)
    return out.stdout.split()


def test_resolving_the_device_flushes_subnormals_unless_told_to_keep_them():
    flushed, survived = _run(keep=False)
    if flushed == "False":
        pytest.skip("this CPU cannot flush subnormal floats")
    assert survived == "False"
    assert _run(keep=True) == ["False", "True"]
