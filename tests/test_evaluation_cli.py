"""``hybridneus eval``: JSON / table output and exit codes."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import trimesh


def _subprocess(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "hybridneus.cli.app", "eval", *args],
        capture_output=True, text=True, timeout=300,
    )


@pytest.fixture()
def cli(run_cli):
    """``hybridneus eval ...`` in this process: (exit code, stdout, stderr)."""
    return lambda *args: run_cli("eval", *args)


def test_eval_prints_json_and_a_table(tmp_path, cli):
    gt = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    pred = trimesh.creation.icosphere(subdivisions=4, radius=0.55)
    gt.export(tmp_path / "gt.ply")
    pred.export(tmp_path / "pred.obj")
    code, stdout, stderr = cli(str(tmp_path / "pred.obj"), str(tmp_path / "gt.ply"), "--json",
                               "--samples", "2000", "--seed", "3")
    assert code == 0, stderr
    out = json.loads(stdout)
    assert abs(out["chamfer"] - 0.05) < 0.01 and abs(out["sdf_mae"] - 0.05) < 0.005
    assert out["samples"] == 2000 and out["seed"] == 3
    code, stdout, _ = cli(str(tmp_path / "pred.obj"), str(tmp_path / "gt.ply"), "--samples",
                          "500", "--no-sdf")
    assert code == 0 and "Chamfer distance" in stdout and "SDF-MAE" not in stdout


def test_eval_takes_eventneus_protocol_and_reports_its_floor(tmp_path, cli):
    gt = trimesh.creation.icosphere(subdivisions=4, radius=0.5)
    pred = trimesh.creation.icosphere(subdivisions=4, radius=0.55)
    pred.apply_translation([0.2, 0.0, 0.0])
    gt.export(tmp_path / "gt.ply")
    pred.export(tmp_path / "pred.ply")
    runs = {}
    for protocol in ("unit-cube", "eventneus"):
        code, stdout, stderr = cli(str(tmp_path / "pred.ply"), str(tmp_path / "gt.ply"),
                                   "--json", "--no-sdf", "--samples", "3000",
                                   "--protocol", protocol)
        assert code == 0, stderr
        runs[protocol] = json.loads(stdout)
        assert runs[protocol]["protocol"] == protocol and 0 < runs[protocol]["floor"]
    # a shifted, scaled sphere is the same sphere to eventneus: its score is its floor's size
    ev = runs["eventneus"]
    assert ev["chamfer"] == pytest.approx(ev["accuracy"] + ev["completeness"])
    assert ev["chamfer"] < 1.5 * ev["floor"]
    assert runs["unit-cube"]["chamfer"] > 5 * runs["unit-cube"]["floor"]
    code, stdout, _ = cli(str(tmp_path / "pred.ply"), str(tmp_path / "gt.ply"), "--no-sdf",
                          "--samples", "500", "--protocol", "eventneus")
    assert code == 0 and "eventneus" in stdout and "floor (GT against itself)" in stdout
    code, _, err = cli(str(tmp_path / "pred.ply"), str(tmp_path / "gt.ply"), "--protocol",
                       "sphere")
    assert code == 2 and err.count("\n") == 1 and "--protocol sphere: expected one of" in err


def test_eval_missing_file_exits_2_from_the_console_entry_point(tmp_path):
    gt = tmp_path / "gt.ply"
    trimesh.creation.box().export(gt)
    missing = _subprocess(str(tmp_path / "nope.ply"), str(gt))
    assert missing.returncode == 2
    assert missing.stderr.strip() == f"error: {tmp_path / 'nope.ply'}: no such mesh file"


def test_eval_bad_input_exits_2_with_one_line(tmp_path, cli):
    gt = tmp_path / "gt.ply"
    trimesh.creation.box().export(gt)
    bad = tmp_path / "bad.ply"
    bad.write_text("this is not a mesh")
    code, _, err = cli(str(gt), str(bad))
    assert code == 2 and err.count("\n") == 1
    assert err.startswith("error: ") and "bad.ply" in err
    code, _, err = cli(str(gt), str(gt), "--sign", "parity")
    assert code == 2 and "--sign parity" in err


def test_eval_errors_draws_a_floater_in_the_last_colour(tmp_path, cli):
    from PIL import Image

    from hybridneus.evaluation import vertex_errors

    gt = trimesh.creation.box(extents=(0.6, 0.6, 0.6))
    floater = trimesh.creation.icosphere(subdivisions=2, radius=0.05)
    floater.apply_translation((0.0, 0.6, 0.0))  # 0.3 above the top face
    pred = trimesh.util.concatenate([gt, floater])
    errors = vertex_errors(pred, gt)
    assert errors[: len(gt.vertices)].max() < 1e-6 and errors[len(gt.vertices):].min() > 0.2 - 1e-6
    gt.export(tmp_path / "gt.ply")
    pred.export(tmp_path / "pred.ply")
    png = tmp_path / "err" / "errors.png"
    code, stdout, stderr = cli(str(tmp_path / "pred.ply"), str(tmp_path / "gt.ply"), "--json",
                               "--samples", "1000", "--no-sdf", "--errors", str(png))
    assert code == 0, stderr and json.loads(stdout)["errors"] == str(png)
    image = np.asarray(Image.open(png)).astype(int)
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    red = (r > 100) & (r > 3 * g) & (r > 3 * b)  # the scale's top end: the floater only
    top, bottom = red[:256], red[256:512]  # two rows of 256-pixel views, then the scale
    assert bottom.sum() > 20 and top.sum() == 0
    code, _, err = cli(str(tmp_path / "pred.ply"), str(tmp_path / "gt.ply"), "--error-max", "0")
    assert code == 2 and "--error-max 0" in err
    code, _, err = cli(str(tmp_path / "pred.ply"), str(tmp_path / "gt.ply"), "--threshold", "-1")
    assert code == 2 and "--threshold -1.0: expected a positive distance" in err


def test_eval_parts_says_which_part_is_missing(tmp_path, cli):
    body = trimesh.creation.box(extents=(0.6, 0.6, 0.6))
    wire = trimesh.creation.cylinder(radius=0.01, height=0.8)
    wire.apply_translation((0.6, 0.0, 0.0))
    trimesh.util.concatenate([body, wire]).export(tmp_path / "gt.ply")
    body.export(tmp_path / "pred.ply")  # the wire is lost
    code, stdout, stderr = cli(str(tmp_path / "pred.ply"), str(tmp_path / "gt.ply"), "--json",
                               "--samples", "1000", "--no-sdf", "--parts")
    assert code == 0, stderr
    parts = json.loads(stdout)["parts"]
    assert [p["index"] for p in parts] == [0, 1] and parts[0]["area"] > parts[1]["area"]
    assert parts[0]["recall"] == 1.0 and parts[0]["completeness"] < 1e-6
    assert parts[1]["recall"] == 0.0 and parts[1]["completeness"] > 0.1
    assert parts[1]["samples"] >= 200  # a thin part is measured too
    components = json.loads(stdout)["components"]
    assert len(components) == 1 and components[0]["distance"] < 1e-6
    code, stdout, _ = cli(str(tmp_path / "pred.ply"), str(tmp_path / "gt.ply"), "--samples",
                          "500", "--no-sdf", "--parts")
    assert code == 0 and "GT parts" in stdout
    # a floater far from GT is named as the farthest mesh part
    floater = trimesh.creation.icosphere(radius=0.05).apply_translation((0.0, 0.0, 0.9))
    trimesh.util.concatenate([body, floater]).export(tmp_path / "floating.ply")
    code, stdout, stderr = cli(str(tmp_path / "floating.ply"), str(tmp_path / "gt.ply"),
                               "--json", "--samples", "1000", "--no-sdf", "--parts")
    assert code == 0, stderr
    components = json.loads(stdout)["components"]
    assert len(components) == 2 and components[1]["distance"] > 0.3
    assert components[0]["distance"] < 1e-6


def test_eval_planes_says_which_face_stands_out(tmp_path, cli):
    gt = trimesh.creation.box(extents=(1.0, 0.6, 0.4)).subdivide().subdivide()
    pred = gt.copy()
    pred.vertices[pred.vertices[:, 0] > 0.49, 0] += 0.02  # the +x face stands out by 0.02
    gt.export(tmp_path / "gt.ply")
    pred.export(tmp_path / "pred.ply")
    code, stdout, stderr = cli(str(tmp_path / "pred.ply"), str(tmp_path / "gt.ply"), "--json",
                               "--samples", "1000", "--no-sdf", "--planes")
    assert code == 0, stderr
    result = json.loads(stdout)
    plus_x = [f for f in result["planes"] if f["normal"][0] > 0.9]
    assert len(result["planes"]) == 6 and len(plus_x) == 1
    assert plus_x[0]["offset"] == pytest.approx(0.02, abs=1e-3)
    assert 0.005 < result["plane_rms"] < 0.02
    code, stdout, _ = cli(str(tmp_path / "pred.ply"), str(tmp_path / "gt.ply"), "--samples",
                          "500", "--no-sdf", "--planes")
    assert code == 0 and "GT planar faces" in stdout
