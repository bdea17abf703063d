"""The bad inputs and faults that ``benchmarks/reliability.py`` tries, and what each must give.

A case prepares its inputs in a folder of its own (from the good ones of a
:class:`Workspace`), names the ``hybridneus`` command a person would type, and says what must
come of it: ``error`` (exit code 2 and one line naming the file or option and the fault),
``warn`` (a loud, specific warning; an error is just as good) or ``recover`` (the command
succeeds and ``check`` finds the state right). ``sees`` is a regular expression the message
must match. A fault case gives ``run`` instead of a plain command: it starts, kills or
resumes processes itself.
"""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: A model small enough that a fit of a few steps takes a second.
TINY = ["grid.n_levels=4", "grid.log2_table_size=12", "grid.base_resolution=8",
        "grid.max_resolution=32", "grid.start_levels=2", "render.n_coarse=8",
        "render.n_importance=4", "render.occupancy_resolution=16", "render.occupancy_march=24",
        "loss.n_random_points=64", "train.n_rays=32", "train.preview_every=0",
        "train.iters=2"]
FORMATS = ("aedat4", "evt2", "evt3", "dat", "h5", "bag", "txt", "npz")
#: Formats that are a plain stream of event words after a header, with no event count.
STREAMS = ("evt2", "evt3", "dat")


@dataclass
class Workspace:
    """The good inputs every case starts from (made once by ``reliability.py``)."""

    root: Path
    data: Path  # a simulated dataset, 12 views at 24x18, with a test split
    small: Path  # the same scene with a small object in a 48x36 image
    runs: Path  # a runs root holding one fitted run (and ``latest``)
    run: Path
    mesh: Path  # a mesh of the run
    recordings: dict[str, Path]  # format -> events file (346x260, ten minutes)
    turntable: Path
    calib: Path
    poses: Path  # a TUM track covering the recordings


@dataclass
class Case:
    group: str
    what: str
    prepare: Callable[[Workspace, Path], list[str]]
    expect: str = "error"
    sees: str = ""
    check: Callable[[Path], str | None] | None = None
    run: Callable[[Workspace, Path, list[str]], tuple[int, str, str]] | None = None


# ----------------------------------------------------------------- helpers


def hybridneus(*args: str) -> list[str]:
    return [sys.executable, "-m", "hybridneus.cli.app", *args]


def fit_args(data: Path | str, *extra: str) -> list[str]:
    sets = [a for s in TINY for a in ("--set", s)]
    return ["fit", str(data), "--out", "runs", "--device", "cpu", "--quiet", *sets, *extra]


def copy_data(ws: Workspace, d: Path, source: Path | None = None) -> Path:
    shutil.copytree(source or ws.data, d / "data")
    return d / "data"


def copy_run(ws: Workspace, d: Path) -> Path:
    shutil.copytree(ws.runs, d / "runs", symlinks=True)
    return d / "runs" / ws.run.name


def _npz(d: Path) -> Path:
    return d / "train" / "events" / "events.npz"


def edit_events(edit: Callable[[dict], dict | None]) -> Callable[[Path], None]:
    def apply(data: Path) -> None:
        with np.load(_npz(data)) as z:
            cols = {k: z[k] for k in z.files}
        cols = edit(cols) or cols
        np.savez(_npz(data), **cols)
    return apply


def write_file(rel: str, content: str | bytes) -> Callable[[Path], None]:
    def apply(data: Path) -> None:
        p = data / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_bytes(content if isinstance(content, bytes) else content.encode())
    return apply


def remove(rel: str) -> Callable[[Path], None]:
    def apply(data: Path) -> None:
        p = data / rel
        shutil.rmtree(p) if p.is_dir() else p.unlink()
    return apply


def edit_matrix(rel: str, edit: Callable[[np.ndarray], np.ndarray]) -> Callable[[Path], None]:
    def apply(data: Path) -> None:
        m = np.loadtxt(data / rel)
        np.savetxt(data / rel, edit(m.copy()), fmt="%.10g")
    return apply


def set_at(index: tuple, value: float) -> Callable[[np.ndarray], np.ndarray]:
    def edit(m: np.ndarray) -> np.ndarray:
        m[index] = value
        return m
    return edit


def edit_scene(edit: Callable[[dict], None]) -> Callable[[Path], None]:
    def apply(data: Path) -> None:
        doc = json.loads((data / "scene.json").read_text())
        edit(doc)
        (data / "scene.json").write_text(json.dumps(doc))
    return apply


def dataset_case(what: str, edit: Callable[[Path], None], sees: str = "",
                 command: str = "info", expect: str = "error", source: str = "data",
                 check=None) -> Case:
    """A dataset made bad by ``edit``, read by ``info`` or fitted by ``fit``."""
    def prepare(ws: Workspace, d: Path) -> list[str]:
        data = copy_data(ws, d, getattr(ws, source))
        edit(data)
        return ["info", str(data)] if command == "info" else fit_args(data)
    return Case("dataset", what, prepare, expect, sees, check)


def _rename_views(sub: str, name: Callable[[int], str], n: int = 12):
    def apply(data: Path) -> None:
        folder = data / "train" / sub
        for i in range(n):
            src = next(folder.glob(f"r_{i:05d}.*"))
            src.rename(folder / (name(i) + src.suffix))
    return apply


def _unpadded(data: Path) -> None:
    for sub in ("pose", "intrinsics", "rgb"):
        _rename_views(sub, lambda i: f"r_{i}")(data)


def _paired_in_natural_order(d: Path) -> str | None:
    from hybridneus.data import load_dataset

    sp = load_dataset(d / "data", splits="train")["train"]
    if sp.view_names != [f"r_{i}" for i in range(12)]:
        return f"views read in the order {sp.view_names[:4]}..."
    m = np.loadtxt(d / "data" / "train" / "pose" / "r_10.txt")
    return None if np.allclose(sp.c2w[10], m, atol=1e-6) else "r_10 got another view's pose"


def _one_polarity(cols: dict) -> None:
    cols["p"] = np.ones_like(cols["p"])


def _swap_xy(cols: dict) -> None:
    cols["x"], cols["y"] = cols["y"].copy(), cols["x"].copy()


def _claim_huge(data: Path) -> None:
    """Rewrite the npz's ``t`` member header to claim 10^12 entries."""
    path = _npz(data)
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    raw = members["t.npy"]
    header_len = int.from_bytes(raw[8:10], "little")
    header = raw[10:10 + header_len].decode("latin1")
    start, end = header.index("'shape': (") + 10, header.index(")", header.index("'shape'"))
    new = (header[:start] + "1000000000000," + header[end:]).rstrip("\n ")
    new = new + " " * (header_len - len(new) - 1) + "\n"
    members["t.npy"] = raw[:10] + new.encode("latin1")[:header_len] + raw[10 + header_len:]
    with zipfile.ZipFile(path, "w") as z:
        for n, b in members.items():
            z.writestr(n, b)


