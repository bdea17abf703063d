"""A hand-written EventNeRF-layout writer for tests (independent of hybridneus.simulate).

It follows docs/eventnerf-format.md directly: per-view txt files of 16 (or 20) floats, one
events npz with keys x, y, t, p, optional rgb files whose content is irrelevant. The tests at
the bottom check that the writer and the reader agree on a round trip.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

W, H = 24, 16


def look_at_c2w(center: np.ndarray, target: np.ndarray | None = None) -> np.ndarray:
    """(4, 4) OpenCV camera-to-world: z towards ``target``, y roughly along world -y."""
    target = np.zeros(3) if target is None else target
    z = target - center
    z = z / np.linalg.norm(z)
    up = np.array([0.0, -1.0, 0.0])
    x = np.cross(up, z)
    if np.linalg.norm(x) < 1e-6:
        x = np.array([1.0, 0.0, 0.0])
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    c2w = np.eye(4)
    c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = x, y, z, center
    return c2w


def orbit_poses(n_views: int, radius: float = 0.8) -> np.ndarray:
    """(n_views, 4, 4) cameras on a horizontal circle, one full turn, looking at the origin."""
    ang = np.linspace(0.0, 2 * np.pi, n_views, endpoint=False)
    centers = np.stack([radius * np.sin(ang), 0.1 * np.ones_like(ang), radius * np.cos(ang)], 1)
    return np.stack([look_at_c2w(c) for c in centers])


def default_K(width: int = W, height: int = H, f: float = 20.0) -> np.ndarray:
    return np.array([[f, 0.0, width / 2], [0.0, f * 1.1, height / 2], [0.0, 0.0, 1.0]])


def random_events(n: int, n_views: int, width: int = W, height: int = H, seed: int = 0) -> dict:
    """Sorted events with integer frame times in 0..n_views-1 and -1/+1 polarity."""
    rng = np.random.default_rng(seed)
    t = np.sort(rng.integers(0, n_views, size=n)).astype(np.float64)
    t[-1] = n_views - 1
    return {
        "x": rng.integers(0, width, size=n).astype(np.int16),
        "y": rng.integers(0, height, size=n).astype(np.int16),
        "t": t,
        "p": rng.choice(np.array([-1, 1], dtype=np.int8), size=n),
    }


def write_txt(path: Path, values: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    rows = np.asarray(values, dtype=np.float64).reshape(-1, 4)
    path.write_text("\n".join(" ".join(f"{v:.17g}" for v in row) for row in rows) + "\n")


def write_split(
    split_dir: Path,
    n_views: int = 6,
    events: dict | None = None,
    c2w: np.ndarray | None = None,
    K: np.ndarray | None = None,
    distortion: tuple[float, float] | None = None,
    rgb: bool = True,
    width: int = W,
    height: int = H,
) -> dict:
    """Write one split; returns what was written (c2w, K, events)."""
    c2w = orbit_poses(n_views) if c2w is None else c2w
    K = default_K(width, height) if K is None else K
    events = random_events(200, n_views, width, height) if events is None else events
    for i in range(n_views):
        name = f"r_{i:05d}"
        write_txt(split_dir / "pose" / f"{name}.txt", c2w[i])
        m = np.eye(4)
        m[:3, :3] = K
        if distortion is not None:
            m = np.vstack([m, [distortion[0], distortion[1], 0.0, 0.0]])
        write_txt(split_dir / "intrinsics" / f"{name}.txt", m)
        if rgb:
            (split_dir / "rgb").mkdir(parents=True, exist_ok=True)
            (split_dir / "rgb" / f"{name}.png").write_bytes(b"placeholder")
    (split_dir / "events").mkdir(parents=True, exist_ok=True)
    np.savez(split_dir / "events" / "events.npz", **events)
    return {"c2w": c2w, "K": K, "events": events}


def write_dataset(root: Path, splits=("train", "validation", "test"), **kwargs) -> dict:
    """Write a tiny dataset with the given splits; returns per-split written data."""
    return {s: write_split(root / s, **kwargs) for s in splits}


# ---- round-trip tests of the writer against the reader ----


def test_round_trip_all_splits(tmp_path):
    from hybridneus.data import load_dataset

    written = write_dataset(tmp_path / "scene", n_views=5)
    ds = load_dataset(tmp_path / "scene", overrides={"width": W, "height": H})
    assert list(ds.splits) == ["train", "validation", "test"]
    tr = ds.splits["train"]
    assert tr.n_views == 5
    np.testing.assert_allclose(tr.c2w, written["train"]["c2w"], atol=1e-12)
    np.testing.assert_allclose(tr.intrinsics[0], written["train"]["K"])
    assert np.all(tr.distortion == 0)
    ev = written["train"]["events"]
    assert tr.events.x.dtype == np.int16 and tr.events.p.dtype == np.int8
    assert tr.events.t.dtype == np.float64
    np.testing.assert_array_equal(tr.events.x, ev["x"])
    np.testing.assert_array_equal(tr.events.p, ev["p"])
    assert tr.rgb_paths is not None and [p.name for p in tr.rgb_paths][0] == "r_00000.png"
    assert tr.view_names == [f"r_{i:05d}" for i in range(5)]


def test_splits_selection_and_other_split_names(tmp_path):
    from hybridneus.data import load_dataset

    write_dataset(tmp_path / "s", splits=("train", "test", "extra_take"), n_views=3)
    (tmp_path / "s" / "notes").mkdir()  # no layout: ignored
    ds = load_dataset(tmp_path / "s", overrides={"width": W, "height": H})
    assert list(ds.splits) == ["train", "test", "extra_take"]
    ds = load_dataset(tmp_path / "s", overrides={"width": W, "height": H}, splits="test")
    assert list(ds.splits) == ["test"]


def test_rgb_absent_and_distortion(tmp_path):
    from hybridneus.data import load_dataset

    write_dataset(tmp_path / "s", splits=("train",), rgb=False, distortion=(0.1, -0.02))
    ds = load_dataset(tmp_path / "s", overrides={"width": W, "height": H})
    tr = ds.splits["train"]
    assert tr.rgb_paths is None
    np.testing.assert_allclose(tr.distortion, [[0.1, -0.02]] * tr.n_views)


def test_public_names_resolve():
    import hybridneus.data as data

    for name in data.__all__:
        assert getattr(data, name) is not None, name


def test_compressed_npz_and_integer_times(tmp_path):
    from hybridneus.data import load_dataset

    root = tmp_path / "s"
    ev = random_events(300, 4)
    write_split(root / "train", n_views=4, events=ev)
    npz = root / "train" / "events" / "events.npz"
    np.savez_compressed(npz, x=ev["x"].astype(np.uint16), y=ev["y"].astype(np.int64),
                        t=ev["t"].astype(np.int64), p=ev["p"].astype(np.float32))
    tr = load_dataset(root, overrides={"width": W, "height": H}).splits["train"]
    np.testing.assert_array_equal(tr.events.x, ev["x"])
    np.testing.assert_array_equal(tr.events.t, ev["t"])
    np.testing.assert_array_equal(tr.events.p, ev["p"])
    assert tr.events.t.dtype == np.float64 and tr.events.p.dtype == np.int8


def test_mixed_4x4_and_5x4_intrinsics(tmp_path):
    from hybridneus.data import load_dataset

    root = tmp_path / "s"
    write_split(root / "train", n_views=3)
    m = np.eye(4)
    m[:3, :3] = default_K()
    write_txt(root / "train" / "intrinsics" / "r_00001.txt", np.vstack([m, [0.2, 0.05, 0, 0]]))
    tr = load_dataset(root, overrides={"width": W, "height": H}).splits["train"]
    np.testing.assert_allclose(tr.distortion, [[0, 0], [0.2, 0.05], [0, 0]])
    np.testing.assert_allclose(tr.intrinsics, np.stack([default_K()] * 3))


def test_notes_for_far_cameras_and_late_timestamps(tmp_path):
    from hybridneus.data import load_dataset

    root = tmp_path / "s"
    ev = random_events(100, 4)
    ev["t"] = ev["t"] + 1000.0
    write_split(root / "train", n_views=4, c2w=orbit_poses(4, radius=1.5), events=ev)
    ds = load_dataset(root, overrides={"width": W, "height": H})
    assert any("radius 1.5" in n for n in ds.notes)
    assert any("far from 0" in n for n in ds.notes)
