"""The scene record: what a fit estimated goes to scene.yaml, never into the config, and a
resume reads it back instead of estimating again."""

from __future__ import annotations

import numpy as np
import pytest
from fitting import tiny

from hybridneus.api import fit, prepare
from hybridneus.config import load_config
from hybridneus.errors import RunError
from hybridneus.training.scene import SceneRecord


@pytest.fixture(scope="module")
def unstated(scene, tmp_path_factory):
    """The test scene with its scene.json preset cut down to the image size: the polarity
    offset, crop and eps are left for the fit to estimate."""
    import json
    import shutil

    root = tmp_path_factory.mktemp("unstated") / "device"
    shutil.copytree(scene, root)
    meta = json.loads((root / "scene.json").read_text())
    meta["preset"] = {"width": meta["preset"]["width"], "height": meta["preset"]["height"]}
    (root / "scene.json").write_text(json.dumps(meta))
    return root


def test_estimates_go_to_the_scene_record_and_the_config_stays_as_given(unstated, tmp_path):
    cfg = tiny("train.iters=2")
    given = cfg.to_dict()
    field = fit(unstated, cfg, out=tmp_path, device="cpu")
    assert cfg.to_dict() == given  # the caller's config is not written to
    saved = load_config(field.run_dir / "config.yaml")
    assert saved.data.crop_r is None and saved.data.polarity_offset is None
    record = SceneRecord.load(field.run_dir / "scene.yaml")
    assert {"crop_r", "tonemap_eps"} <= set(record.estimated)
    assert record.preset["crop_r"] < 1.0  # shrunk from the fallback's whole volume
    assert record.eps_start == 0.1  # the fallback's eps, eased from
    assert field.crop.tolist() == pytest.approx(
        [record.preset["crop_r"], record.preset["crop_y_min"], record.preset["crop_y_max"]])


def test_a_value_set_in_the_config_is_not_estimated(unstated):
    trainer, _ = prepare(unstated, tiny("train.iters=1", "data.crop_r=0.3",
                                        "data.tonemap_eps=0.01"), device="cpu")
    assert "crop_r" not in trainer.record.estimated and trainer.preset.crop_r == 0.3
    assert trainer.preset.tonemap_eps == 0.01 and trainer.record.eps_start is None
    off = prepare(unstated, tiny("train.iters=1", "estimate.crop=false"), device="cpu")[0]
    assert "crop_r" not in off.record.estimated and off.preset.crop_r == 1.0


def test_a_resume_reads_the_record_back_and_estimates_nothing(unstated, tmp_path, monkeypatch):
    first = fit(unstated, tiny("train.iters=4", "train.checkpoint_every=2"), out=tmp_path,
                device="cpu")
    record = SceneRecord.load(first.run_dir / "scene.yaml")

    def never(*args, **kwargs):
        raise AssertionError("a resume must not estimate again")

    monkeypatch.setattr("hybridneus.data.estimate.estimate_scene", never)
    trainer, _ = prepare(None, None, ["train.iters=6"], resume=first.run_dir, device="cpu")
    assert trainer.preset.crop_r == record.preset["crop_r"]
    assert trainer.preset.tonemap_eps == record.preset["tonemap_eps"]
    assert trainer.total_steps == 6 and trainer.step == 4
    assert SceneRecord.load(first.run_dir / "scene.yaml").steps == 6


def test_the_record_round_trips_and_bad_ones_are_run_errors(tmp_path):
    record = SceneRecord("d", "train", "scene.json",
                         {k: 0.5 for k in ("threshold", "polarity_offset", "max_window",
                                           "cyclic", "neg_ratio", "tonemap_eps", "crop_r",
                                           "crop_y_min", "crop_y_max")} | {"background": [0.5] * 3},
                         {"crop_r": "from the hull"}, None, 123, "train.iters", 256, "cpu", "0.2.0")
    record.save(tmp_path / "scene.yaml")
    back = SceneRecord.load(tmp_path / "scene.yaml")
    assert back == record
    assert back.preset_overrides()["background"] == (0.5, 0.5, 0.5)
    assert any("123 steps" in line for line in back.lines())
    (tmp_path / "bad.yaml").write_text("dataset: d\nsplit: t\npreset_source: x\nsteps: -1\n"
                                       "preset: {}\n")
    with pytest.raises(RunError, match="bad.yaml: incomplete scene record"):
        SceneRecord.load(tmp_path / "bad.yaml")
    with pytest.raises(RunError, match="missing"):
        SceneRecord.load(tmp_path / "none.yaml")
    import dataclasses

    for bad in ([[3]], [[1, -2]], [[400, 1]], "x"):
        dataclasses.replace(record, preset=record.preset | {"width": 346, "height": 260},
                            hot_pixels=bad).save(tmp_path / "hot.yaml")
        with pytest.raises(RunError, match="hot.yaml: hot_pixels holds"):
            SceneRecord.load(tmp_path / "hot.yaml")
    assert np.isfinite(back.steps)


def test_a_fit_leaves_hot_pixels_out_and_a_resume_leaves_out_the_same(unstated, tmp_path,
                                                                       monkeypatch):
    import shutil

    from hybridneus.data import load_dataset

    root = tmp_path / "hot"
    shutil.copytree(unstated, root)
    events = root / "train" / "events" / "events.npz"
    ev = load_dataset(root, splits="train")["train"].events
    with np.load(events) as z:
        stored = {k: z[k] for k in z.files}
    n_hot, where = 400, (3, 5)
    t_hot = np.linspace(0, float(ev.t_max), n_hot + 2)[1:-1]
    t = np.concatenate([stored["t"], t_hot.astype(stored["t"].dtype)])
    order = np.argsort(t, kind="stable")
    extra = {"x": np.full(n_hot, where[0]), "y": np.full(n_hot, where[1]), "t": t_hot,
             "p": np.full(n_hot, stored["p"].max())}
    np.savez(events, **{k: np.concatenate([stored[k], extra[k].astype(stored[k].dtype)])[order]
                        for k in ("x", "y", "t", "p")})

    def events_at(trainer):
        e = trainer.split.events
        return int(np.count_nonzero((e.x == where[0]) & (e.y == where[1])))

    first = fit(root, tiny("train.iters=2", "train.checkpoint_every=1"), out=tmp_path / "runs",
                device="cpu")
    record = SceneRecord.load(first.run_dir / "scene.yaml")
    assert record.hot_pixels == [list(where)]
    assert "1 hot pixels left out" in "\n".join(record.lines())
    kept = prepare(root, tiny("train.iters=1", "estimate.hot_pixels=false"), device="cpu")[0]
    assert events_at(kept) >= n_hot and kept.record.hot_pixels == []
    left = prepare(root, tiny("train.iters=1"), device="cpu")[0]
    assert events_at(left) == 0 and len(left.split.events) == len(kept.split.events) - \
        events_at(kept)
    assert left.split.t_max == kept.split.t_max  # the views stay where they were

    def never(*args, **kwargs):
        raise AssertionError("a resume must not estimate again")

    monkeypatch.setattr("hybridneus.data.estimate.estimate_scene", never)
    resumed, _ = prepare(None, None, ["train.iters=3"], resume=first.run_dir, device="cpu")
    assert events_at(resumed) == 0
