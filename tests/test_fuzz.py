"""Readers fed random and mutated files end in the project's own errors, never another one.

Each property starts from a valid file, mutates its bytes (flips, truncation, a splice of
random bytes) and reads it: the read must succeed or raise a
:class:`~hybridneus.errors.HybridNeusError` subclass (``DatasetError``, ``RunError``,
``RecordingError``): never a bare ``ValueError``, ``OSError``, ``MemoryError``, a panic of a
compiled reader, nor take longer than the deadline. ``HYPOTHESIS_EXAMPLES`` sets the number of
examples per property (default 40; the slow fault run uses more).

AEDAT4, RAW and DAT files are decoded by faery, whose Rust decoder panics on some mutated
files (caught: a ``RecordingError``) and aborts the whole process on others (a panic while
unwinding, which no Python code can catch). Mutated files of those formats are therefore
left out here until the decoder is fixed upstream; random bytes under their suffixes are in.
"""

from __future__ import annotations

import io
import json
import os
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from hybridneus.errors import HybridNeusError  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from test_data_builder import H, W, random_events, write_split  # noqa: E402

EXAMPLES = int(os.environ.get("HYPOTHESIS_EXAMPLES", "40"))
FUZZ = settings(max_examples=EXAMPLES, deadline=5000, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture,
                                       HealthCheck.too_slow])


@st.composite
def mutations(draw) -> list[tuple[str, int, bytes]]:
    """A few edits: ("flip", position, byte), ("cut", position, b""), ("splice", position,
    random bytes); positions are fractions of the file in 1/10000."""
    kinds = st.sampled_from(["flip", "cut", "splice"])
    edits = draw(st.lists(st.tuples(kinds, st.integers(0, 9999), st.binary(max_size=16)),
                          min_size=1, max_size=4))
    return edits


def mutate(data: bytes, edits) -> bytes:
    out = bytearray(data)
    for kind, where, payload in edits:
        i = min(len(out) - 1, where * len(out) // 10000) if out else 0
        if kind == "flip" and out:
            out[i] ^= (payload[0] if payload else 0xFF) or 0x01
        elif kind == "cut":
            del out[i:]
        else:
            out[i:i] = payload
    return bytes(out)


def _ours_or_nothing(read) -> None:
    try:
        read()
    except HybridNeusError:
        pass


@pytest.fixture(scope="module")
def valid(tmp_path_factory) -> dict:
    """One valid file of each kind, as bytes."""
    root = tmp_path_factory.mktemp("valid")
    write_split(root / "scene" / "train", n_views=5, events=random_events(300, 5))
    split = root / "scene" / "train"
    files = {"npz": (split / "events" / "events.npz").read_bytes(),
             "pose": (split / "pose" / "r_00002.txt").read_bytes(),
             "scene_json": json.dumps({"width": W, "height": H,
                                       "preset": {"threshold": 0.2}}).encode()}
    buf = io.BytesIO()
    torch.save({"model": {"w": torch.zeros(3)}, "scene": {"a": 1.0}, "step": 3,
                "total_steps": 9}, buf)
    files["checkpoint"] = buf.getvalue()
    ev = random_events(300, 5)
    t_us = (ev["t"] * 1000).astype(np.int64)
    files["txt"] = "\n".join(f"{t / 1e6:.6f} {x} {y} {int(p > 0)}" for t, x, y, p in
                             zip(t_us, ev["x"], ev["y"], ev["p"], strict=True)).encode()
    import faery
    import h5py

    arr = np.zeros(300, dtype=faery.EVENTS_DTYPE)
    arr["t"], arr["x"], arr["y"], arr["on"] = t_us, ev["x"], ev["y"], ev["p"] > 0
    for fmt, suffix in (("aedat4", "aedat4"), ("evt3", "raw"), ("evt2", "raw"), ("dat", "dat")):
        path = root / f"e-{fmt}.{suffix}"
        faery.events_stream_from_array(arr, dimensions=(W, H)).to_file(
            path, version=fmt if fmt.startswith("evt") else None, zero_t0=False)
        files[fmt] = path.read_bytes()
    with h5py.File(root / "e.h5", "w") as f:
        g = f.create_group("events")
        for k, v in (("t", t_us), ("x", ev["x"]), ("y", ev["y"]), ("p", ev["p"] > 0)):
            g.create_dataset(k, data=v)
    files["h5"] = (root / "e.h5").read_bytes()
    files["root"] = root
    return files


@FUZZ
@given(edits=mutations())
def test_the_dataset_reader_ends_in_its_own_errors(valid, tmp_path_factory, edits):
    from hybridneus.data import load_dataset

    root = tmp_path_factory.mktemp("ds")
    write_split(root / "train", n_views=5, events=random_events(300, 5))
    target = [root / "train" / "events" / "events.npz", root / "train" / "pose" / "r_00002.txt",
              root / "scene.json"][edits[0][1] % 3]
    source = {"events.npz": valid["npz"], "r_00002.txt": valid["pose"],
              "scene.json": valid["scene_json"]}[target.name]
    target.write_bytes(mutate(source, edits))
    _ours_or_nothing(lambda: load_dataset(root, overrides=None if target.name == "scene.json"
                                          else {"width": W, "height": H}))


@FUZZ
@given(edits=mutations())
def test_the_checkpoint_loader_ends_in_its_own_errors(valid, tmp_path_factory, edits):
    from hybridneus.training import runs

    run = tmp_path_factory.mktemp("run")
    (run / runs.CHECKPOINT).parent.mkdir(parents=True)
    (run / runs.CHECKPOINT).write_bytes(mutate(valid["checkpoint"], edits))
    _ours_or_nothing(lambda: runs.load_checkpoint(run))


@FUZZ
@given(fmt=st.sampled_from(["txt", "h5", "npz"]),
       edits=mutations())
def test_the_recording_readers_end_in_their_own_errors(valid, tmp_path_factory, fmt, edits):
    from hybridneus.recordings import open_events

    suffix = {"evt3": "raw", "evt2": "raw", "npz": "npz"}.get(fmt, fmt)
    path = tmp_path_factory.mktemp("rec") / f"events.{suffix}"
    path.write_bytes(mutate(valid[fmt], edits))

    def read() -> None:
        source = open_events(path)
        for _ in source.chunks():
            pass

    _ours_or_nothing(read)


@FUZZ
@given(data=st.binary(max_size=2048),
       suffix=st.sampled_from(["npz", "aedat4", "raw", "dat", "h5", "txt", "bag", "npy"]))
def test_random_bytes_under_any_event_suffix_end_in_our_errors(tmp_path_factory, data, suffix):
    from hybridneus.recordings import open_events

    path = tmp_path_factory.mktemp("junk") / f"events.{suffix}"
    path.write_bytes(data)

    def read() -> None:
        for _ in open_events(path).chunks():
            pass

    _ours_or_nothing(read)
