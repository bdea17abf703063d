"""The package surface: every exported name resolves, imports stay light, CLI help works."""

from __future__ import annotations

import importlib
import subprocess
import sys

import pytest

PACKAGES = [
    "hybridneus",
    "hybridneus.grids",
    "hybridneus.data",
    "hybridneus.simulate",
    "hybridneus.meshing",
    "hybridneus.evaluation",
]


@pytest.mark.parametrize("name", PACKAGES)
def test_every_name_in_all_resolves(name: str) -> None:
    module = importlib.import_module(name)
    missing = [n for n in module.__all__ if not hasattr(module, n)]
    assert not missing, f"{name}.__all__ lists names that do not exist: {missing}"


def test_import_hybridneus_does_not_import_torch_or_open3d() -> None:
    code = "import sys, hybridneus; print('torch' in sys.modules, 'open3d' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]


def test_grids_and_cli_install_under_hybridneus() -> None:
    import hybridneus.cli.app
    import hybridneus.grids

    assert hybridneus.grids.__name__ == "hybridneus.grids"
    assert hybridneus.cli.app.__name__ == "hybridneus.cli.app"


def _commands() -> list[str]:
    from hybridneus.cli.app import _COMMANDS

    return [name for name, _, _ in _COMMANDS]


@pytest.mark.parametrize("command", [None, *_commands()])
def test_help_on_every_command(command: str | None) -> None:
    args = [sys.executable, "-m", "hybridneus.cli.app", *([command] if command else []), "--help"]
    out = subprocess.run(args, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "Usage" in out.stdout


def test_unknown_command_exits_2() -> None:
    args = [sys.executable, "-m", "hybridneus.cli.app", "no-such-command"]
    out = subprocess.run(args, capture_output=True, text=True)
    assert out.returncode == 2
    assert "Traceback" not in out.stderr
