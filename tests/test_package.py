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
    "hybridneus.recordings",
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


def test_the_readme_python_example_names_what_the_package_has() -> None:
    import re
    from pathlib import Path

    readme = (Path(__file__).parents[1] / "README.md").read_text()
    block = readme.split("## From Python", 1)[1].split("```python", 1)[1].split("```", 1)[0]
    names = set(re.findall(r"\bhn\.(\w+)", block))
    assert {"fit", "extract_mesh", "load_field"} <= names
    hn = importlib.import_module("hybridneus")
    assert not [n for n in names if not hasattr(hn, n)]
    for module, imported in re.findall(r"from ([\w.]+) import ([\w, ]+)", block):
        mod = importlib.import_module(module)
        assert all(hasattr(mod, n.strip()) for n in imported.split(","))


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


def test_atomic_outputs_keep_nothing_half_written_and_get_umask_modes(tmp_path) -> None:
    import os

    import pytest

    from hybridneus.fileio import atomic_dir, atomic_path

    mask = os.umask(0o022)
    try:
        target = tmp_path / "out.txt"
        with pytest.raises(RuntimeError), atomic_path(target) as tmp:
            tmp.write_text("partial")
            raise RuntimeError("interrupted")
        assert not target.exists() and list(tmp_path.iterdir()) == []
        with atomic_path(target) as tmp:
            tmp.write_text("done")
        assert target.read_text() == "done"
        # mkstemp creates 0600; finished outputs must be readable like any other file.
        assert target.stat().st_mode & 0o777 == 0o644
        with atomic_dir(tmp_path / "folder") as d:
            (d / "a").write_text("x")
        assert (tmp_path / "folder" / "a").read_text() == "x"
        assert (tmp_path / "folder").stat().st_mode & 0o777 == 0o755
    finally:
        os.umask(mask)