def _pickled_member(cols: dict) -> dict:
    cols["t"] = np.array([{"t": 1.0}] * len(cols["t"]), dtype=object)
    return cols


def _symlink_loop(rel: str):
    def apply(data: Path) -> None:
        p = data / rel
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()
        p.symlink_to(p.name)
    return apply


def _root_loop(ws: Workspace, d: Path) -> list[str]:
    (d / "loop").symlink_to("loop")
    return fit_args(d / "loop")


def _unsorted(cols: dict) -> None:
    i = len(cols["t"]) // 2
    cols["t"][i], cols["t"][i + 1] = cols["t"][i + 1], cols["t"][i]
    if cols["t"][i] == cols["t"][i + 1]:
        cols["t"][i] += 1e-3


def _truncate_half(rel: str):
    def apply(data: Path) -> None:
        p = data / rel
        p.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    return apply


def _missing_view(sub: str, index: int = 5):
    def apply(data: Path) -> None:
        next((data / "train" / sub).glob(f"r_{index:05d}.*")).unlink()
    return apply


def _size_173(data: Path) -> None:
    """Write the scene.json size as the events' own (smaller) one: read as stated."""
    def edit(doc: dict) -> None:
        doc["width"], doc["height"] = 30, 20
        doc["camera"]["width"], doc["camera"]["height"] = 30, 20
        doc["preset"]["width"], doc["preset"]["height"] = 30, 20
    edit_scene(edit)(data)
    for split in ("train", "test"):
        for rgb in (data / split / "rgb").glob("*.png"):
            rgb.unlink()


def _read_as_30x20(d: Path) -> str | None:
    from hybridneus.data import load_dataset

    sp = load_dataset(d / "data", splits="train")["train"]
    return None if (sp.width, sp.height) == (30, 20) else f"read as {sp.width}x{sp.height}"


def _rgb_other_size(data: Path) -> None:
    import cv2

    rgb = next((data / "train" / "rgb").glob("*.png"))
    cv2.imwrite(str(rgb), np.zeros((40, 50, 3), np.uint8))


P0 = "train/pose/r_00000.txt"
K0 = "train/intrinsics/r_00000.txt"
NPZ = "train/events/events.npz"


def dataset_cases() -> list[Case]:
    c = dataset_case
    ev = edit_events
    return [
        Case("dataset", "dataset folder missing", lambda ws, d: ["info", str(d / "nope")],
             sees="does not exist|not found|no such"),
        Case("dataset", "dataset path is a file",
             lambda ws, d: (d / "f").write_text("x") and ["info", str(d / "f")],
             sees="not a folder|not a directory"),
        Case("dataset", "empty dataset folder",
             lambda ws, d: (d / "e").mkdir() or ["info", str(d / "e")], sees="split|pose"),
        c("no split folder, only scene.json",
          lambda p: [shutil.rmtree(p / s) for s in ("train", "test")], "split"),
        c("train/ without pose/", remove("train/pose"), "pose"),
        c("train/ without intrinsics/", remove("train/intrinsics"), "intrinsics"),
        c("train/ without events/", remove("train/events"), "events"),
        c("events/ without an npz file", remove(NPZ), "npz|events"),
        c("two npz files in events/",
          lambda p: shutil.copy(p / NPZ, p / "train/events/more.npz"), "npz"),
        c("events.npz is text", write_file(NPZ, "x y t p\n1 2 3 4\n"), "npz|zip"),
        c("events.npz cut in half", _truncate_half(NPZ), "npz|zip|truncated|read"),
        c("events.npz of zero bytes", write_file(NPZ, b""), "npz|empty|zip"),
        c("npz without t", ev(lambda z: {k: v for k, v in z.items() if k != "t"}), "'?t'?"),
        c("npz without p", ev(lambda z: {k: v for k, v in z.items() if k != "p"}), "'?p'?"),
        c("npz x with fractions", ev(lambda z: {**z, "x": z["x"] + 0.5}), "integer|whole"),
        c("npz x negative", ev(lambda z: {**z, "x": z["x"].astype(np.int32) - 30}),
          "x|negative|range|outside"),
        c("npz x beyond the width", ev(lambda z: {**z, "x": z["x"].astype(np.int32) + 24}),
          "x|width|range|outside"),
        c("npz y beyond the height", ev(lambda z: {**z, "y": z["y"].astype(np.int32) + 18}),
          "y|height|range|outside"),
        c("npz t holds NaN", ev(lambda z: {**z, "t": np.where(
            np.arange(len(z["t"])) == 7, np.nan, z["t"].astype(float))}), "NaN|finite"),
        c("npz t starts below zero", ev(lambda z: {**z, "t": z["t"] - 0.5}), "< 0|negative"),
        c("npz t not sorted", ev(_unsorted), "sorted"),
        c("npz polarity values 0 and 2", ev(lambda z: {**z, "p": (z["p"] > 0) * 2}),
          "polarit"),
        c("npz columns of different lengths", ev(lambda z: {**z, "p": z["p"][:-3]}),
          "length|entries|same"),
        c("npz member of pickled objects", ev(_pickled_member), "pickle|object"),
        c("npz header claims 10^12 entries", _claim_huge, "claims|entries|holds"),
        c("npz with no events", ev(lambda z: {k: v[:0] for k, v in z.items()}),
          "no events|empty"),
        c("every event of one polarity (fit)", ev(_one_polarity), "polarity", command="fit"),
        c("x and y exchanged, inside the sensor (fit)", ev(_swap_xy), "x and y columns swapped",
          command="fit", expect="warn", source="small"),
        c("symlink loop at events.npz", _symlink_loop(NPZ), "symbolic link|symlink|loop"),
        Case("dataset", "symlink loop at the dataset root (fit)", _root_loop,
             sees="symbolic link|symlink|loop"),
        c("pose file empty", write_file(P0, ""), "r_00000"),
        c("pose file of 5 numbers", write_file(P0, "1 2 3 4 5\n"), "r_00000"),
        c("pose file with words", write_file(P0, "a b c d\n"), "r_00000"),
        c("pose holds NaN", edit_matrix(P0, set_at((0, 3), np.nan)), "NaN"),
        c("pose rotation scaled by 2", edit_matrix(P0, lambda m: m * np.diag([2, 2, 2, 1])),
          "rotation"),
        c("pose last row not 0 0 0 1", edit_matrix(P0, set_at((3, 0), 1.0)), "last row"),
        c("pose a reflection (det -1)", edit_matrix(P0, lambda m: m * np.diag([-1, 1, 1, 1])),
          "rotation"),
        c("intrinsics file empty", write_file(K0, ""), "r_00000"),
        c("intrinsics hold NaN", edit_matrix(K0, set_at((0, 0), np.nan)), "NaN"),
        c("intrinsics fx = 0", edit_matrix(K0, set_at((0, 0), 0.0)), "focal|fx"),
        c("principal point at x = -5000", edit_matrix(K0, set_at((0, 2), -5000.0)),
          "principal point"),
        c("skew term of 5000", edit_matrix(K0, set_at((0, 1), 5000.0)), "skew"),
        c("k1 = 1e9 (a 5x4 intrinsics file)", edit_matrix(
            K0, lambda m: np.vstack([m, [1e9, 0, 0, 0]])), "k1|distortion|lens"),
        c("K's third row not 0 0 1", edit_matrix(K0, set_at((2, 0), 3.0)), "third row"),
        c("one pose file missing", _missing_view("pose"), "r_00005"),
        c("one intrinsics file missing", _missing_view("intrinsics"), "r_00005"),
        c("intrinsics named unlike the poses",
          _rename_views("intrinsics", lambda i: f"cam_{i:05d}"), "pose|intrinsics|name"),
        c("rgb frames named unlike the poses", _rename_views("rgb", lambda i: f"img_{i:05d}"),
          "rgb|name"),
        c("views r_0 .. r_11 (text order differs from numeric)", _unpadded,
          expect="recover", check=_paired_in_natural_order),
        c("an rgb frame of another size", _rgb_other_size, "size|50x40|24x18"),
        c("scene.json not JSON", write_file("scene.json", "{width: 24"), "scene.json"),
        c("scene.json width not an integer", edit_scene(lambda d: d.update(width=24.5)),
          "integer"),
        c("scene.json width negative", edit_scene(lambda d: d.update(width=-24)),
          "positive|integer"),
        c("scene.json width and camera.width disagree",
          edit_scene(lambda d: d.update(width=30)), "conflict|disagree|30"),
        c("scene.json size smaller than the events",
          edit_scene(lambda d: (d.update(width=10, height=8), d["camera"].update(
              width=10, height=8))), "10x8|width|outside|range"),
        c("scene.json states 30x20 (no rgb frames)", _size_173, expect="recover",
          check=_read_as_30x20),
        c("scene.json preset with an unknown key",
          edit_scene(lambda d: d["preset"].update(nosuch=1)), "unknown preset key 'nosuch'",
          expect="warn"),
        c("scene.json preset threshold negative",
          edit_scene(lambda d: d["preset"].update(threshold=-0.2)), "threshold"),
    ]


