"""One batch job, run as a user would run it: ``convert`` (for a recording), ``fit``, ``mesh``
and ``eval``, each the ``hybridneus`` command in a process of its own, so that a crash or an
out-of-memory kill takes only its job and every error is the command's own one-line message.

A job's folder ``RUNS/<id>/`` holds ``data/`` (a converted recording), ``fit/`` (the fit's runs
folder, with the run's ``report.html`` written last), ``fit.json`` (the run folder and steps of
the fit once it ended), ``mesh.ply``, ``eval.json`` and ``errors.png``, and ``job.log`` (every
command and what it printed). Each step is skipped when its output is
already there, and an interrupted fit (a run folder with a checkpoint, no ``fit.json``) is
resumed with ``fit --resume``: running a job again finishes it rather than starting it over.
"""

from __future__ import annotations

import json
import logging
import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from hybridneus.batch.manifest import JobSpec
from hybridneus.errors import HybridNeusError
from hybridneus.fileio import atomic_path

#: The exit code of a command stopped by Ctrl-C (a fit saves a checkpoint first).
INTERRUPTED = 130


class JobFailed(HybridNeusError):
    """A step of a job failed; the message is one line naming the step."""


class JobInterrupted(HybridNeusError):
    """A step was stopped by an interrupt; the job can be run again to finish it."""


def fit_run(folder: Path) -> tuple[Path | None, dict | None]:
    """A job's fit run folder and, once the fit ended, ``fit.json`` (its ``run`` and
    ``steps``): the run ``fit.json`` names, else the newest run folder under ``fit/`` holding
    a checkpoint (to resume, with None), else ``(None, None)``."""
    from hybridneus.training.runs import CHECKPOINT

    path = folder / "fit.json"
    if path.is_file():
        ended = json.loads(path.read_text())
        if Path(ended["run"]).is_dir():
            return Path(ended["run"]), ended
    started = sorted((p for p in (folder / "fit").glob("*") if (p / CHECKPOINT).is_file()),
                     key=lambda p: p.stat().st_mtime)
    return (started[-1] if started else None), None


def run_job(spec: dict[str, Any] | JobSpec, runs: str | Path, threads: int = 0,
            started: Callable[[subprocess.Popen], None] | None = None,
            env: dict[str, str] | None = None) -> dict[str, Any]:
    """Run one job to its end and return its summary record: ``run``, ``steps``,
    ``wall_s`` (this attempt), ``mesh``, ``chamfer`` and ``fscore`` (when scored).

    Args:
        spec: the job (:class:`~hybridneus.batch.manifest.JobSpec` or its dict).
        runs: the batch's runs folder; the job works in ``runs/<id>``.
        threads: torch threads of the fit (0: torch's default).
        started: called with each command's process as it starts (to forward a stop).
        env: variables to set for the commands (e.g. ``CUDA_VISIBLE_DEVICES``).

    Raises:
        JobFailed: a step failed (the message names it and gives its error).
        JobInterrupted: a step was interrupted.
    """
    job = spec if isinstance(spec, JobSpec) else JobSpec(**{
        k: tuple(v) if isinstance(v, list) else v for k, v in spec.items()})
    t0 = time.perf_counter()
    folder = Path(runs) / job.id
    folder.mkdir(parents=True, exist_ok=True)
    log = folder / "job.log"

    def step(name: str, *args: str) -> str:
        return _command(name, list(args), log, threads, started, env)

    data = job.data
    if job.recording is not None:
        data = str(folder / "data")
        if not (folder / "data" / "scene.json").is_file():
            step("convert", job.recording, data, *job.convert, "-q")
    fit_root = folder / "fit"
    run, ended = fit_run(folder)
    if ended is None:
        if run is not None:
            out = step("fit", "--resume", str(run), "--device", job.device, "--quiet",
                       "--no-report")
        else:
            args = [str(data), "--preset", job.preset, "--out", str(fit_root), "--seed",
                    str(job.seed), "--device", job.device, "--quiet", "--no-report"]
            if job.iters is not None:
                args += ["--iters", str(job.iters)]
            if job.minutes is not None:
                args += ["--minutes", f"{job.minutes:g}"]
            for o in job.overrides:
                args += ["--set", o]
            if threads > 0:
                args += ["--set", f"train.threads={threads}"]
            out = step("fit", *args)
        found = re.search(r"^run: (.+) \(step (\d+)\)$", out, re.M)
        if found is None or not Path(found[1]).is_dir():
            raise JobFailed(f"fit: ended without naming its run (see {log})")
        run, ended = Path(found[1]), {"run": found[1], "steps": int(found[2])}
        with atomic_path(folder / "fit.json") as tmp:
            tmp.write_text(json.dumps(ended) + "\n")
    record: dict[str, Any] = {"run": str(run), "steps": ended["steps"]}
    if job.mesh is not None:
        mesh = folder / "mesh.ply"
        if not mesh.is_file():
            step("mesh", str(run), "--res", str(job.mesh["res"]),
                 "--color" if job.mesh["color"] else "--no-color", "--out", str(mesh),
                 "--device", job.device)
        record["mesh"] = str(mesh)
        if job.gt is not None:
            scores = folder / "eval.json"
            if not scores.is_file():
                text = step("eval", str(mesh), job.gt, "--json", "--errors",
                            str(folder / "errors.png"))
                with atomic_path(scores) as tmp:
                    tmp.write_text(text)
            result = json.loads(scores.read_text())
            record |= {"chamfer": result["chamfer"], "fscore": result["fscore"]}
    report, args = run / "report.html", [str(run)]
    if "mesh" in record:
        args += ["--mesh", record["mesh"]]
    if (folder / "eval.json").is_file():
        args += ["--eval", str(folder / "eval.json")]
    if job.report and not _newer(report, [run / "metrics.csv", *map(Path, args[2::2])]):
        try:
            step("report", *args)
        except JobFailed as exc:  # a page not written takes nothing from the job's results
            with open(log, "a") as f:
                f.write(f"warning: {exc}\n")
            logging.getLogger("hybridneus").warning("%s: %s", job.id, exc)
    if report.is_file():
        record["report"] = str(report)
    record["wall_s"] = round(time.perf_counter() - t0, 1)
    return record


