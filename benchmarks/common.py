"""What every benchmark writes: JSON lines stamped with the commit, machine, threads and date.

A benchmark measures the code of one commit, so it refuses a tree with uncommitted changes to
the package or the benchmarks unless told ``--allow-dirty`` (such lines carry ``"dirty":
true`` and the report leaves them out). ``benchmarks/report.py`` makes docs/benchmarks.md
from these lines alone, so every figure there has its line, its commit and its command.
"""

from __future__ import annotations

import argparse
import datetime as dt
import functools
import json
import os
import platform
import shlex
import subprocess
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / "benchmarks" / "results"
#: What a benchmark's numbers depend on: a change here makes the tree dirty.
CODE = ("hybridneus", "grids", "cli", "benchmarks", ":(exclude)benchmarks/results",
        "pyproject.toml")


#: A copy of the tree without its git history (on another machine) names its commit here;
#: whoever sets it vouches that the copy is that commit, unchanged.
COMMIT_VARIABLE = "HYBRIDNEUS_BENCH_COMMIT"


def short_commit(name: str) -> str:
    """The short hash of the commit ``name`` (a hash, a tag, ``HEAD~2``) in this repository;
    a one-line exit when git does not know it."""
    out = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--verify", "--short",
                          f"{name}^{{commit}}"], capture_output=True, text=True)
    if out.returncode != 0:
        raise SystemExit(f"error: {name}: not a commit of {REPO}")
    return out.stdout.strip()


@functools.cache
def git_state() -> tuple[str, bool]:
    """(short HEAD, whether the code has uncommitted changes), read once per process: a commit
    made while a long benchmark runs is not credited with its numbers."""
    if os.environ.get(COMMIT_VARIABLE):
        return os.environ[COMMIT_VARIABLE], False
    git = ["git", "-C", str(REPO)]
    try:
        head = subprocess.run([*git, "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
        changed = subprocess.run([*git, "status", "--porcelain", "--", *CODE],
                                 capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown", True
    return head, bool(changed)


def add_arguments(ap: argparse.ArgumentParser, name: str) -> None:
    """``--out`` (default ``benchmarks/results/<name>.jsonl``) and ``--allow-dirty``."""
    ap.add_argument("--out", type=Path, default=RESULTS / f"{name}.jsonl",
                    help="JSON-lines results file (appended to)")
    ap.add_argument("--allow-dirty", action="store_true",
                    help="run on a tree with uncommitted changes (its lines say so and stay "
                    "out of docs/benchmarks.md)")


def check_tree(args: argparse.Namespace) -> None:
    """Stop unless the tree is clean or ``--allow-dirty`` was given."""
    commit, dirty = git_state()
    if dirty and not getattr(args, "allow_dirty", False):
        raise SystemExit(f"{REPO}: uncommitted changes to the code; commit them first, or "
                         "give --allow-dirty (the lines then stay out of the docs)")


def require_dataset(path: Path) -> None:
    """Exit with one line unless ``path`` is a dataset folder (it holds ``scene.json``)."""
    if not (path / "scene.json").is_file():
        raise SystemExit(f"error: {path}: no scene.json (not a dataset folder)")


def machine(device: str = "cpu") -> dict[str, Any]:
    """Where a measurement ran: CPU model and cores, the GPU's name, torch's version."""
    import torch

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    out = {"cpu": cpu, "cores": os.cpu_count(), "torch": torch.__version__,
           "python": platform.python_version(), "device": device.split(":")[0]}
    if device.startswith("cuda") and torch.cuda.is_available():
        out["gpu"] = torch.cuda.get_device_name(torch.device(device))
    return out


def stamp(threads: int | None, device: str = "cpu") -> dict[str, Any]:
    """The fields every result line carries."""
    commit, dirty = git_state()
    return {"commit": commit, "dirty": dirty,
            "date": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
            "threads": threads, "machine": machine(device),
            "command": command()}


#: A suite line's ``volume`` when its mesh spans the field's crop box, as ``hybridneus mesh``
#: makes it (lines without it were meshed over the whole cube, a coarser ruler).
CROP_VOLUME = "crop"


def meshed_over_crop(line: dict[str, Any]) -> bool:
    """Whether a suite line's mesh spans the crop (:data:`CROP_VOLUME`)."""
    return line.get("volume") == CROP_VOLUME


def budget_label(line: dict[str, Any]) -> str:
    """A suite line's budget as tables and captions write it: ``15 min`` or ``2000 steps``."""
    return f"{line['minutes']:g} min" if line.get("minutes") else f"{line.get('iters')} steps"


#: The suite command a fit was made for, handed to its child process and kept in fit.json
#: (a line scored later, by another command, names both).
FIT_COMMAND = "HYBRIDNEUS_FIT_COMMAND"


def command() -> str:
    """This process's command line, as a result line records it."""
    return " ".join(shlex.quote(a) for a in ["python", *_script_args()])


def _script_args() -> list[str]:
    argv = list(sys.argv)
    if argv:
        try:
            argv[0] = str(Path(argv[0]).resolve().relative_to(REPO))
        except ValueError:
            pass
    return argv


def append(path: Path, record: dict[str, Any]) -> None:
    """Append one line to ``path`` (created with its folder)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as fh:
        fh.write(json.dumps(record) + "\n")
        fh.flush()


def read_lines(path: Path) -> list[dict[str, Any]]:
    """Every line of a results file (none when it does not exist)."""
    if not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def settings_of(line: dict[str, Any]) -> list[str]:
    """The ``key=value`` config settings a result line was made with: a suite line's variant
    (``fast+train.lr=0.02``, ``fast priors.hull.enabled=false``) and overrides, a pose line's
    smoothing settings."""
    parts = [p for chunk in str(line.get("preset", "")).split() for p in chunk.split("+")]
    found = [p for p in parts if "=" in p]
    found += [s for s in line.get("overrides") or [] if "=" in s]
    found += [s for s in line.get("refine_sets") or [] if "=" in s]
    return list(dict.fromkeys(found))


def reruns_today(line: dict[str, Any]) -> bool:
    """Whether today's software can repeat a result line: none of its settings is a key of an
    experiment removed from the config (``REMOVED_KEYS``) at another value than the default it
    had, which is what the software does now. Such lines stay in the results files (history)
    and out of docs/benchmarks.md."""
    import yaml

    from hybridneus.config.overrides import REMOVED_KEYS

    for key, text in removed_settings(line):
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            return False
        if value != REMOVED_KEYS[key][0]:
            return False
    return True


def removed_settings(line: dict[str, Any]) -> list[tuple[str, str]]:
    """The (key, value text) settings of a result line whose key was removed from the config
    (``REMOVED_KEYS``)."""
    from hybridneus.config.overrides import REMOVED_KEYS

    pairs = (s.partition("=") for s in settings_of(line))
    return [(key, text) for key, _, text in pairs if key in REMOVED_KEYS]


def write_calibration(split, path: Path) -> None:
    """A plain-JSON calibration of ``split``'s first camera in OpenCV's pixel convention (the
    layout's principal point less half a pixel), as a user would give ``convert --calib``."""
    K = split.intrinsics[0]
    path.write_text(json.dumps({
        "fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2] - 0.5, "cy": K[1, 2] - 0.5,
        "width": split.width, "height": split.height}))
