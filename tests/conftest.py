"""Shared fixtures: a tiny simulated scene with a (barely) trained run, for CLI tests."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path

import pytest

# A one-step fit of a minimal model: enough to make a real run folder (config, checkpoint,
# latest pointer) in a second, not to learn anything.
TINY_FIT = [
    "grid.n_levels=4",
    "grid.log2_table_size=12",
    "grid.base_resolution=8",
    "grid.max_resolution=32",
    "grid.start_levels=2",
    "render.n_coarse=8",
    "render.n_importance=4",
    "render.occupancy_resolution=16",
    "render.occupancy_every=8",
    "render.occupancy_march=24",
    "loss.n_random_points=64",
    "train.n_rays=32",
    "train.warmup=0.5",
    "train.log_every=1",
    "train.preview_every=0",
    "train.checkpoint_every=0",
    "train.iters=1",
]
TINY_SIZE = (24, 18)  # width, height


#: A machine without the simulator's Open3D (a GPU host) copies the scenes from this folder
#: instead, simulated elsewhere by ``benchmarks/pack_datasets.py --test-scenes``.
PRESIMULATED = "HYBRIDNEUS_TEST_SCENES"


def device_scene_name(n_views: int, width: int, height: int, revolutions: float) -> str:
    return f"device-{n_views}v-{width}x{height}-r{revolutions:g}"


def simulate_device(out: Path, n_views: int, width: int, height: int, revolutions: float) -> Path:
    """The built-in ``device`` scene simulated into ``out`` (train split only, no supersampling)."""
    import os
    import shutil

    from hybridneus.simulate import SimulationConfig, simulate_dataset

    if os.environ.get(PRESIMULATED):
        src = Path(os.environ[PRESIMULATED]) / device_scene_name(n_views, width, height,
                                                                 revolutions)
        if src.is_dir():
            shutil.copytree(src, out)
            return out

    cfg = SimulationConfig(n_views=n_views, width=width, height=height, val_views=0,
                           test_views=0, revolutions=revolutions, supersample=1)
    simulate_dataset("builtin:device", out, cfg)
    return out


def fit_with_previews(data: Path, out: Path, iters: int = 4, **kw):
    """The tiny fit for ``iters`` steps with a preview every two (and the view windows at
    its end): a run folder with everything a report shows."""
    from hybridneus.api import fit
    from hybridneus.config import apply_overrides, preset_config

    short = [o for o in TINY_FIT if not o.startswith(("train.iters", "train.preview_every"))]
    cfg = apply_overrides(preset_config("fast"), [*short, f"train.iters={iters}",
                                                  "train.preview_every=2"])
    return fit(data, cfg, out=out, device="cpu", **kw)


def scanned_run(root: Path) -> Path:
    """A run fitted a few steps, meshed at 32^3 with colour and scored by ``hybridneus eval``
    (its ``eval.json`` and ``errors.png`` in the run folder): a report's every section."""
    from hybridneus.cli.app import app

    data = simulate_device(root / "device", 12, 24, 18, 1.0)
    run = fit_with_previews(data, root / "runs").run_dir
    for args in (["mesh", str(run), "--res", "32", "--color", "--device", "cpu"],
                 ["eval", str(run / "mesh_32.ply"), str(data / "gt_mesh.ply"), "--samples",
                  "2000", "--no-sdf"]):
        app(args, standalone_mode=False)
    return run


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> Path:
    """The built-in device scene, 40 views at 48x36 (the training tests' scene)."""
    return simulate_device(tmp_path_factory.mktemp("data") / "device", 40, 48, 36, 1.5)


@pytest.fixture(scope="session")
def tiny_scene(tmp_path_factory) -> Path:
    """A folder holding ``device/`` (8 training + 3 test views at 24x18, simulated from the
    built-in scene) and ``runs/`` with one fitted run."""
    from hybridneus.api import fit
    from hybridneus.config import apply_overrides, preset_config
    from hybridneus.simulate import SimulationConfig, simulate_dataset

    root = tmp_path_factory.mktemp("tiny_scene")
    width, height = TINY_SIZE
    cfg = SimulationConfig(n_views=8, width=width, height=height, val_views=0, test_views=3,
                           revolutions=1.0, supersample=1)
    simulate_dataset("builtin:device", root / "device", cfg)
    fit(root / "device", apply_overrides(preset_config("fast"), TINY_FIT), out=root / "runs",
        device="cpu")
    return root


@pytest.fixture()
def run_cli(capsys, monkeypatch) -> Callable[..., tuple[int, str, str]]:
    """Run ``hybridneus <args>`` in this process through ``main()`` (which maps errors to exit
    codes): returns (exit code, stdout, stderr)."""
    from hybridneus.cli.app import main

    def run(*args: str) -> tuple[int, str, str]:
        monkeypatch.setattr(sys, "argv", ["hybridneus", *args])
        capsys.readouterr()
        try:
            main()
            code = 0
        except SystemExit as exc:
            # sys.exit(None) is success; a message instead of a code means failure.
            code = 0 if exc.code is None else exc.code if isinstance(exc.code, int) else 1
        out, err = capsys.readouterr()
        return code, out, err

    return run
