"""Bad inputs and faults, tried as a user would meet them: docs/reliability.md.

Every case of ``benchmarks/reliability_cases.py`` runs the ``hybridneus`` command a person would
type, in a fresh process and a folder of its own, on inputs made bad in one way from good ones
(a simulated dataset, a fitted run, a recording in each event format). What the person sees is
judged:

- ``traceback``: a Python traceback reached the terminal;
- ``silent``: a bad input was taken without an error or its warning (exit code 0);
- ``unclear``: it failed, but not with exit code 2 and one line that matches the case;
- ``leftover``: a failed command left files behind, or any command left a temporary file;
- ``ok``: none of these (for a fault: the command after it succeeded and the state is right).

Writes ``docs/reliability.md`` (every case, the command and the message) and a result line
to ``benchmarks/results/reliability.jsonl``.

Usage::

    python benchmarks/reliability.py                 # all cases, two at a time
    python benchmarks/reliability.py --only npz -j 1  # cases whose name holds "npz"
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import common
import numpy as np
import reliability_cases as rc

DOC = common.REPO / "docs" / "reliability.md"
TEMPORARY = re.compile(r"^\..*tmp")
TRACEBACK = "Traceback (most recent call last)"
VERDICTS = ("ok", "traceback", "silent", "unclear", "leftover", "wrong", "harness error")


@dataclass
class Row:
    group: str
    what: str
    command: str
    code: int
    message: str
    verdict: str
    seconds: float


def build_workspace(root: Path) -> rc.Workspace:
    """The good inputs: two simulated datasets, a fitted run, a mesh, and a ten-minute
    recording of 20,000 events in every format with a turntable, a TUM track and a
    calibration."""
    import trimesh
    from bench_convert import write_recording, write_setup
    from scipy.spatial.transform import Rotation

    from hybridneus.api import fit
    from hybridneus.config import apply_overrides, preset_config
    from hybridneus.simulate import SimulationConfig, simulate_dataset

    sim = dict(val_views=0, revolutions=1.0, supersample=1)
    simulate_dataset("builtin:device", root / "data",
                     SimulationConfig(n_views=12, width=24, height=18, test_views=2, **sim),
                     progress=False)
    simulate_dataset("builtin:device", root / "small",
                     SimulationConfig(n_views=24, width=48, height=36, test_views=0,
                                      object_radius=0.2, **sim), progress=False)
    cfg = apply_overrides(preset_config("fast"), [*rc.TINY, "train.iters=2",
                                                  "train.checkpoint_every=1"])
    field = fit(root / "data", cfg, out=root / "runs", device="cpu", progress=False)
    mesh = root / "mesh.ply"
    trimesh.creation.icosphere(subdivisions=3, radius=0.3).export(mesh)
    rec = root / "recording"
    rec.mkdir()
    recordings = {}
    for fmt in rc.FORMATS:
        folder = rec / fmt
        folder.mkdir()
        recordings[fmt] = write_recording(folder, 20000, fmt)
    turntable, calib = write_setup(rec)
    t = np.linspace(-1.0, 601.0, 6021)
    angle = np.deg2rad(6.0 * t)
    centre = np.column_stack([0.5 * np.sin(angle), np.zeros_like(t), 0.5 * np.cos(angle)])
    forward = -centre / np.linalg.norm(centre, axis=1, keepdims=True)
    down = np.tile([0.0, -1.0, 0.0], (len(t), 1))
    right = np.cross(down, forward)
    rot = Rotation.from_matrix(np.stack([right, down, forward], axis=2))
    np.savetxt(rec / "poses.txt", np.column_stack([t, centre, rot.as_quat()]), fmt="%.9g")
    return rc.Workspace(root=root, data=root / "data", small=root / "small",
                        runs=root / "runs", run=field.run_dir, mesh=mesh,
                        recordings=recordings, turntable=turntable, calib=calib,
                        poses=rec / "poses.txt")


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def _message(err: str, expect: str, sees: str) -> str:
    """The line a person reads: the error, else the warning the case looks for, else the
    last line written."""
    lines = [ln.strip(" │╭╮╰╯─") for ln in err.splitlines()]
    lines = [ln.strip() for ln in lines if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("error:")]
    usage = [ln for ln in lines if re.search(r"Invalid value|No such option|Missing|Got unexp"
                                             r"ected|requires an argument", ln)]
    if errors:
        return errors[-1]
    if usage:
        return usage[-1]
    if sees and expect == "warn":
        found = [ln for ln in lines if re.search(sees, ln, re.I)]
        if found:
            return found[-1]
    return lines[-1] if lines else ""


def judge(case: rc.Case, code: int, out: str, err: str, new: set[str], folder: Path) -> str:
    if TRACEBACK in out or TRACEBACK in err:
        return "traceback"
    temporaries = [p for p in new if TEMPORARY.match(Path(p).name)]
    message = _message(err, case.expect, case.sees)
    matches = not case.sees or bool(re.search(case.sees, message, re.I))
    if code == 0:
        if case.expect == "error":
            return "silent"
        if case.expect == "warn" and not (case.sees and re.search(case.sees, out + err, re.I)):
            return "silent"
        if case.check is not None and (why := case.check(folder)):
            return f"wrong: {why}"
        return "leftover" if temporaries else "ok"
    if case.expect == "recover":
        return "unclear"
    failed_ok = code == 2 and matches and message.startswith(("error:", "Error:"))
    if not failed_ok:
        return "unclear"
    return "leftover" if new else "ok"


def run_case(case: rc.Case, ws: rc.Workspace, folder: Path) -> Row:
    folder.mkdir(parents=True)
    args = case.prepare(ws, folder)
    before = _files(folder)
    start = time.perf_counter()
    if case.run is not None:
        code, out, err = case.run(ws, folder, args)
    else:
        try:
            done = subprocess.run(rc.hybridneus(*args), cwd=folder, capture_output=True,
                                  text=True, timeout=600)
            code, out, err = done.returncode, done.stdout, done.stderr
        except subprocess.TimeoutExpired:
            code, out, err = -1, "", "timed out after 600 s"
    seconds = time.perf_counter() - start
    (folder.parent / f"{folder.name}.log").write_text(f"{args}\nexit {code}\n{out}\n{err}")
    new = _files(folder) - before
    if case.run is not None or case.expect != "error":
        new = {p for p in new if TEMPORARY.match(Path(p).name)}
    verdict = judge(case, code, out, err, new, folder)
    if verdict == "leftover":
        verdict += ": " + ", ".join(sorted(new)[:3])
    message = _message(out + "\n" + err if code == 0 else err, case.expect, case.sees)
    shown = " ".join(_shown(a, ws, folder) for a in args)
    return Row(case.group, case.what, f"hybridneus {shown}", code,
               _shown(message, ws, folder), verdict, seconds)


def _shown(text: str, ws: rc.Workspace, folder: Path) -> str:
    """Paths as a person would write them: relative to the case folder or the workspace."""
    text = text.replace(str(folder) + "/", "").replace(str(folder), ".")
    text = text.replace(str(ws.root) + "/", "").replace(str(ws.root), "")
    return text.replace(sys.executable, "python")


def table(rows: list[Row], line: dict) -> str:
    counts = {k: sum(r.verdict.split(":")[0] == k for r in rows)
              for k in VERDICTS}
    out = [
        "# Reliability: bad inputs and faults",
        "",
        "Generated by `python benchmarks/reliability.py` (do not edit by hand) at commit "
        f"`{line['commit']}` on {line['date'][:10]}. Each case runs the command shown in a "
        "fresh process and a folder of its own, on inputs made bad in one way from good ones "
        "(a simulated dataset, a fitted run, a ten-minute recording in each event format). "
        "Verdicts: **ok**; **traceback** (a Python traceback reached the terminal); "
        "**silent** (a bad input taken with exit code 0 and no warning); **unclear** (not "
        "exit code 2 with one line matching the case); **leftover** (a failed command left "
        "files, or any command a temporary file); **wrong** (a fault's recovery ended in the "
        "wrong state). A case expects an error (exit code 2, one line naming the file or "
        "option and the fault), a warning (a specific line; an error does as well) or, for "
        "faults and inputs that are odd but valid, a recovery whose result is checked.",
        "",
        f"**{len(rows)} cases: {counts['ok']} ok, {counts['traceback']} tracebacks, "
        f"{counts['silent']} silent accepts, {counts['unclear']} unclear, "
        f"{counts['leftover']} leftovers, {counts['wrong']} wrong.**",
        "",
    ]
    for group in dict.fromkeys(r.group for r in rows):
        out += [f"## {group}", "", "| case | command | exit | what the user sees | verdict |",
                "|---|---|---|---|---|"]
        for r in rows:
            if r.group == group:
                cells = [r.what, f"`{r.command}`", str(r.code), r.message[:220], r.verdict]
                out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        out.append("")
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="run the cases whose name holds this text")
    ap.add_argument("-j", "--jobs", type=int, default=2, help="cases run at once")
    ap.add_argument("--keep", type=Path, default=None, help="work here and keep the files")
    ap.add_argument("--doc", type=Path, default=DOC, help="where the table goes")
    common.add_arguments(ap, "reliability")
    args = ap.parse_args()
    common.check_tree(args)
    cases = [c for c in rc.all_cases() if args.only.lower() in c.what.lower()]
    work = args.keep or Path(tempfile.mkdtemp(prefix="hybridneus-reliability-"))
    work.mkdir(parents=True, exist_ok=True)
    env_threads = os.environ.setdefault("OMP_NUM_THREADS", "1")
    tick = time.perf_counter()
    ws = build_workspace(work / "good")
    print(f"workspace ready in {time.perf_counter() - tick:.0f} s; {len(cases)} cases",
          flush=True)

    def one(item: tuple[int, rc.Case]) -> Row:
        i, case = item
        try:
            row = run_case(case, ws, work / "cases" / f"{i:03d}")
        except Exception as exc:  # noqa: BLE001 - a broken case must not stop the others
            row = Row(case.group, case.what, "", -1, f"{type(exc).__name__}: {exc}",
                      "harness error", 0.0)
        print(f"{i:3d} {row.verdict[:40]:<40} {case.what} ({row.seconds:.1f} s)", flush=True)
        return row

    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        rows = list(pool.map(one, enumerate(cases)))
    counts = {k: sum(r.verdict.split(":")[0] == k for r in rows)
              for k in VERDICTS}
    line = {"bench": "reliability", **common.stamp(int(env_threads)), "cases": len(rows),
            **counts, "seconds": round(time.perf_counter() - tick, 1),
            "failures": [f"{r.what}: {r.verdict}" for r in rows if r.verdict != "ok"]}
    print(json.dumps({k: v for k, v in line.items() if k != "machine"}, indent=1))
    if not args.only:
        common.append(args.out, line)
        args.doc.write_text(table(rows, line) + "\n")
        print(f"wrote {args.doc}")
    if args.keep is None:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