def fit_case(what: str, extra: list[str], sees: str, prepare_more=None,
             expect: str = "error") -> Case:
    """``hybridneus fit`` on the good dataset with ``extra`` arguments."""
    def prepare(ws: Workspace, d: Path) -> list[str]:
        if prepare_more is not None:
            prepare_more(ws, d)
        return fit_args(ws.data, *extra)
    return Case("config", what, prepare, expect, sees)


def resume_case(what: str, extra: list[str], sees: str, edit=None,
                data: bool = False) -> Case:
    def prepare(ws: Workspace, d: Path) -> list[str]:
        run = copy_run(ws, d)
        if edit is not None:
            edit(run)
        head = ["fit", str(copy_data(ws, d))] if data else ["fit"]
        return [*head, "--resume", str(run), "--device", "cpu", "--quiet", *extra]
    return Case("config", what, prepare, "error", sees)


def _config_file(text: str):
    def more(ws: Workspace, d: Path) -> None:
        (d / "c.yaml").write_text(text)
    return more


def config_cases() -> list[Case]:
    f = fit_case
    return [
        f("--set an unknown key", ["--set", "train.nosuch=1"], "nosuch"),
        f("--set a misspelt section", ["--set", "trian.lr=0.01"], "trian"),
        f("--set a number as text", ["--set", "train.lr=fast"], "train.lr"),
        f("--set without =", ["--set", "train.lr"], "train.lr|="),
        f("--set train.iters=-5", ["--set", "train.iters=-5"], "train.iters"),
        f("--set train.minutes=-3", ["--set", "train.minutes=-3"], "train.minutes"),
        f("--set train.lr=-1", ["--set", "train.lr=-1"], "train.lr"),
        f("--set train.lr=nan", ["--set", "train.lr=nan"], "train.lr"),
        f("--set grid.n_levels=0", ["--set", "grid.n_levels=0"], "n_levels"),
        f("--set train.n_rays=-1", ["--set", "train.n_rays=-1"], "n_rays"),
        f("--set render.n_coarse=0", ["--set", "render.n_coarse=0"], "n_coarse"),
        f("--set data.threshold=0", ["--set", "data.threshold=0"], "threshold"),
        f("--set data.threshold=-0.2", ["--set", "data.threshold=-0.2"], "threshold"),
        f("--set data.split=nosuch", ["--set", "data.split=nosuch"], "nosuch"),
        f("--set train.seed=-1", ["--set", "train.seed=-1"], "seed"),
        f("--iters 0", ["--iters", "0"], "--iters"),
        f("--minutes -1", ["--minutes", "-1"], "--minutes"),
        f("--iters with --minutes", ["--iters", "3", "--minutes", "1"],
          "--iters and --minutes"),
        f("--preset nosuch", ["--preset", "nosuch"], "nosuch"),
        f("--config file missing", ["--config", "missing.yaml"], "missing.yaml"),
        f("--config not YAML", ["--config", "c.yaml"], "c.yaml", _config_file("a: [1, 2\n")),
        f("--config a YAML list", ["--config", "c.yaml"], "c.yaml", _config_file("- 1\n- 2\n")),
        f("--config with an unknown key", ["--config", "c.yaml"], "nosuch",
          _config_file("train:\n  nosuch: 3\n")),
        f("--device cuda without a GPU", ["--device", "cuda"], "cuda|CUDA"),
        f("--device tpu", ["--device", "tpu"], "tpu"),
        Case("config", "--out is a file",
             lambda ws, d: (d / "file").write_text("x") and fit_args(ws.data) + [
                 "--out", "file"], sees="not a folder"),
        Case("config", "--out inside a file",
             lambda ws, d: (d / "file").write_text("x") and fit_args(ws.data) + [
                 "--out", "file/runs"], sees="file"),
        Case("config", "--resume a missing folder",
             lambda ws, d: ["fit", "--resume", str(d / "nope"), "--quiet"],
             sees="does not exist"),
        resume_case("--resume a run without checkpoints", [], "checkpoint",
                    lambda run: shutil.rmtree(run / "checkpoints")),
        resume_case("--resume on another dataset", [], "was fitted on", data=True),
        resume_case("--resume --iters at or below its step", ["--iters", "1"],
                    "already at step"),
        resume_case("--resume --minutes", ["--minutes", "3"], "schedule|--iters"),
        resume_case("--resume a run whose config.yaml is gone", [], "config",
                    lambda run: (run / "config.yaml").unlink()),
        resume_case("--resume a run whose scene.yaml is gone", [], "scene",
                    lambda run: (run / "scene.yaml").unlink()),
        Case("config", "fit without DATA or --resume", lambda ws, d: ["fit", "--quiet"],
             sees="DATA"),
    ]


