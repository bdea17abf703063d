"""Runs that survive crashes: two checkpoints, saves by wall time, no leftovers, roll-backs."""

from __future__ import annotations

import math
import os

import pytest
import torch
from fitting import params, tiny

from hybridneus.api import fit
from hybridneus.errors import RunError
from hybridneus.training import runs
from hybridneus.training.trainer import Trainer


class Crash(Exception):
    """Stands for a process killed after a step (no finish, no Ctrl-C checkpoint)."""


def _crash_at(step: int):
    def callback(trainer, logs) -> None:
        if trainer.step == step:
            raise Crash(step)
    return callback


def test_a_crash_before_the_step_schedule_keeps_the_wall_time_checkpoint(scene, tmp_path):
    cfg = tiny("train.iters=20", "train.checkpoint_every=0", "train.checkpoint_seconds=0.000001")
    with pytest.raises(Crash):
        fit(scene, cfg, [_crash_at(5)], out=tmp_path / "runs", device="cpu")
    run = next(p for p in (tmp_path / "runs").iterdir() if p.is_dir())
    assert runs.load_checkpoint(run)["step"] == 5
    assert torch.load(run / runs.PREVIOUS, weights_only=True)["step"] == 4
    assert not (tmp_path / "runs" / runs.LATEST).exists()  # a failed fit moves no pointer
    resumed = fit(None, None, resume=run, device="cpu")
    assert resumed.trainer_step == 20
    assert (tmp_path / "runs" / runs.LATEST).read_text().strip() == run.name


def test_an_unreadable_last_checkpoint_falls_back_to_the_previous_one(scene, tmp_path,
                                                                     caplog):
    cfg = tiny("train.iters=6", "train.checkpoint_every=2", "train.checkpoint_seconds=0")
    done = fit(scene, cfg, out=tmp_path / "runs", device="cpu")
    run = done.run_dir
    assert runs.load_checkpoint(run)["step"] == 6
    previous_step = torch.load(run / runs.PREVIOUS, weights_only=True)["step"]
    assert previous_step == 6  # the end saves again after the step-6 save
    (run / runs.CHECKPOINT).write_bytes(b"truncated by a full disk")
    (run / runs.CHECKPOINT.parent / ".last.abc123.tmp.pt").write_bytes(b"\0" * 1000)
    with caplog.at_level("WARNING", logger="hybridneus"):
        state = runs.load_checkpoint(run)
    assert state["step"] == previous_step and "using" in caplog.text
    resumed = fit(None, None, overrides=["train.iters=8"], resume=run, device="cpu")
    assert resumed.trainer_step == 8
    assert not list((run / runs.CHECKPOINT.parent).glob(".*.tmp.pt"))


def _poison_from(monkeypatch, step: int, every: bool):
    original = Trainer.train_step
    hits: list[int] = []

    def poisoned(self):
        if self.step >= step and (every or not hits):
            hits.append(self.step)
            with torch.no_grad():
                next(self.field.parameters()).fill_(float("nan"))
        return original(self)

    monkeypatch.setattr(Trainer, "train_step", poisoned)
    return hits


def test_a_nan_step_rolls_back_with_a_lower_learning_rate(scene, tmp_path, monkeypatch,
                                                          caplog):
    hits = _poison_from(monkeypatch, 4, every=False)
    with caplog.at_level("WARNING", logger="hybridneus"):
        field = fit(scene, tiny("train.iters=10"), out=tmp_path / "runs", device="cpu")
    assert hits == [4] and field.trainer_step == 10
    assert all(torch.isfinite(v).all() for v in params(field).values())
    assert "step 5: the loss became nan; restored its state of step 0 with the learning " \
           "rate x0.5 (restore 1 of at most 3" in caplog.text
    state = runs.load_checkpoint(field.run_dir)
    assert state["priors"]["collapse_guard"]["restores"] == 1
    assert math.isclose(state["priors"]["collapse_guard"]["lr_scale"], 0.5)


def test_a_run_that_keeps_diverging_stops_after_its_roll_backs(scene, tmp_path, monkeypatch):
    _poison_from(monkeypatch, 3, every=True)
    with pytest.raises(RunError, match=r"diverged at step \d+ \(loss nan\) after 3 roll-back"):
        fit(scene, tiny("train.iters=30"), out=tmp_path / "runs", device="cpu")
    assert not (tmp_path / "runs" / runs.LATEST).exists()


def _blow_up_from(monkeypatch, step: int, every: bool):
    """Multiply the event term by 10^6 at ``step`` (and after, when ``every``): finite."""
    from hybridneus.training.objective import Objective

    original = Objective.__call__
    hits: list[int] = []

    def blown(self, ctx, batch, eps):
        terms = original(self, ctx, batch, eps)
        if ctx.p >= step / 16 and (every or not hits):
            hits.append(ctx.p)
            weight, value = terms["event"]
            terms["event"] = (weight, value * 1e6)
        return terms

    monkeypatch.setattr(Objective, "__call__", blown)
    return hits


def test_an_exploding_finite_loss_rolls_back_then_stops(scene, tmp_path, monkeypatch, caplog):
    hits = _blow_up_from(monkeypatch, 10, every=False)
    cfg = tiny("train.iters=16", "priors.collapse_guard.window=5")
    with caplog.at_level("WARNING", logger="hybridneus"):
        field = fit(scene, cfg, out=tmp_path / "a", device="cpu")
    assert len(hits) == 1 and field.trainer_step == 16
    assert "step 11: the loss jumped to" in caplog.text and "x the median of the 5 steps " \
        "before; restored its state of step" in caplog.text
    monkeypatch.undo()
    _blow_up_from(monkeypatch, 10, every=True)
    with pytest.raises(RunError, match=r"diverged at step \d+ \(loss [0-9.e+]+\) after 3 "):
        fit(scene, cfg, out=tmp_path / "b", device="cpu")
    monkeypatch.undo()
    off = tiny("train.iters=16", "priors.collapse_guard.window=5",
               "priors.collapse_guard.explode=0")
    _blow_up_from(monkeypatch, 10, every=False)
    assert fit(scene, off, out=tmp_path / "c", device="cpu").trainer_step == 16


def test_temporaries_of_killed_writers_go_and_running_ones_stay(tmp_path):
    import subprocess
    import sys

    from hybridneus.fileio import atomic_path

    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True).stdout.strip()
    dead = tmp_path / f".mesh.{gone}-abc.tmp.ply"
    alive = tmp_path / f".mesh.{os.getpid()}-def.tmp.ply"
    other = tmp_path / f".other.{gone}-abc.tmp.ply"
    for p in (dead, alive, other):
        p.write_bytes(b"half")
    with atomic_path(tmp_path / "mesh.ply") as tmp:
        tmp.write_text("whole")
    assert not dead.exists() and alive.exists() and other.exists()
    assert (tmp_path / "mesh.ply").read_text() == "whole"


def test_a_resume_removes_what_killed_writes_left_in_the_run(scene, tmp_path):
    first = fit(scene, tiny("train.iters=2"), out=tmp_path / "runs", device="cpu")
    run = first.run_dir
    left = [run / ".metrics.1-x.tmp.csv", run / ".scene.1-x.tmp.yaml",
            run / "checkpoints" / ".last.1-x.tmp.pt"]
    for p in left:
        p.write_bytes(b"cut")
    fit(None, None, overrides=["train.iters=3"], resume=run, device="cpu")
    assert not [p for p in left if p.exists()]
