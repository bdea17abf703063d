"""Inputs that used to load silently wrong: each is now an error naming the file, or a note."""

from __future__ import annotations

import io
import json
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from hybridneus.data import load_dataset
from hybridneus.errors import DatasetError

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_data_builder import H, W, default_K, random_events, write_split  # noqa: E402

SIZE = {"width": W, "height": H}


def _unpadded(split: Path, n: int) -> None:
    """Rename r_00000.txt ... to r_0.txt ... r_11.txt (text order: r_0, r_1, r_10, r_11, r_2)."""
    for sub, suffix in (("pose", ".txt"), ("intrinsics", ".txt"), ("rgb", ".png")):
        for i in range(n):
            (split / sub / f"r_{i:05d}{suffix}").rename(split / sub / f"r_{i}{suffix}")


def test_unpadded_view_names_keep_their_numeric_order(tmp_path):
    written = write_split(tmp_path / "s" / "train", n_views=12)
    _unpadded(tmp_path / "s" / "train", 12)
    sp = load_dataset(tmp_path / "s", overrides=SIZE)["train"]
    assert sp.view_names == [f"r_{i}" for i in range(12)]
    np.testing.assert_allclose(sp.c2w, written["c2w"], atol=1e-12)
    assert [p.stem for p in sp.rgb_paths] == sp.view_names


@pytest.mark.parametrize("sub", ["intrinsics", "rgb"])
def test_views_are_paired_by_name_not_by_position(tmp_path, sub):
    write_split(tmp_path / "s" / "train", n_views=4)
    suffix = ".png" if sub == "rgb" else ".txt"
    (tmp_path / "s" / "train" / sub / f"r_00002{suffix}").rename(
        tmp_path / "s" / "train" / sub / f"view_2{suffix}")
    with pytest.raises(DatasetError, match=rf"view names differ: r_00002 is in only one of "
                                           rf"pose/ and {sub}/"):
        load_dataset(tmp_path / "s", overrides=SIZE)


@pytest.mark.parametrize(("edit", "message"), [
    (lambda K: K.__setitem__((0, 2), -5000.0), r"principal point \(-5000, 8\) lies outside"),
    (lambda K: K.__setitem__((0, 1), 5000.0), r"skew K\[0, 1\] = 5000 is more than 5% of fx"),
])
def test_implausible_intrinsics_name_the_view(tmp_path, edit, message):
    write_split(tmp_path / "s" / "train", n_views=4)
    K = default_K()
    edit(K)
    m = np.eye(4)
    m[:3, :3] = K
    (tmp_path / "s" / "train" / "intrinsics" / "r_00001.txt").write_text(
        " ".join(str(v) for v in m.ravel()))
    with pytest.raises(DatasetError, match="r_00001.txt: " + message):
        load_dataset(tmp_path / "s", overrides=SIZE)


def test_distortion_of_no_real_lens_is_refused(tmp_path):
    write_split(tmp_path / "s" / "train", n_views=4, distortion=(1e9, 0.0))
    with pytest.raises(DatasetError, match=r"r_00000.txt: distortion k1=1e\+09.*far from any"):
        load_dataset(tmp_path / "s", overrides=SIZE)
    write_split(tmp_path / "ok" / "train", n_views=4, distortion=(-0.3, 0.1))
    assert load_dataset(tmp_path / "ok", overrides=SIZE)["train"].distortion[0, 0] == -0.3


def test_timestamps_below_zero_are_refused(tmp_path):
    ev = random_events(100, 6)
    ev["t"] = ev["t"] - 2.0
    write_split(tmp_path / "s" / "train", n_views=6, events=ev)
    with pytest.raises(DatasetError, match=r"events.npz: timestamps start at -2.0 < 0"):
        load_dataset(tmp_path / "s", overrides=SIZE)


def test_a_stream_of_one_polarity_is_refused_before_a_fit_estimates_from_it(tmp_path):
    from hybridneus.config import preset_config
    from hybridneus.data.estimate import estimate_scene

    ev = random_events(300, 6)
    ev["p"][:] = 1
    write_split(tmp_path / "s" / "train", n_views=6, events=ev)
    ds = load_dataset(tmp_path / "s", overrides=SIZE)  # loading alone is fine
    with pytest.raises(DatasetError, match=r"every event has polarity \+1.*a fit needs both"):
        estimate_scene(ds, preset_config("fast").estimate)