def _garbage_checkpoint(run: Path) -> None:
    (run / "checkpoints" / "last.pt").write_bytes(b"not a checkpoint")
    (run / "checkpoints" / "previous.pt").unlink(missing_ok=True)


def _pickled_checkpoint(run: Path) -> None:
    import os

    import torch

    (run / "checkpoints" / "previous.pt").unlink(missing_ok=True)
    # a global that weights_only loading must refuse to call
    torch.save({"model": os.getcwd, "scene": {}, "step": 1, "total_steps": 2},
               run / "checkpoints" / "last.pt")


def _edit_checkpoint(edit):
    def apply(run: Path) -> None:
        import torch

        path = run / "checkpoints" / "last.pt"
        state = torch.load(path, weights_only=True)
        edit(state)
        torch.save(state, path)
        (run / "checkpoints" / "previous.pt").unlink(missing_ok=True)
    return apply


def _other_grid(run: Path) -> None:
    text = (run / "config.yaml").read_text()
    (run / "config.yaml").write_text(text.replace("log2_table_size: 12", "log2_table_size: 13"))


def run_case(what: str, edit, command: list[str], sees: str, expect: str = "error",
             check=None) -> Case:
    """A copy of the fitted run, changed by ``edit``, given to ``command`` (RUN replaced)."""
    def prepare(ws: Workspace, d: Path) -> list[str]:
        run = copy_run(ws, d)
        if edit is not None:
            edit(run)
        return [a.replace("RUN", str(run)) for a in command]
    return Case("run", what, prepare, expect, sees, check)


MESH = ["mesh", "RUN", "--res", "24", "--device", "cpu", "--no-preview", "--out", "m.ply"]


def _has_mesh(d: Path) -> str | None:
    return None if (d / "m.ply").is_file() else "no mesh written"


def run_cases() -> list[Case]:
    r = run_case
    return [
        Case("run", "mesh with no runs folder", lambda ws, d: ["mesh", "--runs-root", "runs"],
             sees="runs"),
        Case("run", "mesh on an empty runs folder",
             lambda ws, d: (d / "runs").mkdir() or ["mesh", "--runs-root", "runs"],
             sees="no run"),
        Case("run", "mesh on a missing run folder", lambda ws, d: ["mesh", "nope"],
             sees="nope"),
        r("last.pt unreadable, no previous.pt", _garbage_checkpoint, MESH, "last.pt"),
        r("last.pt unreadable, previous.pt good",
          lambda run: (run / "checkpoints" / "last.pt").write_bytes(b"x"), MESH,
          "previous.pt", expect="warn"),
        r("a pickled (non-tensor) checkpoint", _pickled_checkpoint, MESH, "last.pt"),
        r("a checkpoint without its scene record",
          _edit_checkpoint(lambda s: s.pop("scene")), MESH, "scene"),
        r("a checkpoint with NaN camera centres",
          _edit_checkpoint(lambda s: s["scene"].update(cameras=[[float("nan")] * 3])), MESH,
          "NaN"),
        r("config.yaml missing", lambda run: (run / "config.yaml").unlink(), MESH, "config"),
        r("config.yaml not YAML", lambda run: (run / "config.yaml").write_text("a: [\n"), MESH,
          "config.yaml"),
        r("config.yaml of another grid size", _other_grid, MESH, "does not match"),
        r("latest names a deleted run",
          lambda run: (run.parent / "latest").write_text("gone\n"),
          ["mesh", "--runs-root", "RUN/..", "--res", "24", "--device", "cpu", "--no-preview",
           "--out", "m.ply"], "", expect="recover", check=_has_mesh),
        r("mesh --res 0", None, [*MESH[:2], "--res", "0"], "--res"),
        r("mesh --res -5", None, [*MESH[:2], "--res", "-5"], "--res"),
        r("mesh --res 100000", None, [*MESH[:2], "--res", "100000"], "--res"),
        r("mesh --format xyz", None, [*MESH, "--format", "xyz"], "xyz"),
        r("mesh --out an existing folder",
          lambda run: (run.parent.parent / "m.ply").mkdir(), MESH, "m.ply"),
        r("mesh --out inside a file",
          lambda run: (run.parent.parent / "f").write_text("x"),
          [*MESH[:-1], "f/m.ply"], "f"),
        r("mesh --out with an unknown suffix", None, [*MESH[:-1], "m.xyz"], "xyz|suffix"),
        r("mesh --frame nosuch", None, [*MESH, "--frame", "nosuch"], "nosuch"),
        r("mesh --decimate -1", None, [*MESH, "--decimate", "-1"], "decimate"),
        r("mesh --min-component -1", None, [*MESH, "--min-component", "-1"], "min-component"),
        r("mesh --device cuda without a GPU", None, [*MESH[:-5], "--device", "cuda"],
          "cuda|CUDA"),
        r("mesh --chunk 0", None, [*MESH, "--chunk", "0"], "chunk"),
        r("render --views 999", None, ["render", "RUN", "--views", "999", "--out", "r",
                                       "--device", "cpu"], "999"),
        r("render --views abc", None, ["render", "RUN", "--views", "abc", "--out", "r",
                                       "--device", "cpu"], "abc"),
        r("render --split nosuch", None, ["render", "RUN", "--split", "nosuch", "--out", "r",
                                          "--device", "cpu"], "nosuch"),
        r("render --size 0", None, ["render", "RUN", "--size", "0", "--out", "r",
                                    "--device", "cpu"], "size"),
        r("render --data a missing folder", None, ["render", "RUN", "--data", "nope", "--out",
                                                   "r", "--device", "cpu"], "nope"),
        r("render --stride 0", None, ["render", "RUN", "--stride", "0", "--out", "r",
                                      "--device", "cpu"], "stride"),
    ]


def _mesh_file(name: str, content: str | bytes | None = None):
    def prepare(d: Path, ws: Workspace) -> Path:
        p = d / name
        if content is None:
            shutil.copy(ws.mesh, p)
        else:
            p.write_bytes(content if isinstance(content, bytes) else content.encode())
        return p
    return prepare


EMPTY_PLY = ("ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\n"
             "property float z\nelement face 0\nproperty list uchar int vertex_indices\n"
             "end_header\n")
NAN_PLY = ("ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
           "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
           "end_header\nnan 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")


def eval_case(what: str, pred, extra: list[str], sees: str) -> Case:
    def prepare(ws: Workspace, d: Path) -> list[str]:
        mesh = pred(d, ws) if pred is not None else ws.mesh
        return ["eval", str(mesh), str(ws.mesh), *extra]
    return Case("evaluate", what, prepare, "error", sees)


