"""``hybridneus mesh`` end to end on a (barely) trained run of a tiny simulated scene."""

from __future__ import annotations

import re

import numpy as np
import pytest

from hybridneus.meshing import load_mesh


@pytest.fixture(scope="module")
def runs(tiny_scene):
    return tiny_scene / "runs"


@pytest.fixture()
def cli(run_cli):
    """``hybridneus mesh ...`` in this process: (exit code, stderr)."""

    def run(*args: str):
        code, _, err = run_cli("mesh", *args)
        return code, err

    return run


def test_mesh_latest_run_writes_a_coloured_ply_inside_the_crop_and_a_preview(runs, cli):
    code, err = cli("--runs-root", str(runs), "--res", "48", "--color", "--device", "cpu")
    assert code == 0, err
    run = next(p for p in runs.iterdir() if (p / "checkpoints").is_dir())
    ply, png = run / "mesh_48.ply", run / "mesh_48.png"
    assert ply.is_file() and png.read_bytes()[:4] == b"\x89PNG"
    mesh = load_mesh(ply)
    assert len(mesh.faces) > 100 and mesh.visual.kind == "vertex"
    from hybridneus.training.runs import load_field

    r, y0, y1 = (float(v) for v in load_field(run, device="cpu").crop)
    v = np.asarray(mesh.vertices)
    slack = 0.05  # half a voxel of clip margin at res 48 plus marching-cubes jitter
    assert (np.hypot(v[:, 0], v[:, 2]) <= r + slack).all()
    assert v[:, 1].min() >= y0 - slack and v[:, 1].max() <= y1 + slack


def test_mesh_options_and_errors(runs, tmp_path, cli, monkeypatch):
    out = tmp_path / "m.obj"
    code, err = cli(str(runs), "--res", "32", "--format", "obj", "--out", str(out),
                    "--no-postprocess", "--no-preview", "--device", "cpu")
    assert code == 0, err
    assert out.is_file() and not out.with_suffix(".png").exists()
    code, err = cli(str(tmp_path / "no_run"), "--device", "cpu")
    assert code == 2 and "no_run" in err and err.count("\n") == 1
    code, err = cli(str(runs), "--format", "stl")
    assert code == 2 and "--format stl" in err
    monkeypatch.chdir(tmp_path)  # no runs/ here
    code, err = cli("--res", "32")
    assert code == 2 and "no run" in err


def test_postprocess_flags_reach_the_postprocessing(runs, tmp_path, cli, monkeypatch):
    import hybridneus.meshing.extract as extract

    seen = []
    real = extract.extract_mesh

    def spy(*args, **kwargs):
        options = kwargs["postprocess"]
        seen.append((options.trim_crop, options.remove_cavities))
        return real(*args, **kwargs)

    monkeypatch.setattr(extract, "extract_mesh", spy)
    for flags in ([], ["--trim-crop"], ["--keep-crop-cap", "--keep-cavities"],
                  ["--remove-cavities"]):
        code, err = cli(str(runs), "--res", "32", "--out", str(tmp_path / f"{len(seen)}.ply"),
                        "--no-preview", "--device", "cpu", *flags)
        assert code == 0, err
    assert seen == [(False, True), (True, True), (False, False), (False, True)]


def test_mesh_fills_unseen_space_from_the_runs_cameras_unless_told_not_to(
    runs, tmp_path, cli, monkeypatch
):
    import torch

    import hybridneus.meshing.extract as extract
    from hybridneus.training.runs import latest_run, load_cameras

    seen, reads = [], []
    real, real_load = extract.extract_mesh, torch.load

    def spy(*args, **kwargs):
        seen.append(kwargs["cameras"])
        return real(*args, **kwargs)

    def counted_load(*args, **kwargs):
        reads.append(args[0])
        return real_load(*args, **kwargs)

    monkeypatch.setattr(extract, "extract_mesh", spy)
    monkeypatch.setattr(torch, "load", counted_load)
    for flags in ([], ["--keep-unseen"], ["--no-postprocess"]):
        code, err = cli(str(runs), "--res", "32", "--out", str(tmp_path / f"{len(seen)}.ply"),
                        "--no-preview", "--device", "cpu", *flags)
        assert code == 0, err
    assert len(reads) == 3  # the checkpoint once per command: field and cameras share it
    expected = load_cameras(latest_run(runs))
    assert seen[0] is not None and np.allclose(seen[0], expected)
    assert seen[1] is None and seen[2] is None


def test_mesh_checks_its_output_before_meshing(runs, tmp_path, cli):
    (tmp_path / "folder.ply").mkdir()
    (tmp_path / "file").write_text("x")
    for out, message in [(tmp_path / "folder.ply", "folder.ply: is a folder; give a file name"),
                         (tmp_path / "file" / "m.ply", "m.ply: cannot be created, "),
                         (tmp_path / "m.xyz", "--out .*m.xyz: expected one of ply"),
                         (tmp_path / "m.ply", None)]:
        extra = ["--format", "obj"] if message is None else []
        code, err = cli(str(runs), "--res", "16", "--out", str(out), "--no-preview", *extra)
        assert code == 2 and err.count("\n") == 1, err
        assert re.search(message or r"a mesh in obj format needs the suffix \.obj", err)
    code, err = cli(str(runs), "--res", "16", "--chunk", "0")
    assert code == 2 and "--chunk 0: expected >= 1" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "folder.ply"]
    code, err = cli(str(runs), "--res", "16", "--out", str(tmp_path / "m.obj"), "--no-preview",
                    "--no-postprocess", "--device", "cpu")
    assert code == 0, err  # the format follows the suffix
    assert (tmp_path / "m.obj").read_text().startswith(("#", "v ", "o "))