def test_an_npz_header_claiming_more_entries_than_it_holds_is_refused(tmp_path):
    write_split(tmp_path / "s" / "train", n_views=4)
    path = tmp_path / "s" / "train" / "events" / "events.npz"
    data = dict(np.load(path))
    buf = io.BytesIO()
    np.lib.format.write_array(buf, data["x"])
    raw = buf.getvalue()
    claimed = raw.replace(f"({len(data['x'])},)".encode(), b"(1000000000000,)")
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("x.npy", claimed)
        for key in ("y", "t", "p"):
            b = io.BytesIO()
            np.lib.format.write_array(b, data[key])
            zf.writestr(f"{key}.npy", b.getvalue())
    with pytest.raises(DatasetError, match=r"key 'x' claims 1,000,000,000,000 entries"):
        load_dataset(tmp_path / "s", overrides=SIZE)


@pytest.mark.parametrize("doc", [
    {"width": W, "height": H},
    {"camera": {"width": W, "height": H}},
    {"preset": {"threshold": 0.2}, "width": W, "height": H},
    {"preset": {"width": W, "height": H}, "width": float(W), "height": H},
])
def test_scene_json_states_the_size_in_any_of_its_places(tmp_path, doc):
    write_split(tmp_path / "s" / "train", n_views=4, rgb=False)
    (tmp_path / "s" / "scene.json").write_text(json.dumps(doc))
    ds = load_dataset(tmp_path / "s")
    assert (ds.preset.width, ds.preset.height) == (W, H)


@pytest.mark.parametrize(("doc", "message"), [
    ({"width": 24.5, "height": H}, r"width \(top level\) must be a positive integer, got 24.5"),
    ({"width": "24", "height": H}, r"width \(top level\) must be a positive integer"),
    ({"width": W, "camera": {"width": 2 * W}}, r"width 24 \(top level\) and 48 \(camera\)"),
])
def test_bad_or_conflicting_sizes_in_scene_json_are_errors(tmp_path, doc, message):
    write_split(tmp_path / "s" / "train", n_views=4, rgb=False)
    (tmp_path / "s" / "scene.json").write_text(json.dumps(doc))
    with pytest.raises(DatasetError, match=message):
        load_dataset(tmp_path / "s")


def _rgb_frames(split: Path, width: int, height: int) -> None:
    from PIL import Image

    for f in (split / "rgb").glob("*.png"):
        Image.new("RGB", (width, height)).save(f)


def test_the_rgb_frames_give_the_size_and_contradict_a_stated_one(tmp_path):
    write_split(tmp_path / "s" / "train", n_views=4)
    _rgb_frames(tmp_path / "s" / "train", W, H)
    ds = load_dataset(tmp_path / "s")  # no scene.json, unknown path: 346x260 otherwise
    assert (ds.preset.width, ds.preset.height) == (W, H)
    assert any("image size 24x16 from the rgb frames" in n for n in ds.notes)
    (tmp_path / "s" / "scene.json").write_text(json.dumps({"width": 2 * W, "height": 2 * H}))
    with pytest.raises(DatasetError, match=r"r_00000.png: frame is 24x16, but scene.json "
                                           r"states 48x32"):
        load_dataset(tmp_path / "s")


def test_without_frames_a_far_principal_point_gives_the_size(tmp_path):
    w, h = 640, 480
    write_split(tmp_path / "s" / "train", n_views=4, rgb=False, K=default_K(w, h),
                events=random_events(100, 4, w, h))
    ds = load_dataset(tmp_path / "s")
    assert (ds.preset.width, ds.preset.height) == (w, h)
    assert any("from the principal point" in n for n in ds.notes)


def test_a_symlink_loop_is_an_error_naming_it(tmp_path):
    write_split(tmp_path / "s" / "train", n_views=4)
    npz = tmp_path / "s" / "train" / "events" / "events.npz"
    npz.unlink()
    npz.symlink_to("events.npz")
    with pytest.raises(DatasetError, match=r"events.npz: cannot read \(Too many levels"):
        load_dataset(tmp_path / "s", overrides=SIZE)