def other_cases() -> list[Case]:
    e = eval_case
    info = [
        e("eval: predicted mesh missing", lambda d, ws: d / "nope.ply", [], "nope.ply"),
        Case("evaluate", "eval: ground truth missing",
             lambda ws, d: ["eval", str(ws.mesh), str(d / "gt.ply")], sees="gt.ply"),
        e("eval: mesh file of garbage", _mesh_file("g.ply", "not a mesh\n"), [], "g.ply"),
        e("eval: mesh with no faces", _mesh_file("empty.ply", EMPTY_PLY), [], "empty.ply"),
        e("eval: mesh with a NaN vertex", _mesh_file("nan.ply", NAN_PLY), [], "nan.ply|NaN"),
        e("eval: mesh of an unknown suffix", _mesh_file("m.xyz", "1 2 3\n"), [], "m.xyz"),
        e("eval --threshold -1", None, ["--threshold", "-1"], "threshold"),
        e("eval --threshold 0", None, ["--threshold", "0"], "threshold"),
        e("eval --samples 0", None, ["--samples", "0"], "samples"),
        e("eval --sign nosuch", None, ["--sign", "nosuch"], "nosuch"),
        e("eval --error-max -1", None, ["--error-max", "-1", "--errors", "e.ply"],
          "error-max"),
        Case("dataset", "info on a file", lambda ws, d: (d / "f").write_text("x") and [
            "info", str(d / "f")], sees="f"),
        Case("dataset", "preview --n 0", lambda ws, d: ["preview", str(ws.data), "--out", "p",
                                                        "--n", "0"], sees="--n"),
        Case("dataset", "preview --window -1", lambda ws, d: [
            "preview", str(ws.data), "--out", "p", "--window", "-1"], sees="window"),
        Case("dataset", "preview --split nosuch", lambda ws, d: [
            "preview", str(ws.data), "--out", "p", "--split", "nosuch"], sees="nosuch"),
        Case("dataset", "preview --background green", lambda ws, d: [
            "preview", str(ws.data), "--out", "p", "--background", "green"], sees="green"),
    ]
    sim = "simulate"
    small = ["--views", "4", "--width", "16", "--height", "12", "--val-views", "0",
             "--test-views", "0", "--quiet"]
    simulate = [
        Case(sim, "simulate a missing mesh file",
             lambda ws, d: ["simulate", "nope.obj", "out", *small], sees="nope.obj"),
        Case(sim, "simulate builtin:nosuch",
             lambda ws, d: ["simulate", "builtin:nosuch", "out", *small], sees="nosuch"),
        Case(sim, "simulate generated:box:abc",
             lambda ws, d: ["simulate", "generated:box:abc", "out", *small], sees="abc"),
        Case(sim, "simulate generated:nosuch:1",
             lambda ws, d: ["simulate", "generated:nosuch:1", "out", *small], sees="nosuch"),
        Case(sim, "simulate a mesh file of garbage",
             lambda ws, d: (d / "g.ply").write_text("garbage") and [
                 "simulate", "g.ply", "out", *small], sees="g.ply"),
        Case(sim, "simulate --views 0",
             lambda ws, d: ["simulate", "builtin:device", "out", *small, "--views", "0"],
             sees="views"),
        Case(sim, "simulate --width 0",
             lambda ws, d: ["simulate", "builtin:device", "out", *small, "--width", "0"],
             sees="width"),
        Case(sim, "simulate --threshold -0.2",
             lambda ws, d: ["simulate", "builtin:device", "out", *small, "--threshold",
                            "-0.2"], sees="threshold"),
        Case(sim, "simulate --sensor nosuch",
             lambda ws, d: ["simulate", "builtin:device", "out", *small, "--sensor", "nosuch"],
             sees="nosuch"),
        Case(sim, "simulate OUT is a file",
             lambda ws, d: (d / "out").write_text("x") and [
                 "simulate", "builtin:device", "out", *small], sees="out"),
        Case(sim, "demo --minutes -1", lambda ws, d: ["demo", "--out", "demo", "--minutes",
                                                      "-1"], sees="minutes"),
    ]
    return info + simulate + batch_cases() + report_cases()


def report_cases() -> list[Case]:
    def case(what: str, prepare, sees: str, expect: str = "error", check=None) -> Case:
        return Case("report", what, prepare, expect, sees, check)

    def garbled_metrics(ws: Workspace, d: Path) -> list[str]:
        run = copy_run(ws, d)
        (run / "metrics.csv").write_text("step,loss/total\n1,abc\n\x00\x01,2,3\n")
        return ["report", str(run)]

    def written(d: Path) -> str | None:
        pages = list((d / "runs").glob("*/report.html"))
        return None if pages and pages[0].stat().st_size > 10**6 else "no report.html"

    def scores(text: str):
        def make(ws: Workspace, d: Path) -> list[str]:
            (d / "s.json").write_text(text)
            return ["report", str(ws.run), "--eval", str(d / "s.json"), "--out", "r.html"]
        return make

    return [
        case("report of a missing folder", lambda ws, d: ["report", str(d / "nope")], "nope"),
        case("report of a folder that is not a run",
             lambda ws, d: (d / "x").mkdir() or ["report", str(d / "x")], "not a run folder"),
        case("report --mesh missing", lambda ws, d: [
            "report", str(ws.run), "--mesh", str(d / "nope.ply"), "--out", "r.html"],
             "nope.ply"),
        case("report --mesh of garbage", lambda ws, d: (d / "g.ply").write_text("garbage") and [
            "report", str(ws.run), "--mesh", str(d / "g.ply"), "--out", "r.html"], "g.ply"),
        case("report --eval not eval's", scores('{"steps": 3}'), "s.json"),
        case("report --eval of garbage", scores("not json"), "s.json"),
        case("report --out is a folder", lambda ws, d: (d / "o").mkdir() or [
            "report", str(ws.run), "--out", str(d / "o")], "is a folder"),
        case("report of a run with a garbled metrics.csv", garbled_metrics, "",
             expect="recover", check=written),
    ]


def _manifest(content: str) -> Callable[[Workspace, Path], Path]:
    def make(ws: Workspace, d: Path) -> Path:
        (d / "m.yaml").write_text(content.replace("DATA", str(ws.data)))
        return d / "m.yaml"
    return make


