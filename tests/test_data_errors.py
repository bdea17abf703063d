"""Every malformed-input case raises DatasetError with one line that names the file."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_data_builder import H, W, random_events, write_split, write_txt  # noqa: E402

from hybridneus.data import load_dataset  # noqa: E402
from hybridneus.errors import DatasetError  # noqa: E402

SIZE = {"width": W, "height": H}


def _load(root: Path, **kw):
    return load_dataset(root, overrides=SIZE, **kw)


def _expect_error(root: Path, names: Path, *fragments: str, **kw) -> str:
    """Load ``root``; assert a one-line DatasetError naming ``names`` and holding fragments."""
    with pytest.raises(DatasetError) as info:
        _load(root, **kw)
    msg = str(info.value)
    assert "\n" not in msg
    assert str(names) in msg, msg
    for frag in fragments:
        assert frag in msg, msg
    return msg


@pytest.fixture
def scene(tmp_path) -> Path:
    root = tmp_path / "scene"
    write_split(root / "train", n_views=5)
    return root


def _write_events(root: Path, **changes) -> Path:
    ev = random_events(100, 5)
    ev.update(changes)
    for k in [k for k, v in ev.items() if v is None]:
        del ev[k]
    npz = root / "train" / "events" / "events.npz"
    np.savez(npz, **ev)
    return npz


def test_unsorted_timestamps(scene):
    ev = random_events(100, 5)
    t = ev["t"].copy()
    t[50], t[51] = t[51] + 1, t[50]
    npz = _write_events(scene, t=t)
    _expect_error(scene, npz, "not sorted", "t[50]")


def test_unsorted_across_chunk_border(scene, monkeypatch):
    import hybridneus.data.events as events

    monkeypatch.setattr(events, "_CHUNK", 16)
    t = np.sort(np.random.default_rng(0).random(100)) * 4
    t[32] = t[31] - 0.5  # first value of the third chunk
    npz = _write_events(scene, t=t)
    _expect_error(scene, npz, "not sorted", "t[31]")


def test_nan_timestamps(scene):
    t = np.linspace(0, 4, 100)
    t[10] = np.nan
    npz = _write_events(scene, t=t)
    _expect_error(scene, npz, "NaN")


@pytest.mark.parametrize(
    "key,value,fragment",
    [("x", W, "max x"), ("y", H, "max y"), ("x", -1, "negative"), ("y", -3, "negative")],
)
def test_pixels_outside_image(scene, key, value, fragment):
    arr = np.zeros(100, dtype=np.int64)
    arr[7] = value
    npz = _write_events(scene, **{key: arr})
    _expect_error(scene, npz, "outside the image", fragment)


def test_non_integer_pixels(scene):
    npz = _write_events(scene, x=np.full(100, 1.5))
    _expect_error(scene, npz, "non-integer")


def test_nan_in_pose(scene):
    f = scene / "train" / "pose" / "r_00003.txt"
    c2w = np.eye(4)
    c2w[0, 3] = np.nan
    write_txt(f, c2w)
    _expect_error(scene, f, "NaN or inf")


def test_inf_in_intrinsics(scene):
    f = scene / "train" / "intrinsics" / "r_00001.txt"
    K = np.eye(4)
    K[0, 0] = np.inf
    write_txt(f, K)
    _expect_error(scene, f, "NaN or inf")


@pytest.mark.parametrize(
    "rot,fragment",
    [
        (np.zeros((3, 3)), "not invertible"),
        (np.diag([2.0, 2.0, 2.0]), "not a rotation"),  # scaled
        (np.diag([1.0, 1.0, -1.0]), "not a rotation"),  # reflection, det -1
        (np.array([[1.0, 0.3, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]), "not a rotation"),
    ],
)
def test_bad_rotation(scene, rot, fragment):
    f = scene / "train" / "pose" / "r_00002.txt"
    c2w = np.eye(4)
    c2w[:3, :3] = rot
    write_txt(f, c2w)
    _expect_error(scene, f, fragment)


def test_singular_intrinsics(scene):
    f = scene / "train" / "intrinsics" / "r_00000.txt"
    write_txt(f, np.diag([0.0, 10.0, 1.0, 1.0]))
    _expect_error(scene, f, "not invertible")


def test_view_counts_pose_vs_intrinsics(scene):
    (scene / "train" / "intrinsics" / "r_00004.txt").unlink()
    _expect_error(scene, scene / "train", "view counts differ", "pose/ has 5", "intrinsics/ has 4")


def test_view_counts_pose_vs_rgb(scene):
    (scene / "train" / "rgb" / "r_00004.png").unlink()
    _expect_error(scene, scene / "train", "view counts differ", "rgb/ has 4")


def test_missing_npz(scene):
    (scene / "train" / "events" / "events.npz").unlink()
    _expect_error(scene, scene / "train" / "events", "exactly one .npz", "found 0")


def test_extra_npz(scene):
    ev = random_events(10, 5)
    np.savez(scene / "train" / "events" / "more.npz", **ev)
    _expect_error(scene, scene / "train" / "events", "exactly one .npz", "found 2")


def test_missing_key(scene):
    npz = _write_events(scene, p=None)
    _expect_error(scene, npz, "missing key", "p")


def test_wrong_key_names(scene):
    npz = scene / "train" / "events" / "events.npz"
    ev = random_events(20, 5)
    np.savez(npz, xs=ev["x"], ys=ev["y"], ts=ev["t"], ps=ev["p"])
    _expect_error(scene, npz, "missing key")


def test_empty_event_arrays(scene):
    empty = {k: np.zeros(0, dtype=np.int16) for k in ("x", "y", "p")}
    npz = _write_events(scene, t=np.zeros(0), **empty)
    _expect_error(scene, npz, "no events")


def test_length_mismatch(scene):
    npz = _write_events(scene, p=np.ones(99, dtype=np.int8))
    _expect_error(scene, npz, "'p' has 99 entries")


def test_two_d_key(scene):
    npz = _write_events(scene, x=np.zeros((10, 10), dtype=np.int16))
    _expect_error(scene, npz, "expected 1-D")


def test_bad_polarity_values(scene):
    npz = _write_events(scene, p=np.full(100, 2))
    _expect_error(scene, npz, "neither -1/+1 nor 0/1")


def test_mixed_polarity_values(scene):
    p = np.ones(100, dtype=np.int8)
    p[:10], p[10:20] = 0, -1
    npz = _write_events(scene, p=p)
    _expect_error(scene, npz, "-1, 0 and +1")


def test_object_array_refused(scene):
    npz = scene / "train" / "events" / "events.npz"
    ev = random_events(20, 5)
    np.savez(npz, x=ev["x"], y=ev["y"], t=ev["t"], p=np.array([1, "a"] * 10, dtype=object))
    _expect_error(scene, npz, "'p' holds Python objects")


@pytest.mark.parametrize("folder,n", [("pose", 12), ("intrinsics", 9), ("intrinsics", 17)])
def test_wrong_float_count(scene, folder, n):
    f = scene / "train" / folder / "r_00002.txt"
    f.write_text(" ".join(["1"] * n))
    _expect_error(scene, f, f"found {n}")


def test_text_that_is_not_numbers(scene):
    f = scene / "train" / "pose" / "r_00001.txt"
    f.write_text("1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 one")
    _expect_error(scene, f, "not a list of numbers")


def test_unreadable_txt(scene):
    f = scene / "train" / "pose" / "r_00001.txt"
    f.write_bytes(b"\xff\xfe\x00garbage")
    _expect_error(scene, f, "cannot read")


def test_unreadable_npz(scene):
    npz = scene / "train" / "events" / "events.npz"
    npz.write_bytes(b"this is not a zip archive")
    _expect_error(scene, npz, "cannot read events npz")


def test_truncated_npz_member(scene, tmp_path):
    import zipfile

    npz = scene / "train" / "events" / "events.npz"
    ev = random_events(50, 5)
    np.save(tmp_path / "t.npy", ev["t"])
    raw = (tmp_path / "t.npy").read_bytes()
    with zipfile.ZipFile(npz, "w") as zf:
        for k in ("x", "y", "p"):
            np.save(tmp_path / f"{k}.npy", ev[k])
            zf.write(tmp_path / f"{k}.npy", f"{k}.npy")
        zf.writestr("t.npy", raw[: len(raw) - 40])
    _expect_error(scene, npz, "truncated")


def test_missing_split_folder(scene):
    _expect_error(scene, scene / "validation", "missing split folder", splits=["validation"])


def test_missing_subfolder(scene):
    import shutil

    shutil.rmtree(scene / "train" / "intrinsics")
    _expect_error(scene, scene / "train" / "intrinsics", "missing folder")


def test_no_splits_at_all(tmp_path):
    (tmp_path / "empty").mkdir()
    _expect_error(tmp_path / "empty", tmp_path / "empty", "no split folders")


def test_root_missing(tmp_path):
    _expect_error(tmp_path / "nope", tmp_path / "nope", "does not exist")


def test_error_names_right_split(tmp_path):
    root = tmp_path / "scene"
    write_split(root / "train", n_views=4)
    write_split(root / "test", n_views=4)
    f = root / "test" / "pose" / "r_00000.txt"
    f.write_text("1 2 3")
    _expect_error(root, f, "found 3")


def test_split_folder_given_as_root(scene):
    _expect_error(scene / "train", scene / "train", "this is a split folder")
