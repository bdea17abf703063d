"""Fault test: a fit killed with SIGKILL at random moments, resumed each time, ends where an
uninterrupted run ends (slow: ``pytest -m slow tests/test_faults.py``).

Every kill is checked the way a person coming back to the machine would: the newest checkpoint
loads as it is (no fallback needed), it is at most one checkpoint interval behind the last step
the run logged, and once the run has finished no temporary file is left in the run folder. The
fit is deterministic (one thread, a fixed seed, every random state in the checkpoint), so the
resumed run's final field must equal the uninterrupted one's bit for bit.
"""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from fitting import TINY

from hybridneus.training import runs

pytestmark = pytest.mark.slow

STEPS = 120
EVERY = 10  # the checkpoint interval, in steps
KILLS = 10
SETTINGS = [*TINY, f"train.iters={STEPS}", f"train.checkpoint_every={EVERY}",
            "train.checkpoint_seconds=0", "train.log_every=1", "train.threads=1",
            "train.seed=11", "train.minutes=0"]


def _fit_command(*args: str) -> list[str]:
    sets = [a for s in SETTINGS for a in ("--set", s)]
    return [sys.executable, "-m", "hybridneus.cli.app", "fit", *args, "--device", "cpu",
            "--quiet", *sets]


def _logged_step(run: Path) -> int:
    """The last step ``metrics.csv`` holds in full (a kill may cut its last line)."""
    path = run / "metrics.csv"
    if not path.is_file():
        return 0
    text = path.read_text()
    lines = text.splitlines()
    if lines and not text.endswith("\n"):
        lines = lines[:-1]
    rows = list(csv.reader(lines[1:]))
    steps = [int(r[0]) for r in rows if r and r[0].isdigit()]
    return max(steps, default=0)


def _run_folder(root: Path) -> Path | None:
    folders = [p for p in root.glob("*") if p.is_dir()] if root.is_dir() else []
    return max(folders, key=lambda p: p.stat().st_mtime) if folders else None


def _kill_when(proc: subprocess.Popen, root: Path, rng: np.random.Generator,
               target: int | None) -> str:
    """SIGKILL ``proc`` during its start (loading, estimating, the step-0 save) when
    ``target`` is None, else a random fraction of a step after it logs step ``target``."""
    spawned = time.time()
    if target is None:
        delay = rng.uniform(0.0, 4.0)
        time.sleep(delay)
        what = f"{delay:.2f} s after start"
    else:
        while proc.poll() is None:
            run = _run_folder(root)
            metrics = None if run is None else run / "metrics.csv"
            # this process's own rows: a resume rewrites the file before its first step
            if (metrics is not None and metrics.is_file()
                    and metrics.stat().st_mtime > spawned and _logged_step(run) >= target):
                break
            time.sleep(0.002)
        time.sleep(rng.uniform(0.0, 0.05))
        what = f"after step {target}"
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    return what


def _moments(rng: np.random.Generator) -> list[int | None]:
    """Ten kill moments: two during a start, eight after random steps (in order)."""
    steps = sorted(int(s) for s in rng.choice(np.arange(1, STEPS), KILLS - 2, replace=False))
    moments: list[int | None] = list(steps)
    for at in sorted(rng.choice(KILLS - 1, 2, replace=False)):
        moments.insert(int(at), None)
    return moments


def test_a_fit_killed_ten_times_ends_as_an_uninterrupted_one(scene, tmp_path):
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    straight = subprocess.run(_fit_command(str(scene), "--out", str(tmp_path / "straight")),
                              env=env, capture_output=True, text=True, timeout=900)
    assert straight.returncode == 0, straight.stderr
    reference = runs.load_checkpoint(runs.latest_run(tmp_path / "straight"))
    assert reference["step"] == STEPS

    root = tmp_path / "killed"
    rng = np.random.default_rng(20261129)
    moments = _moments(rng)
    kills: list[str] = []
    finished = None
    while True:
        run = _run_folder(root)
        resumable = run is not None and (run / runs.CHECKPOINT).is_file()
        start = runs.load_checkpoint(run)["step"] if resumable else 0
        args = ("--resume", str(run)) if resumable else (str(scene), "--out", str(root))
        if run is not None and not resumable:
            # killed before its step-0 checkpoint: nothing to resume, start again
            subprocess.run(["rm", "-rf", str(run)], check=True)
        proc = subprocess.Popen(_fit_command(*args), env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        if len(kills) == KILLS:
            out, err = proc.communicate(timeout=900)
            assert proc.returncode == 0, err
            finished = _run_folder(root)
            break
        target = moments[len(kills)]
        if target is not None and target <= start:  # behind the checkpoint it resumed from
            target = min(start + int(rng.integers(1, EVERY + 1)), STEPS - 1)
        what = _kill_when(proc, root, rng, target)
        assert proc.returncode == -signal.SIGKILL, f"the fit ended before the kill {what}"
        kills.append(what)
        run = _run_folder(root)
        if run is None or not (run / runs.CHECKPOINT).is_file():
            continue
        # the newest checkpoint is whole: it loads directly, without the fallback
        last = torch.load(run / runs.CHECKPOINT, weights_only=True)
        lost = _logged_step(run) - int(last["step"])
        assert lost <= EVERY, f"killed {what}: {lost} steps lost (interval {EVERY})"
    print("kills:", kills)
    assert finished is not None
    assert not [p for p in finished.rglob(".*.tmp*")], "temporary files left behind"
    assert (root / runs.LATEST).read_text().strip() == finished.name
    final = runs.load_checkpoint(finished)
    assert final["step"] == STEPS
    for key, value in reference["model"].items():
        assert torch.equal(value, final["model"][key]), key
    rows = (finished / "metrics.csv").read_text().splitlines()[1:]
    steps = [int(r.split(",")[0]) for r in rows]
    assert steps == list(range(1, STEPS + 1))