def _newer(path: Path, sources: list[Path]) -> bool:
    """Whether ``path`` exists and is newer than each of ``sources`` that exists."""
    if not path.is_file():
        return False
    made = path.stat().st_mtime
    return all(made >= p.stat().st_mtime for p in sources if p.is_file())


def _command(name: str, args: list[str], log: Path, threads: int,
             started: Callable[[subprocess.Popen], None] | None,
             extra: dict[str, str] | None = None) -> str:
    """Run ``hybridneus NAME ARGS`` (:func:`run_command`) with ``threads`` threads."""
    env = dict(extra or {})
    if threads > 0:
        env |= {"OMP_NUM_THREADS": str(threads), "MKL_NUM_THREADS": str(threads)}
    return run_command([sys.executable, "-m", "hybridneus.cli.app", name, *args], name, log,
                       started, env, shown=f"hybridneus {name} {' '.join(args)}")


def run_command(cmd: list[str], name: str, log: Path,
                started: Callable[[subprocess.Popen], None] | None = None,
                env: dict[str, str] | None = None, shown: str | None = None) -> str:
    """Run ``cmd`` in its own process, it and its output appended to ``log``; return its
    stdout. An interrupt while it runs is passed on to it (a fit saves a checkpoint).

    Raises:
        JobInterrupted: it ended on an interrupt.
        JobFailed: it failed: ``"<name>: <its last error line>"``.
    """
    with open(log, "a") as f:
        f.write(f"$ {shown or ' '.join(cmd)}\n")
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=dict(os.environ) | (env or {}))
    if started is not None:
        started(proc)
    try:
        out, err = proc.communicate()
    except BaseException:
        proc.send_signal(signal.SIGINT)  # a fit saves a checkpoint on an interrupt
        proc.wait()
        raise
    with open(log, "a") as f:
        f.write(out + err + f"[exit {proc.returncode}]\n")
    if proc.returncode in (INTERRUPTED, -signal.SIGINT):
        raise JobInterrupted(f"{name}: interrupted")
    if proc.returncode != 0:
        lines = [ln for ln in err.splitlines() if ln.strip()]
        message = next((ln for ln in reversed(lines) if ln.startswith("error:")),
                       lines[-1] if lines else f"exit code {proc.returncode}")
        if proc.returncode < 0:
            message = f"killed by signal {-proc.returncode}"
        raise JobFailed(f"{name}: {message.removeprefix('error: ')}")
    return out


__all__ = ["JobFailed", "JobInterrupted", "fit_run", "run_command", "run_job"]