def batch_cases() -> list[Case]:
    good = "jobs:\n  - {name: a, data: DATA, iters: 2, mesh: false}\n"

    def case(what: str, manifest, extra: list[str], sees: str, before=None) -> Case:
        def prepare(ws: Workspace, d: Path) -> list[str]:
            path = manifest(ws, d) if callable(manifest) else d / manifest
            if before is not None:
                before(d)
            return ["batch", str(path), "--out", str(d / "runs"), "-q", *extra]
        return Case("batch", what, prepare, sees=sees)

    def garbage_state(d: Path) -> None:
        (d / "runs").mkdir()
        (d / "runs" / "batch.json").write_text("not json")

    return [
        case("batch: manifest missing", "nope.yaml", [], "nope.yaml"),
        case("batch: manifest not YAML", _manifest("jobs: [a, {"), [], "m.yaml"),
        case("batch: a job with an unknown key", _manifest(
            "jobs:\n  - {name: a, data: DATA, colour: red}\n"), [], "colour"),
        case("batch: a job with no dataset", _manifest("jobs:\n  - {name: a}\n"), [],
             "data"),
        case("batch: two jobs of one name", _manifest(good + "  - {name: a, data: DATA}\n"),
             [], "two jobs"),
        case("batch --executor dask", _manifest(good), ["--executor", "dask"], "dask"),
        case("batch --workers 0", _manifest(good), ["--workers", "0"], "workers"),
        case("batch: a state file of garbage", _manifest(good), [], "batch.json",
             before=garbage_state),
    ]


def convert_case(what: str, events=None, extra: list[str] | None = None, sees: str = "",
                 expect: str = "error", fmt: str = "h5", poses=None, calib=None,
                 turntable=None, check=None) -> Case:
    """``hybridneus convert`` of the good recording in ``fmt`` (or what ``events`` writes),
    with the turntable and calibration unless ``poses`` (a TUM file) replaces the first."""
    def prepare(ws: Workspace, d: Path) -> list[str]:
        ev = events(ws, d) if events is not None else ws.recordings[fmt]
        pose_args = (["--poses", str(poses(ws, d))] if poses is not None else
                     ["--turntable", str(turntable(ws, d) if turntable else ws.turntable)])
        cal = calib(ws, d) if calib is not None else ws.calib
        return ["convert", str(ev), "out", *pose_args, "--calib", str(cal), "--views", "8",
                "-q", *(extra or [])]
    return Case("recording", what, prepare, expect, sees, check)


def _recording_bytes(fmt: str, edit: Callable[[bytes], bytes], name: str | None = None):
    def make(ws: Workspace, d: Path) -> Path:
        src = ws.recordings[fmt]
        p = d / (name or src.name)
        if src.is_dir():
            shutil.copytree(src, p)
        else:
            p.write_bytes(edit(src.read_bytes()))
        return p
    return make


def _text_events(text: str, name: str = "events.txt"):
    def make(ws: Workspace, d: Path) -> Path:
        (d / name).write_text(text)
        return d / name
    return make


def _h5(build: Callable) -> Callable[[Workspace, Path], Path]:
    def make(ws: Workspace, d: Path) -> Path:
        import h5py

        with h5py.File(d / "events.h5", "w") as f:
            build(f)
        return d / "events.h5"
    return make


def _bag_without_events(ws: Workspace, d: Path) -> Path:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC)
    with Writer(d / "imu.bag") as w:
        conn = w.add_connection("/imu", "std_msgs/msg/String", typestore=store)
        w.write(conn, 1, store.serialize_ros1(store.types["std_msgs/msg/String"](data="x"),
                                              "std_msgs/msg/String"))
    return d / "imu.bag"


def _evt4(ws: Workspace, d: Path) -> Path:
    raw = ws.recordings["evt3"].read_bytes()
    (d / "v4.raw").write_bytes(raw.replace(b"evt 3.0", b"evt 4.0").replace(b"EVT3", b"EVT4"))
    return d / "v4.raw"


def _tum(rows: Callable[[np.ndarray], np.ndarray] | None = None, name: str = "poses.txt",
         text: str | None = None):
    def make(ws: Workspace, d: Path) -> Path:
        if text is not None:
            (d / name).write_text(text)
            return d / name
        table = np.loadtxt(ws.poses)
        np.savetxt(d / name, rows(table.copy()) if rows else table, fmt="%.9g")
        return d / name
    return make


def _set(index, value):
    def edit(t: np.ndarray) -> np.ndarray:
        t[index] = value
        return t
    return edit


def _json_file(doc: dict | str, name: str):
    def make(ws: Workspace, d: Path) -> Path:
        (d / name).write_text(doc if isinstance(doc, str) else json.dumps(doc))
        return d / name
    return make


def _edited(good: str, **changes):
    """A copy of the workspace's JSON file ``good`` (``"calib"``, ``"turntable"``) with
    ``changes`` (a None value removes its key)."""
    def make(ws: Workspace, d: Path) -> Path:
        source = getattr(ws, good)
        doc = {**json.loads(source.read_text()), **changes}
        doc = {k: v for k, v in doc.items() if v is not None}
        (d / source.name).write_text(json.dumps(doc))
        return d / source.name
    return make


def _calib(**changes):
    return _edited("calib", **changes)


def _turntable(**changes):
    return _edited("turntable", **changes)


def _npz_without_p(ws: Workspace, d: Path) -> Path:
    np.savez(d / "e.npz", t=np.arange(5), x=np.ones(5), y=np.ones(5))
    return d / "e.npz"


def _out_not_empty(ws: Workspace, d: Path) -> Path:
    (d / "out").mkdir()
    (d / "out" / "notes.txt").write_text("mine")
    return ws.recordings["h5"]


def _converted(d: Path) -> str | None:
    return None if (d / "out" / "scene.json").is_file() else "no dataset written"


