"""The package's shape: small modules, no import cycles, data flowing one way."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: source folder -> the package it installs as (pyproject.toml's package-dir)
SOURCES = {"hybridneus": "hybridneus", "grids": "hybridneus.grids", "cli": "hybridneus.cli"}
MAX_LINES = 420


def _modules() -> dict[str, Path]:
    out = {}
    for folder, package in SOURCES.items():
        for path in (ROOT / folder).rglob("*.py"):
            parts = path.relative_to(ROOT / folder).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([package, *parts])] = path
    return out


def _imports(path: Path, module: str, known: set[str]) -> set[str]:
    """The project modules ``path`` imports, at the top or inside functions."""
    found = set()
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1]
                                + ([base] if base else []))
            names = [f"{base}.{a.name}" if f"{base}.{a.name}" in known else base
                     for a in node.names]
        else:
            continue
        found |= {n for n in names if n in known and n != module}
    return found


def test_no_module_is_much_over_400_lines():
    long = {m: n for m, p in _modules().items()
            if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, long


def test_no_import_cycle():
    modules = _modules()
    known = set(modules)
    graph = {m: _imports(p, m, known) for m, p in modules.items()}
    # a package's __init__ re-exporting its modules is not a dependency of theirs
    graph = {m: {d for d in deps if not m.startswith(d + ".")} for m, deps in graph.items()}
    cycles = []

    def visit(node, stack, seen):
        for dep in sorted(graph[node]):
            if dep in stack:
                cycles.append(stack[stack.index(dep):] + [dep])
            elif dep not in seen:
                seen.add(dep)
                visit(dep, [*stack, dep], seen)

    for start in sorted(graph):
        visit(start, [start], {start})
    assert not cycles, cycles[:5]


def test_data_flows_one_way():
    """dataset -> batches -> field -> renderer -> objective -> trainer; meshing and evaluation
    read a trained field and never reach into training's loop."""
    modules = _modules()
    known = set(modules)
    below = {
        "hybridneus.data": {"hybridneus.model", "hybridneus.rendering", "hybridneus.training",
                            "hybridneus.meshing", "hybridneus.evaluation"},
        "hybridneus.recordings": {"hybridneus.model", "hybridneus.rendering",
                                  "hybridneus.training", "hybridneus.meshing",
                                  "hybridneus.evaluation"},
        "hybridneus.model": {"hybridneus.rendering", "hybridneus.training", "hybridneus.meshing"},
        "hybridneus.rendering": {"hybridneus.training", "hybridneus.meshing"},
        "hybridneus.meshing": {"hybridneus.training.trainer", "hybridneus.training.objective",
                               "hybridneus.training.priors"},
        "hybridneus.evaluation": {"hybridneus.training.trainer"},
        # a batch runs the commands; it reaches into no step of a fit
        "hybridneus.batch": {"hybridneus.model", "hybridneus.rendering", "hybridneus.meshing",
                             "hybridneus.evaluation", "hybridneus.training.trainer",
                             "hybridneus.training.objective", "hybridneus.training.priors",
                             "hybridneus.api"},
        # a report reads a run folder's files; it loads no field and runs no step
        "hybridneus.report": {"hybridneus.model", "hybridneus.rendering", "hybridneus.training",
                              "hybridneus.data", "hybridneus.api", "hybridneus.batch"},
    }
    wrong = []
    for module, path in modules.items():
        for layer, forbidden in below.items():
            if module == layer or module.startswith(layer + "."):
                for dep in _imports(path, module, known):
                    if any(dep == f or dep.startswith(f + ".") for f in forbidden):
                        wrong.append((module, dep))
    assert not wrong, wrong
