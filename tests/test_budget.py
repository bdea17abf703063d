"""A --minutes budget becomes a step count before the first step, recorded and repeatable."""

from __future__ import annotations

import time

import pytest
import torch
from fitting import params, tiny

from hybridneus.api import fit, prepare
from hybridneus.training.budget import mean_step_seconds, step_seconds
from hybridneus.training.scene import SceneRecord


def test_the_mean_step_interpolates_the_probe_points():
    # 0.4 * (1 + 3) / 2 + 0.5 * (3 + 2) / 2 + 0.1 * 2 = 0.8 + 1.25 + 0.2, plus 1 / 10
    assert mean_step_seconds(1.0, 3.0, 2.0, 1.0, 0.4, 10) == pytest.approx(2.35)


def test_probing_leaves_the_trainer_as_it_was(scene):
    """A probed trainer trains exactly as one that was never probed."""
    cfg = tiny("train.iters=8", "train.seed=4")
    plain, _ = prepare(scene, cfg, device="cpu")
    probed, _ = prepare(scene, cfg, device="cpu")
    first, full, late, refresh = step_seconds(probed)
    assert min(first, full, late, refresh) > 0
    assert probed.step == 0 and probed.total_steps == 8
    plain.fit(progress=False)
    probed.fit(progress=False)
    a, b = params(plain.field), params(probed.field)
    for k in a:
        assert torch.equal(a[k], b[k]), k


def test_a_budget_is_turned_into_steps_once_and_repeats_with_iters(scene, tmp_path,
                                                                   monkeypatch):
    """The step count is fixed before the first step and recorded; a fit given that many
    steps with --iters follows the same schedule and ends with the same field. (The probe's
    timings are fixed here, so that the count does not depend on the machine's speed; at
    2 s a probed step is far slower than a real one, so a loaded machine still finishes.)"""
    import hybridneus.training.budget as budget

    monkeypatch.setattr(budget, "step_seconds", lambda trainer: (2.0, 2.0, 2.0, 0.0))
    cfg = tiny("train.minutes=0.5", "train.seed=2")
    started = time.perf_counter()
    timed = fit(scene, cfg, out=tmp_path / "timed", device="cpu", started=started)
    left = 30.0 - (time.perf_counter() - started)
    record = SceneRecord.load(timed.run_dir / "scene.yaml")
    assert "budget" in record.steps_from and "2000.0, 2000.0 and 2000.0 ms" in record.steps_from
    assert 5 <= record.steps < 30.0 / (2.0 * budget.HEADROOM)
    assert timed.trainer_step == record.steps and left > 0
    again = fit(scene, tiny(f"train.iters={record.steps}", "train.seed=2"), device="cpu")
    a, b = params(timed), params(again)
    for k in a:
        assert torch.equal(a[k], b[k]), k


def test_a_run_stops_at_its_deadline_and_records_where(scene, caplog, tmp_path):
    trainer, logger = prepare(scene, tiny("train.iters=100000"), out=tmp_path, device="cpu")
    trainer.deadline = time.perf_counter() + 0.5
    with caplog.at_level("WARNING", logger="hybridneus"):
        trainer.fit(run=logger, progress=False)
    assert trainer.stopped_early and 0 < trainer.step < 100000
    assert "the time budget ran out" in caplog.text
    record = SceneRecord.load(logger.run_dir / "scene.yaml")
    assert record.steps == 100000 and record.stopped_at == trainer.step
    assert any("stopped at step" in line for line in record.lines())


def test_a_budget_too_short_to_train_is_refused(scene, tmp_path):
    from hybridneus.errors import ConfigError

    with pytest.raises(ConfigError, match="train.minutes: 0.001 min leave time for"):
        fit(scene, tiny("train.minutes=0.001"), out=tmp_path, device="cpu")
