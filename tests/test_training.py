"""Training end to end on a tiny simulated scene: loss, geometry, resume, Ctrl-C, determinism."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
import torch

from hybridneus.api import fit, prepare
from hybridneus.config import apply_overrides, preset_config
from hybridneus.training import losses as L
from hybridneus.training.runs import latest_run, load_checkpoint, load_field

TINY = [
    "grid.n_levels=6",
    "grid.log2_table_size=14",
    "grid.base_resolution=8",
    "grid.max_resolution=64",
    "grid.start_levels=3",
    "render.n_coarse=12",
    "render.n_importance=8",
    "render.occupancy_resolution=24",
    "render.occupancy_every=8",
    "render.occupancy_march=48",
    "loss.n_random_points=256",
    "train.n_rays=64",
    "train.warmup=5",
    "train.log_every=2",
    "train.preview_every=0",
    "train.checkpoint_every=0",
]


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from hybridneus.simulate import SimulationConfig, simulate_dataset

    out = tmp_path_factory.mktemp("data") / "device"
    cfg = SimulationConfig(n_views=40, width=48, height=36, val_views=0, test_views=0,
                           revolutions=1.5, supersample=1)
    simulate_dataset("builtin:device", out, cfg)
    return out


def tiny(*extra: str):
    return apply_overrides(preset_config("fast"), [*TINY, *extra])


def _params(field) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in field.state_dict().items()}


def test_event_loss_matches_the_format_definition():
    c0 = torch.tensor([[0.2, 0.5, 0.7], [0.3, 0.3, 0.3]])
    c1 = torch.tensor([[0.4, 0.5, 0.1], [0.3, 0.6, 0.3]])
    bayer = torch.tensor([[1.0, 0, 0], [0, 1.0, 0]])
    target = torch.tensor([0.5, -0.2])
    eps = 1e-3
    d = np.log(c1.numpy() ** 2.2 + eps) - np.log(c0.numpy() ** 2.2 + eps)
    pred = (d * bayer.numpy()).sum(-1)
    expected = np.mean((pred - target.numpy()) ** 2)
    assert float(L.event_loss(c0, c1, target, bayer, eps)) == pytest.approx(expected, rel=1e-5)


def test_fit_lowers_the_loss_and_moves_the_surface(scene):
    import trimesh

    cfg = tiny("train.iters=60", "train.seed=3")
    trainer, _ = prepare(scene, cfg, device="cpu")
    gt = trimesh.load(scene / "gt_mesh.ply")
    surface = torch.as_tensor(np.asarray(gt.sample(2000, seed=0)), dtype=torch.float32)

    def fixed_loss() -> float:
        # The same 6 windows before and after training (own sampler seed).
        from hybridneus.data import EventWindowSampler
        from hybridneus.rendering.renderer import render_rays

        win = EventWindowSampler(trainer.split, trainer.preset, seed=123)
        total = 0.0
        for _ in range(6):
            b = win.sample(256)
            out = render_rays(trainer.field, torch.cat([b.origins0, b.origins1]),
                              torch.cat([b.dirs0, b.dirs1]), trainer.sampler, None, False)
            n = b.target.shape[0]
            total += float(L.event_loss(out.color[:n], out.color[n:], b.target, b.bayer,
                                        trainer.scene["tonemap_eps"]))
        return total / 6

    trainer.field.update_step(0, trainer.total_steps)
    before_loss = fixed_loss()
    before_sdf = float(trainer.field.raw_sdf(surface).abs().mean())
    trainer.fit(progress=False)
    after_loss = fixed_loss()
    after_sdf = float(trainer.field.raw_sdf(surface).abs().mean())
    assert after_loss < 0.9 * before_loss
    # The zero level moves towards the true surface.
    assert after_sdf < 0.8 * before_sdf


def test_resume_continues_with_identical_state(scene, tmp_path):
    cfg = tiny("train.iters=6", "train.checkpoint_every=3", "train.seed=5")
    straight = fit(scene, cfg, out=tmp_path / "a", device="cpu")

    stop_at_3 = _stop_at(3)
    first = fit(scene, cfg, [stop_at_3], out=tmp_path / "b", device="cpu")
    assert first.interrupted and first.trainer_step == 3
    resumed = fit(None, None, resume=first.run_dir, device="cpu")
    assert resumed.trainer_step == 6 and not resumed.interrupted
    a, b = _params(straight), _params(resumed)
    assert a.keys() == b.keys()
    for k in a:
        assert torch.equal(a[k], b[k]), k
    rows = (first.run_dir / "metrics.csv").read_text().splitlines()
    steps = [int(r.split(",")[0]) for r in rows[1:]]
    assert steps == sorted(set(steps)) and steps[-1] == 6


def _stop_at(step: int):
    def callback(trainer, logs):
        if trainer.step == step:
            raise KeyboardInterrupt

    return callback


def test_keyboard_interrupt_saves_a_checkpoint(scene, tmp_path):
    field = fit(scene, tiny("train.iters=50"), [_stop_at(2)], out=tmp_path, device="cpu")
    assert field.interrupted
    state = load_checkpoint(field.run_dir)
    assert state["step"] == 2
    assert latest_run(tmp_path) == field.run_dir
    loaded = load_field(field.run_dir, device="cpu")
    pts = np.random.default_rng(0).uniform(-0.3, 0.3, (50, 3)).astype(np.float32)
    assert np.allclose(loaded.sdf(pts), field.sdf(pts), atol=1e-6)


def test_same_seed_gives_the_same_field(scene):
    cfg = tiny("train.iters=3", "train.seed=11")
    a = _params(fit(scene, cfg, device="cpu"))
    b = _params(fit(scene, cfg, device="cpu"))
    for k in a:
        assert torch.equal(a[k], b[k]), k


def test_cli_fit_writes_a_run_and_latest(scene, tmp_path):
    sets = []
    for item in tiny_overrides("train.preview_every=2"):
        sets += ["--set", item]
    proc = subprocess.run(
        [sys.executable, "-m", "hybridneus.cli.app", "fit", str(scene), "--iters", "2",
         "--device", "cpu", "--out", str(tmp_path), "--quiet", *sets],
        capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr
    run = latest_run(tmp_path)
    names = {p.name for p in run.iterdir()}
    assert {"config.yaml", "checkpoints", "metrics.csv", "previews"} <= names
    assert (run / "previews" / "step_0000002.png").is_file()
    assert (run / "previews" / "curve.png").is_file()


def tiny_overrides(*extra: str) -> list[str]:
    return [*TINY, *extra]
