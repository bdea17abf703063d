"""`hybridneus info` and `hybridneus preview`: output, PNGs and exit codes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_data_builder import H, W, random_events, write_split  # noqa: E402

SIZE_ARGS = ["--preset-override", f"width={W}", "--preset-override", f"height={H}"]


@pytest.fixture
def scene(tmp_path) -> Path:
    root = tmp_path / "data" / "real" / "multimeter"
    ev = random_events(400, 6)
    ev["p"] = ((ev["p"] + 1) // 2).astype(np.uint8)  # stored as 0/1
    write_split(root / "train", n_views=6, events=ev)
    write_split(root / "test", n_views=4, rgb=False)
    return root


def test_info_table(run_cli, scene):
    code, out, err = run_cli("info", str(scene), *SIZE_ARGS)
    assert code == 0, err
    assert "train" in out and "test" in out
    assert "400" in out and "absent" in out
    assert f"{W}x{H}" in out
    assert "preset source: path (real/multimeter)" in out
    assert "-0.406" in out
    assert "0/1 (converted to -1/+1)" in out
    # the real group's eps (1e-5) is below the cap, and random events ask for little
    assert "fit: tonemap eps 1e-05, the preset's" in out
    # 400 events spread over 24x16 pixels: noise, and too dense to filter
    assert "noise: events: the noise is too dense" in out and "(data.denoise, off" in out
    # 400 events over 384 pixels: no pixel busy enough to say what the polarity offset is
    assert "polarity: too few pixels" in out and "a fit keeps the preset's -0.406" in out


def test_info_override_and_split(run_cli, scene):
    code, out, _ = run_cli("info", str(scene), *SIZE_ARGS,
                        "-o", "threshold=0.2", "--split", "test")
    assert code == 0
    assert "threshold=0.2" in out and "│ train" not in out


def test_info_fallback_is_reported(run_cli, tmp_path):
    root = tmp_path / "captures" / "thing"
    write_split(root / "train", n_views=3)
    code, out, _ = run_cli("info", str(root), *SIZE_ARGS)
    assert code == 0
    assert "custom" in out and "fallback" in out
    assert "fit: tonemap eps 0.001, capped at data.eps_max 0.001" in out  # not the nerf 0.1


def test_info_broken_dataset_exit_2(run_cli, scene):
    bad = scene / "train" / "pose" / "r_00001.txt"
    bad.write_text("1 2 3")
    code, out, err = run_cli("info", str(scene), *SIZE_ARGS)
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and str(bad) in lines[0]


def test_info_bad_override_exit_2(run_cli, scene):
    code, _, err = run_cli("info", str(scene), "-o", "thresh=1")
    assert code == 2 and err.strip().startswith("error: thresh: unknown preset key")


def test_preview_writes_pngs(run_cli, scene, tmp_path):
    # A readable rgb frame for view 0; the rest stay unreadable placeholders.
    rgb0 = np.full((H * 2, W * 2, 3), 90, np.uint8)
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