def recording_cases() -> list[Case]:
    c = convert_case
    cases = []
    for fmt in FORMATS:
        half = _recording_bytes(fmt, lambda b: b[: len(b) // 2])
        if fmt in STREAMS:
            # nothing in these files says how long they were: a cut one is a shorter recording
            cut = c(f"{fmt}: recording cut in half (no length in the format)", half, fmt=fmt,
                    expect="recover", check=_converted)
        else:
            cut = c(f"{fmt}: recording cut in half", half, fmt=fmt, expect="warn",
                    sees="cut|truncat|incomplete|cannot|damaged|failed|columns|zip|short")
        cases += [cut, c(f"{fmt}: empty file", _recording_bytes(fmt, lambda b: b""), fmt=fmt,
                         sees="empty")]
    cases += [
        c("recording file missing", lambda ws, d: d / "nope.h5", sees="nope.h5"),
        c("unknown file type", _text_events("1 2 3 4\n", "e.xyz"), sees="e.xyz"),
        c("HDF5 without an events group", _h5(lambda f: f.create_group("other")),
          sees="events"),
        c("Prophesee HDF5 (its own codec)",
          _h5(lambda f: f.create_group("CD").create_dataset("events", data=np.zeros(3))),
          sees="Prophesee"),
        c("HDF5 events with columns of different lengths",
          _h5(lambda f: [f.create_dataset(f"events/{k}", data=np.arange(n)) for k, n in
                         (("t", 10), ("x", 10), ("y", 9), ("p", 10))]), sees="length|same"),
        c("EVT 4.0 RAW (unsupported version)", _evt4, sees="EVT4|evt 4"),
        c("ROS bag without an event topic", _bag_without_events, sees="no event topic"),
        c("--topic that the bag lacks", None, ["--topic", "/nope"], fmt="bag",
          sees="/nope"),
        c("text with three columns", _text_events("0.1 2 3\n0.2 4 5\n"), sees="columns"),
        c("text with words", _text_events("t x y p\na b c d\n"), sees="events.txt"),
        c("text polarity 7", _text_events("0.1 2 3 1\n0.2 2 3 7\n"), sees="polarity"),
        c("text x beyond the sensor", _text_events("0.1 2 3 1\n0.2 9000 3 0\n"),
          sees="9000|outside|width|346"),
        c("--columns xyz", None, ["--columns", "xyz"], fmt="txt", sees="columns"),
        c("--time-unit fortnights", None, ["--time-unit", "fortnights"], fmt="txt",
          sees="fortnights"),
        c("npz recording without p", _npz_without_p, sees="p"),
        # an occluded tracker row: dropped and counted, the rest of the track is used
        c("poses: NaN quaternion", poses=_tum(_set((3, 5), np.nan)), expect="warn",
          sees="1 occluded row"),
        c("poses: zero quaternion", poses=_tum(_set((3, slice(4, 8)), 0.0)), expect="warn",
          sees="1 occluded row"),
        c("poses: times not increasing", poses=_tum(_set((3, 0), 0.0)), sees="increase"),
        c("poses: quaternion of length 2", poses=_tum(lambda t: np.column_stack(
            [t[:, :4], 2 * t[:, 4:]])), sees="unit"),
        c("poses: seven columns", poses=_tum(lambda t: t[:, :7]), sees="8"),
        c("poses: track ends before the events begin", poses=_tum(_shift_track(-1e4)),
          sees="cover|outside|before|track"),
        c("poses: track covers a tenth of the recording", poses=_tum(_tenth),
          expect="warn", sees="dropped|outside"),
        c("poses: file missing", poses=lambda ws, d: d / "nope.txt", sees="nope.txt"),
        c("poses: CSV without a quaternion column",
          poses=_tum(text="time,x,y,z\n0,0,0,0\n1,0,0,0\n", name="p.csv"), sees="p.csv"),
        c("poses: empty COLMAP folder", poses=lambda ws, d: (d / "sparse").mkdir() or
          d / "sparse", sees="sparse"),
        c("turntable without an axis", turntable=_turntable(axis=None), sees="axis"),
        c("turntable at speed 0", turntable=_turntable(speed_deg_s=0.0), sees="speed"),
        c("turntable camera not 4x4", turntable=_turntable(camera=[[1, 0], [0, 1]]),
          sees="camera|4x4"),
        c("turntable file not JSON", turntable=_json_file("{axis", "t.json"), sees="t.json"),
        c("calibration without an image size", calib=_calib(width=None, height=None),
          sees="image size"),
        c("calibration principal point outside", calib=_calib(cx=-5000.0),
          sees="outside"),
        c("calibration skew 5000", calib=_calib(skew=5000.0), sees="skew"),
        c("calibration width 346.5", calib=_calib(width=346.5), sees="integer"),
        c("calibration of an unknown lens model", calib=_calib(model="division",
                                                                coeffs=[0.1]),
          sees="not supported"),
        c("calibration for another sensor size", calib=_calib(width=640, height=480,
                                                              cx=320.0, cy=240.0),
          fmt="aedat4", sees="640x480|346x260|size"),
        c("calibration file missing", calib=lambda ws, d: d / "nope.yaml", sees="nope.yaml"),
        c("calibration YAML not YAML", calib=_json_file("cam0: [\n", "c.yaml"), sees="c.yaml"),
        c("Kalibr camchain without the named camera",
          calib=_json_file("cam0:\n  intrinsics: [300, 300, 172, 129]\n  resolution: [346, 260]"
                           "\n  distortion_model: radtan\n  distortion_coeffs: [0, 0, 0, 0]\n"
                           "  camera_model: pinhole\n", "chain.yaml"),
          extra=["--camera", "cam1"], sees="cam1"),
        c("--views 1", None, ["--views", "1"], sees="views"),
        c("--views 0", None, ["--views", "0"], sees="views"),
        c("--start after --end", None, ["--start", "300", "--end", "100"], sees="start|end"),
        c("--start after the recording", None, ["--start", "5000"],
          sees="start|after|no events|outside"),
        c("--hand-eye not a 4x4 matrix", None, ["--hand-eye", "1,2,3"], sees="hand-eye"),
        c("--box malformed", None, ["--box", "1,2"], sees="box"),
        c("--up nonsense", None, ["--up", "sideways"], sees="up|sideways"),
        c("--clock-offset nan", None, ["--clock-offset", "nan"], sees="clock"),
        c("--sensor nosuch", None, ["--sensor", "nosuch"], sees="nosuch"),
        c("--threshold -0.2", None, ["--threshold", "-0.2"], sees="threshold"),
        c("--spacing nosuch", None, ["--spacing", "nosuch"], sees="nosuch"),
        c("--point malformed", None, ["--check", "--point", "a,b"], sees="point"),
        c("OUT already holds other files", _out_not_empty, sees="out"),
        Case("recording", "neither --poses nor --turntable",
             lambda ws, d: ["convert", str(ws.recordings["h5"]), "out", "--calib",
                            str(ws.calib), "-q"], sees="poses|turntable"),
        Case("recording", "--poses and --turntable together",
             lambda ws, d: ["convert", str(ws.recordings["h5"]), "out", "--calib",
                            str(ws.calib), "--poses", str(ws.poses), "--turntable",
                            str(ws.turntable), "-q"], sees="poses|turntable"),
    ]
    return cases


def _shift_track(by: float):
    def edit(t: np.ndarray) -> np.ndarray:
        t[:, 0] += by
        return t
    return edit


def _tenth(t: np.ndarray) -> np.ndarray:
    return t[t[:, 0] <= t[0, 0] + (t[-1, 0] - t[0, 0]) / 10]


# ----------------------------------------------------------------- faults


def _metrics_step(run_root: Path) -> int:
    for metrics in run_root.glob("*/metrics.csv"):
        lines = metrics.read_text().splitlines()[1:]
        steps = [int(r.split(",")[0]) for r in lines if r.split(",")[0].isdigit()]
        return max(steps, default=0)
    return 0


def _kill(proc: subprocess.Popen, sig: int = signal.SIGKILL) -> None:
    proc.send_signal(sig)
    proc.wait(timeout=120)


def _wait_for(proc: subprocess.Popen, ready: Callable[[], bool], timeout: float = 300) -> None:
    end = time.monotonic() + timeout
    while proc.poll() is None and not ready() and time.monotonic() < end:
        time.sleep(0.01)


def _finish(args: list[str], d: Path) -> tuple[int, str, str]:
    done = subprocess.run(hybridneus(*args), cwd=d, capture_output=True, text=True,
                          timeout=600)
    return done.returncode, done.stdout, done.stderr


def _long_fit(ws: Workspace, d: Path) -> list[str]:
    return fit_args(ws.data, "--set", "train.checkpoint_every=5", "--set",
                    "train.log_every=1", "--set", "train.threads=1", "--iters", "60")


def _the_run(d: Path) -> Path:
    return next(p for p in (d / "runs").iterdir() if p.is_dir())


def _fit_killed(at_step: int | None, sig: int = signal.SIGKILL):
    """Start a 60-step fit, kill it after ``at_step`` steps (``None``: 1 s after it starts),
    then resume it to the end; the outcome is the resume's."""
    def run(ws: Workspace, d: Path, args: list[str]) -> tuple[int, str, str]:
        proc = subprocess.Popen(hybridneus(*args), cwd=d, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        if at_step is None:
            time.sleep(1.0)
        else:
            _wait_for(proc, lambda: _metrics_step(d / "runs") >= at_step)
        _kill(proc, sig)
        folders = [p for p in (d / "runs").glob("*") if p.is_dir()] \
            if (d / "runs").is_dir() else []
        if not folders or not (folders[0] / "checkpoints" / "last.pt").is_file():
            return _finish(args, d)  # killed before the run existed: start it again
        return _finish(["fit", "--resume", str(folders[0]), "--quiet"], d)
    return run


def _finished_at(steps: int):
    def check(d: Path) -> str | None:
        import torch

        run = _the_run(d)
        state = torch.load(run / "checkpoints" / "last.pt", weights_only=True)
        if state["step"] != steps:
            return f"ended at step {state['step']}"
        left = [p.name for p in run.rglob(".*tmp*")]
        return f"left {left}" if left else None
    return check


def _stale_save(ws: Workspace, d: Path) -> list[str]:
    run = copy_run(ws, d)
    (run / "checkpoints" / ".last.12345.abcd.tmp.pt").write_bytes(b"\0" * 4096)
    (run / ".metrics.12345.abcd.tmp.csv").write_text("step\n")
    return ["fit", "--resume", str(run), "--iters", "4", "--device", "cpu", "--quiet"]


def _no_temporaries(d: Path) -> str | None:
    left = [str(p.relative_to(d)) for p in d.rglob(".*tmp*")]
    return f"left {left}" if left else None


def _cut_metrics(ws: Workspace, d: Path) -> list[str]:
    run = copy_run(ws, d)
    with open(run / "metrics.csv", "a") as f:
        f.write("3,0.1")  # a row cut short by a kill
    return ["fit", "--resume", str(run), "--iters", "4", "--device", "cpu", "--quiet"]


def _metrics_whole(d: Path) -> str | None:
    header, *rows = (_the_run(d) / "metrics.csv").read_text().splitlines()
    cut = [r for r in rows if r.count(",") != header.count(",")]
    steps = [int(r.split(",")[0]) for r in rows]
    return f"rows {cut} cut short" if cut else None if steps == sorted(set(steps)) else \
        f"steps {steps}"


def _killed_writer(command: Callable[[Workspace, Path], list[str]], after: float):
    """Kill ``command`` ``after`` seconds in, then run it again; the outcome is the rerun's."""
    def run(ws: Workspace, d: Path, args: list[str]) -> tuple[int, str, str]:
        proc = subprocess.Popen(hybridneus(*args), cwd=d, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True)
        time.sleep(after)
        _kill(proc)
        return _finish(args, d)
    return run


def _mesh_big(ws: Workspace, d: Path) -> list[str]:
    run = copy_run(ws, d)
    return ["mesh", str(run), "--res", "160", "--device", "cpu", "--no-preview", "--out",
            "m.ply"]


def fault_cases() -> list[Case]:
    ok = _finished_at(60)
    return [
        Case("fault", "fit killed (SIGKILL) at step 20, resumed", _long_fit, "recover",
             check=ok, run=_fit_killed(20)),
        Case("fault", "fit killed (SIGKILL) 1 s after it starts, resumed", _long_fit,
             "recover", check=ok, run=_fit_killed(None)),
        Case("fault", "fit stopped by Ctrl-C (SIGINT) at step 10, resumed", _long_fit,
             "recover", check=ok, run=_fit_killed(10, signal.SIGINT)),
        Case("fault", "fit killed (SIGTERM) at step 30, resumed", _long_fit, "recover",
             check=ok, run=_fit_killed(30, signal.SIGTERM)),
        Case("fault", "resume beside a killed save's temporary files", _stale_save, "recover",
             check=_no_temporaries),
        Case("fault", "resume after a kill cut metrics.csv mid-row", _cut_metrics, "recover",
             check=_metrics_whole),
        Case("fault", "last.pt missing, previous.pt there (resume)",
             lambda ws, d: (lambda run: (run / "checkpoints" / "last.pt").unlink() or [
                 "fit", "--resume", str(run), "--iters", "4", "--device", "cpu", "--quiet"])(
                 copy_run(ws, d)), "warn", sees="previous.pt"),
        Case("fault", "fit with train.lr=1e6 (a diverging loss)",
             lambda ws, d: fit_args(ws.data, "--set", "train.lr=1000000") + [
                 "--iters", "40"], "warn", sees="diverged|restored"),
        Case("fault", "mesh killed while it runs, run again", _mesh_big, "recover",
             check=lambda d: _no_temporaries(d) or _has_mesh(d),
             run=_killed_writer(_mesh_big, 4.0)),
        Case("fault", "convert killed while it runs, run again",
             lambda ws, d: ["convert", str(ws.recordings["txt"]), "out", "--turntable",
                            str(ws.turntable), "--calib", str(ws.calib), "--views", "8", "-q"],
             "recover", check=lambda d: _no_temporaries(d) or _converted(d),
             run=_killed_writer(None, 3.0)),
        Case("fault", "simulate killed while it runs, run again",
             lambda ws, d: ["simulate", "builtin:device", "sim", "--views", "60", "--width",
                            "64", "--height", "48", "--quiet"], "recover",
             check=lambda d: _no_temporaries(d) or (
                 None if (d / "sim" / "scene.json").is_file() else "no dataset"),
             run=_killed_writer(None, 3.0)),
    ]


def all_cases() -> list[Case]:
    return [*dataset_cases(), *config_cases(), *run_cases(), *other_cases(),
            *recording_cases(), *fault_cases()]
