"""`hybridneus info` and `hybridneus preview`: output, PNGs and exit codes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_data_builder import H, W, random_events, write_split  # noqa: E402

SIZE_ARGS = ["--set", f"data.width={W}", "--set", f"data.height={H}"]


@pytest.fixture
def scene(tmp_path) -> Path:
    root = tmp_path / "data" / "real" / "multimeter"
    ev = random_events(400, 6)
    ev["p"] = ((ev["p"] + 1) // 2).astype(np.uint8)  # stored as 0/1
    write_split(root / "train", n_views=6, events=ev)
    write_split(root / "test", n_views=4, rgb=False)
    return root


def _info(run_cli, *args: str) -> dict:
    code, out, err = run_cli("info", *args, "--json")
    assert code == 0, err
    return json.loads(out)


def test_info_json(run_cli, scene):
    report = _info(run_cli, str(scene), *SIZE_ARGS)
    assert set(report["splits"]) == {"train", "test"}
    train = report["splits"]["train"]
    assert (train["views"], train["events"], train["width"], train["height"]) == (6, 400, W, H)
    assert train["polarity_stored_as"] == "0/1 (converted to -1/+1)"
    assert report["splits"]["test"]["rgb_frames"] == 0
    assert report["preset_source"].startswith("path (real/multimeter)")
    assert report["preset"]["polarity_offset"] == -0.406
    fit = report["fit"]
    # the real group's eps (1e-5) is below the cap, and random events ask for little
    assert fit["preset"]["tonemap_eps"] == 1e-5 and "tonemap_eps" not in fit["estimated"]
    # 400 events spread over 24x16 pixels: noise, and too dense to filter
    assert "the noise is too dense" in fit["noise"]
    # 400 events over 384 pixels: no pixel busy enough to say what the polarity offset is
    assert fit["polarity_balance"] is None and fit["preset"]["polarity_offset"] == -0.406


def test_info_table_says_the_same(run_cli, scene):
    code, out, err = run_cli("info", str(scene), *SIZE_ARGS)
    assert code == 0, err
    assert "train" in out and "test" in out and f"{W}x{H}" in out
    assert "preset source: path (real/multimeter)" in out and "-0.406" in out
    assert "fit: polarity: too few pixels" in out


def test_info_set_and_split(run_cli, scene):
    report = _info(run_cli, str(scene), *SIZE_ARGS, "--set", "data.threshold=0.2",
                   "--split", "test")
    assert report["preset"]["threshold"] == 0.2 and "threshold" in report["stated"]
    assert set(report["splits"]) == {"test"} and "fit" not in report


def test_info_fallback_and_estimates(run_cli, tmp_path):
    root = tmp_path / "captures" / "thing"
    write_split(root / "train", n_views=3)
    report = _info(run_cli, str(root), *SIZE_ARGS)
    assert report["preset"]["group"] == "custom" and "fallback" in report["preset_source"]
    # not the nerf group's 0.1: the fit caps it
    assert report["fit"]["preset"]["tonemap_eps"] == 0.001
    assert "capped at estimate.eps_max 0.001" in report["fit"]["estimated"]["tonemap_eps"]
    assert report["fit"]["eps_start"] == 0.1
    off = _info(run_cli, str(root), *SIZE_ARGS, "--set", "estimate.tonemap_eps=false")
    assert off["fit"]["preset"]["tonemap_eps"] == 0.1


def test_info_broken_dataset_exit_2(run_cli, scene):
    bad = scene / "train" / "pose" / "r_00001.txt"
    bad.write_text("1 2 3")
    code, out, err = run_cli("info", str(scene), *SIZE_ARGS)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and str(bad) in lines[0]


def test_info_bad_set_exit_2(run_cli, scene):
    code, _, err = run_cli("info", str(scene), "--set", "data.thresh=1")
    assert code == 2 and err.strip().startswith("error: data.thresh: unknown key 'thresh'")
    code, _, err = run_cli("info", str(scene), "-o", "threshold=1")
    assert code == 2  # the old option is gone: one override syntax everywhere


def test_preview_writes_pngs(run_cli, scene, tmp_path):
    # A readable rgb frame for view 0; the rest stay unreadable placeholders.
    rgb0 = np.full((H, W, 3), 90, np.uint8)
    cv2.imwrite(str(scene / "train" / "rgb" / "r_00000.png"), rgb0)
    out_dir = tmp_path / "prev"
    code, out, err = run_cli("preview", str(scene), "--out", str(out_dir),
                          "--n", "3", "--window", "2", *SIZE_ARGS)
    assert code == 0, err
    files = sorted(out_dir.glob("*.png"))
    assert len(files) == 3 and "wrote 3 PNGs" in out
    img0 = cv2.imread(str(out_dir / "train_r_00000_events.png"))
    assert img0.shape == (H, 2 * W, 3)  # events | rgb side by side
    assert np.all(img0[:, W:] == 90)
    img = cv2.imread(str(files[-1]))
    assert img.shape == (H, W, 3)
    # White background; some pixels coloured (red = +, blue = - in BGR).
    assert (img == 255).all(axis=2).mean() > 0.3
    assert ((img[..., 2] > img[..., 0]) | (img[..., 0] > img[..., 2])).any()
    assert not list(out_dir.glob(".*"))  # no temporary files left


def test_preview_broken_dataset_exit_2(run_cli, scene, tmp_path):
    (scene / "train" / "events" / "events.npz").unlink()
    code, _, err = run_cli("preview", str(scene), "--out",
                        str(tmp_path / "p"), *SIZE_ARGS)
    assert code == 2
    assert err.startswith("error: ") and "exactly one .npz" in err
    assert len(err.strip().splitlines()) == 1


def test_info_subprocess_end_to_end(scene):
    res = subprocess.run(
        [sys.executable, "-m", "hybridneus.cli.app", "info", str(scene), *SIZE_ARGS],
        capture_output=True, text=True, timeout=120,
    )
    assert res.returncode == 0, res.stderr
    res = subprocess.run(
        [sys.executable, "-m", "hybridneus.cli.app", "info", str(scene / "nope")],
        capture_output=True, text=True, timeout=120,
    )
    assert res.returncode == 2
    assert res.stderr.strip() == f"error: {scene / 'nope'}: dataset folder does not exist"


def test_info_shows_what_loading_warns_about(run_cli, scene, caplog):
    # (on a terminal the warning reaches stderr; under pytest its log handler takes it)
    (scene / "scene.json").write_text(json.dumps({"preset": {"nosuch": 1, "threshold": 0.2}}))
    with caplog.at_level("WARNING"):
        code, out, err = run_cli("info", str(scene), *SIZE_ARGS)
    assert code == 0, err
    assert "ignoring unknown preset key 'nosuch'" in caplog.text


def test_a_ctrl_c_outside_a_fits_loop_ends_the_command_with_130(run_cli, scene, monkeypatch):
    # Typer hands such an interrupt back as a return value: ended 0 and silent, a batch took
    # the fit it stopped while it wrote its curve for a failure
    import hybridneus.cli.info as info

    def stopped(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(info, "dataset_report", stopped)
    code, out, err = run_cli("info", str(scene), *SIZE_ARGS)
    assert code == 130 and "interrupted" in err and out == ""