def _damaged_run(tiny_scene, tmp_path, damage):
    """A copy of a tiny fit's run whose last checkpoint ``damage(state)`` changed in place
    (the previous one removed, else it is read instead)."""
    import shutil

    import torch

    run = next(p for p in (tiny_scene / "runs").iterdir() if p.is_dir() and not p.is_symlink())
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    path = copy / "checkpoints" / "last.pt"
    state = torch.load(path, weights_only=True)
    damage(state)
    torch.save(state, path)
    (copy / "checkpoints" / "previous.pt").unlink()
    return copy


def test_a_checkpoint_without_its_scene_record_is_refused_by_name(tiny_scene, tmp_path,
                                                                   run_cli):
    copy = _damaged_run(tiny_scene, tmp_path, lambda state: state.pop("scene"))
    code, _, err = run_cli("mesh", str(copy), "--res", "16", "--out", str(tmp_path / "m.ply"))
    assert code == 2 and "last.pt: checkpoint lacks scene" in err and err.count("\n") == 1
    assert not (tmp_path / "m.ply").exists()


def test_events_with_x_and_y_exchanged_are_reported(tmp_path, caplog):
    from hybridneus.config import DataConfig, EstimateConfig
    from hybridneus.data.estimate import estimate_scene
    from hybridneus.data.orientation import transposed_events
    from hybridneus.simulate import SimulationConfig, simulate_dataset

    # a small object in a 48x36 image: its events fit the sensor either way round
    cfg = SimulationConfig(n_views=24, width=48, height=36, val_views=0, test_views=0,
                           revolutions=1.0, supersample=1, object_radius=0.2)
    simulate_dataset("builtin:device", tmp_path / "s", cfg)
    events = next((tmp_path / "s" / "train" / "events").glob("*.npz"))
    assert transposed_events(load_dataset(tmp_path / "s")["train"]) is None
    with np.load(events) as z:
        cols = {k: z[k] for k in z.files}
    assert cols["x"].max() < 36 and cols["y"].max() < 48
    cols["x"], cols["y"] = cols["y"], cols["x"]
    np.savez(events, **cols)
    dataset = load_dataset(tmp_path / "s")  # in range: no reader check can see it
    with caplog.at_level("WARNING", logger="hybridneus"):
        estimate_scene(dataset, EstimateConfig(), DataConfig())
    assert "with x and y exchanged they would match: are the file's x and y columns " \
           "swapped?" in caplog.text
    assert str(events) in caplog.text


def test_every_rgb_frame_is_checked_not_only_the_first(tmp_path):
    from PIL import Image

    write_split(tmp_path / "s" / "train", n_views=4)
    _rgb_frames(tmp_path / "s" / "train", W, H)
    Image.new("RGB", (W + 2, H)).save(tmp_path / "s" / "train" / "rgb" / "r_00002.png")
    with pytest.raises(DatasetError, match=r"r_00002.png: frame is 26x16, but the rgb frames "
                                           r"\(.*r_00000.png\) states 24x16"):
        load_dataset(tmp_path / "s")


@pytest.mark.parametrize("sub, message", [
    ("pose", "view r_00002 is in intrinsics/ but not in pose/"),
    ("intrinsics", "view r_00002 is in pose/ but not in intrinsics/"),
    ("rgb", "view r_00002 is in pose/ but not in rgb/"),
])
def test_a_view_lost_from_one_folder_is_named(tmp_path, sub, message):
    write_split(tmp_path / "s" / "train", n_views=4)
    next((tmp_path / "s" / "train" / sub).glob("r_00002.*")).unlink()
    with pytest.raises(DatasetError, match=f"view counts differ .*: {message}"):
        load_dataset(tmp_path / "s", overrides=SIZE)


def test_a_checkpoint_with_damaged_schedule_knots_is_refused_by_name(tiny_scene, tmp_path,
                                                                      run_cli):
    copy = _damaged_run(tiny_scene, tmp_path,
                        lambda state: state.update(knots=[[0, 0.0], [5, "half"]]))
    code, _, err = run_cli("mesh", str(copy), "--res", "16", "--out", str(tmp_path / "m.ply"))
    assert code == 2 and "last.pt: checkpoint's schedule knots" in err and err.count("\n") == 1
    assert not (tmp_path / "m.ply").exists()
