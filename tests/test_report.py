"""The run report: what ``report.html`` holds, when a fit writes it, and its refusals."""

from __future__ import annotations

import json
import logging
import re
from pathlib import Path

import pytest
from conftest import fit_with_previews, scanned_run, simulate_device


@pytest.fixture(scope="module")
def scanned(tmp_path_factory) -> Path:
    return scanned_run(tmp_path_factory.mktemp("report"))


def test_a_fit_writes_a_report_that_opens_with_no_network(scanned, run_cli):
    code, out, err = run_cli("report", str(scanned))
    assert code == 0, err
    html = (scanned / "report.html").read_text()
    # one file: plotly's script inside the head, no address the page itself would fetch
    head, body = html.split("</head>", 1)
    assert "<script src" not in html and "<link" not in head and "plotly.js v" in head
    assert not re.search(r"(src|href)=['\"]https?://", body)
    assert "Plotly.newPlot" in body and len(head) > 1_000_000
    for div in ("curves", "mesh-view"):
        assert f'id="{div}"' in html
    for key in ("loss/event", "loss/eikonal", "inv_s", "step_seconds", "lr"):
        assert '"name":"{}"'.format(key.replace("/", "\\u002f")) in html  # plotly's JSON
    # what the fit estimated, and the config keys changed from the preset
    assert "contrast threshold C" in html and "train.iters" in html and "grid.n_levels" in html
    # event windows beside renders at the end, step previews, the scores and error picture
    assert len(list((scanned / "previews").glob("view_*.png"))) == 4
    assert html.count("data:image/png;base64,") >= 4 + 2 + 1
    scores = json.loads((scanned / "eval.json").read_text())
    assert f"{scores['chamfer']:.5g}" in html and (scanned / "errors.png").is_file()
    assert "errors.png" in scores["errors"]


def test_the_report_names_the_files_it_shows(scanned, tmp_path, run_cli):
    other = tmp_path / "elsewhere.html"
    code, out, err = run_cli("report", str(scanned), "--out", str(other))
    assert code == 0, err and other.is_file()
    assert "mesh_32.ply" in other.read_text() and f"{other}" in out


@pytest.mark.parametrize("make,message", [
    (lambda p: p.mkdir(), "not a run folder (no config.yaml)"),
    (lambda p: None, "run folder does not exist"),
])
def test_report_of_what_is_not_a_run_is_one_line(tmp_path, run_cli, make, message):
    path = tmp_path / "nothing"
    make(path)
    code, out, err = run_cli("report", str(path))
    assert code == 2 and err.strip() == f"error: {path}: {message}"


def test_report_refuses_a_scores_file_of_another_kind(scanned, tmp_path, run_cli):
    bad = tmp_path / "scores.json"
    bad.write_text('{"steps": 3}')
    code, out, err = run_cli("report", str(scanned), "--eval", str(bad))
    assert code == 2 and err.strip() == f"error: {bad}: not a record of hybridneus eval " \
                                        "(no chamfer)"
    assert not list(tmp_path.glob(".*.tmp.html"))


def test_no_report_skips_it_and_a_resume_refreshes_it(tmp_path, run_cli):
    data = simulate_device(tmp_path / "device", 12, 24, 18, 1.0)
    run = fit_with_previews(data, tmp_path / "runs", iters=2, report=False).run_dir
    assert not (run / "report.html").exists()
    code, out, err = run_cli("fit", "--resume", str(run), "--iters", "4", "--quiet")
    assert code == 0, err
    html = (run / "report.html").read_text()
    assert "4 steps, logged to step 4" in html
    code, out, err = run_cli("fit", "--resume", str(run), "--iters", "6", "--quiet",
                             "--no-report")
    assert code == 0 and "logged to step 4;" in (run / "report.html").read_text()


def test_a_report_that_fails_is_a_warning_and_the_fit_stands(tmp_path, monkeypatch, caplog):
    import hybridneus.report

    def broken(run_dir):
        raise OSError("disk full")

    monkeypatch.setattr(hybridneus.report, "write_report", broken)
    data = simulate_device(tmp_path / "device", 12, 24, 18, 1.0)
    with caplog.at_level(logging.WARNING, logger="hybridneus"):
        field = fit_with_previews(data, tmp_path / "runs", iters=2)
    assert field.trainer_step == 2 and (field.run_dir / "checkpoints" / "last.pt").is_file()
    assert "report not written (OSError: disk full)" in caplog.text


def test_a_large_mesh_is_shown_reduced_with_its_colours_and_its_shape():
    import numpy as np
    import trimesh

    from hybridneus.report.figures import viewer_mesh

    sphere = trimesh.creation.icosphere(subdivisions=6)  # 81,920 faces
    red = np.tile([200, 30, 30, 255], (len(sphere.vertices), 1)).astype(np.uint8)
    sphere.visual.vertex_colors = red
    shown = viewer_mesh(sphere, 8000)
    assert 4000 < len(shown.faces) <= 9600
    assert shown.visual.kind == "vertex"
    assert np.abs(shown.visual.vertex_colors[:, :3].astype(int) - [200, 30, 30]).max() <= 1
    radius = np.linalg.norm(shown.vertices, axis=1)
    assert np.abs(radius - 1.0).max() < 0.02 and np.allclose(shown.bounds, sphere.bounds,
                                                                 atol=0.02)


GARBLED = ("step,elapsed_s,loss/total\n1,0.1,2.0\n2,0.2,1.5\n"
           "3,0.3,1.43,0.4,1.2\n"  # a row cut short and the next run into it
           "4,0.4\n"  # a row cut short
           "5,0.5,1.1\n"
           "\x00\x00\x00")  # what a file system that grew the file before a crash leaves


def test_metrics_written_by_a_killed_fit_read_with_the_broken_rows_blank(tmp_path):
    from hybridneus.report.content import RunContent, read_metrics

    (tmp_path / "metrics.csv").write_text(GARBLED)
    m = read_metrics(tmp_path / "metrics.csv")
    assert list(m) == ["step", "elapsed_s", "loss/total"]
    assert m["step"] == [1, 2, 3, 4, 5] and m["loss/total"][:2] == [2.0, 1.5]
    assert m["loss/total"][4] == 1.1 and m["loss/total"][3] != m["loss/total"][3]  # NaN
    (tmp_path / "metrics.csv").write_text("step,loss/total\n1,2.0\nx\x00y,1.5\n")
    from hybridneus.report.run import render

    content = RunContent(run=tmp_path, metrics=read_metrics(tmp_path / "metrics.csv"))
    assert "logged to step 1;" in render(content)  # a step that is not a number is skipped


def test_a_resumed_fit_drops_the_rows_a_killed_write_broke(tmp_path):
    from hybridneus.training.runlog import RunLogger

    (tmp_path / "metrics.csv").write_text(GARBLED)
    logger = RunLogger(tmp_path, None, resume_step=5)
    assert [r["step"] for r in logger.history] == [1, 2, 5]
    assert logger.columns == ["step", "elapsed_s", "loss/total"]
    assert (tmp_path / "metrics.csv").read_text().splitlines()[1:] == ["1,0.1,2", "2,0.2,1.5",
                                                                       "5,0.5,1.1"]
