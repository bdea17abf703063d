"""``hybridneus batch``: a manifest's fits on the local, Ray and Slurm (submitit) executors,
failures kept to their job, and a batch stopped or killed mid-way finished by a rerun."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from conftest import TINY_FIT

from hybridneus.errors import ConfigError

#: The tiny fits' settings, without their step count (the manifest states it).
SETTINGS = [s for s in TINY_FIT if not s.startswith("train.iters")]


@pytest.fixture(scope="module")
def scans(tmp_path_factory) -> Path:
    """A folder holding a tiny simulated scan ``device/`` (with its ``gt_mesh.ply``)."""
    from hybridneus.simulate import SimulationConfig, simulate_dataset

    root = tmp_path_factory.mktemp("scans")
    cfg = SimulationConfig(n_views=8, width=24, height=18, val_views=0, test_views=0,
                           revolutions=1.0, supersample=1)
    simulate_dataset("builtin:device", root / "device", cfg, progress=False)
    return root


def _manifest(folder: Path, jobs: list[dict], iters: int = 2, mesh=None,
              report: bool = False) -> Path:
    """The tiny fits' manifest; only the tests that look at the pages have them written."""
    doc = {"defaults": {"iters": iters, "set": SETTINGS, "report": report,
                        "mesh": mesh if mesh is not None else {"res": 16, "color": False}},
           "jobs": jobs}
    path = folder / "manifest.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def _fits(job_folder: Path) -> list[str]:
    """The fit commands a job ran, from its log."""
    return [ln for ln in (job_folder / "job.log").read_text().splitlines()
            if ln.startswith("$ hybridneus fit")]


def _batch(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "hybridneus.cli.app", "batch", *args, "-q"],
                          capture_output=True, text=True, **kw)


def test_a_manifest_states_defaults_once_and_expands_seeds(tmp_path):
    from hybridneus.batch import load_manifest

    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump({
        "defaults": {"preset": "fast", "minutes": 15, "set": ["train.lr=0.01"],
                     "mesh": {"res": 200}},
        "jobs": [{"name": "mug", "data": "scans/mug", "gt": "scans/mug.ply"},
                 {"name": "cup", "recording": "/rec/cup.aedat4", "seeds": [0, 1],
                  "convert": ["--poses", "cup.csv"], "mesh": False, "report": False}]}))
    jobs = load_manifest(path)
    assert [j.id for j in jobs] == ["mug", "cup-s0", "cup-s1"]
    mug, cup = jobs[0], jobs[2]
    assert mug.data == str(tmp_path / "scans/mug") and mug.gt == str(tmp_path / "scans/mug.ply")
    assert mug.minutes == 15 and mug.iters is None and mug.overrides == ("train.lr=0.01",)
    assert mug.mesh == {"res": 200, "color": True}
    assert cup.recording == "/rec/cup.aedat4" and cup.data is None and cup.seed == 1
    assert cup.mesh is None and cup.convert == ("--poses", "cup.csv")
    assert mug.report and not cup.report


@pytest.mark.parametrize("doc, message", [
    ({"jobs": []}, "non-empty 'jobs' list"),
    ({"jobs": [{"name": "a"}]}, "job 'a': give one of 'data'"),
    ({"jobs": [{"name": "a", "data": "d", "colour": 1}]}, "job 'a': unknown key 'colour'"),
    ({"jobs": [{"name": "a", "data": "d"}, {"name": "a", "data": "e"}]}, "two jobs are named"),
    ({"defaults": {"gt": "x"}, "jobs": [{"name": "a", "data": "d"}]},
     "defaults: unknown key 'gt'"),
    ({"jobs": [{"name": "a", "data": "d", "iters": -3}]}, "'iters' must be a positive"),
    ({"jobs": [{"name": "a/b", "data": "d"}]}, "'name' must be a plain folder name"),
    ({"jobs": [{"name": "a", "data": "d", "report": "no"}]}, "'report' must be true or false"),
])
def test_a_bad_manifest_is_one_line_naming_the_file(tmp_path, doc, message):
    from hybridneus.batch import load_manifest

    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(ConfigError, match=message) as info:
        load_manifest(path)
    assert str(info.value).startswith(str(path)) and "\n" not in str(info.value)
    with pytest.raises(ConfigError, match="no such manifest"):
        load_manifest(tmp_path / "missing.yaml")


def test_a_failed_job_leaves_the_others_and_a_rerun_does_only_it(scans, tmp_path):
    manifest = _manifest(tmp_path, [
        {"name": "good", "data": str(scans / "device"), "gt": str(scans / "device/gt_mesh.ply")},
        {"name": "late", "data": str(tmp_path / "late")}], report=True)
    runs = tmp_path / "runs"
    proc = _batch(str(manifest), "--out", str(runs), "--workers", "2", "--threads", "1")
    assert proc.returncode == 1, proc.stderr
    assert "1 of 2 jobs failed" in proc.stderr
    state = json.loads((runs / "batch.json").read_text())["jobs"]
    assert state["good"]["status"] == "done" and state["good"]["steps"] == 2
    assert state["good"]["chamfer"] > 0 and 0 <= state["good"]["fscore"] <= 1
    assert Path(state["good"]["mesh"]).is_file()
    assert state["late"]["status"] == "failed"
    assert state["late"]["error"] == f"fit: {tmp_path / 'late'}: dataset folder does not exist"
    summary = (runs / "summary.csv").read_text().splitlines()
    assert summary[0].startswith("job,status,steps,wall_s,chamfer,fscore,mesh,report,error")
    assert summary[2].startswith("late,failed,") and "does not exist" in summary[2]
    assert "| good | done | 2 |" in (runs / "summary.md").read_text()
    # each job's report (with its mesh and scores), linked from the batch's index page
    report = Path(state["good"]["report"])
    assert report.is_file() and "mesh-view" in report.read_text()
    assert "Scores against the ground truth" in report.read_text()
    index = (runs / "index.html").read_text()
    assert f"href='{report.relative_to(runs)}'>good</a>" in index
    assert "does not exist" in index and "1 done, 1 failed" in index
    # the data turns up: the same command runs the failed job only
    shutil.copytree(scans / "device", tmp_path / "late")
    proc = _batch(str(manifest), "--out", str(runs), "--workers", "2", "--threads", "1")
    assert proc.returncode == 0, proc.stderr
    state = json.loads((runs / "batch.json").read_text())["jobs"]
    assert state["late"]["status"] == "done" and "error" not in state["late"]
    assert state["late"]["attempts"] == 2 and state["good"]["attempts"] == 1
    assert len(_fits(runs / "good")) == 1 and len(_fits(runs / "late")) == 2


@pytest.mark.parametrize("engine", ["ray", "slurm"])
def test_ray_and_submitit_run_the_same_jobs(scans, tmp_path, engine):
    pytest.importorskip({"ray": "ray", "slurm": "submitit"}[engine])
    manifest = _manifest(tmp_path, [
        {"name": "a", "data": str(scans / "device"), "gt": str(scans / "device/gt_mesh.ply")},
        {"name": "b", "data": str(tmp_path / "missing")}])
    runs = tmp_path / "runs"
    extra = ["--cluster", "local"] if engine == "slurm" else []
    proc = _batch(str(manifest), "--out", str(runs), "--executor", engine, "--threads", "1",
                  *extra, timeout=600)
    assert proc.returncode == 1, proc.stderr
    state = json.loads((runs / "batch.json").read_text())["jobs"]
    assert state["a"]["status"] == "done" and state["a"]["chamfer"] > 0
    assert state["b"]["status"] == "failed" and "dataset folder does not exist" in \
        state["b"]["error"]


def _wait_for(runs: Path, ready, timeout: float = 300.0) -> dict:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            jobs = json.loads((runs / "batch.json").read_text())["jobs"]
        except (OSError, ValueError, KeyError):
            jobs = {}
        if jobs and ready(jobs):
            return jobs
        time.sleep(0.2)
    raise AssertionError(f"{runs}: the batch did not get there in {timeout} s")


@pytest.mark.parametrize("stop", [signal.SIGKILL, signal.SIGINT])
def test_a_batch_stopped_mid_way_is_finished_by_a_rerun_each_job_once(scans, tmp_path, stop):
    names = ["a", "b", "c"]
    manifest = _manifest(tmp_path, [{"name": n, "data": str(scans / "device")} for n in names],
                         iters=40, mesh=False)
    runs = tmp_path / "runs"
    cmd = [sys.executable, "-m", "hybridneus.cli.app", "batch", str(manifest), "--out",
           str(runs), "--workers", "1", "--threads", "1", "-q"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    # stop it while one job is done and the next has written its first checkpoint
    _wait_for(runs, lambda j: j["a"]["status"] == "done" and j["b"]["status"] == "running"
              and any((runs / "b" / "fit").glob("*/checkpoints/last.pt")))
    os.killpg(proc.pid, stop)
    _, err = proc.communicate(timeout=120)
    if stop == signal.SIGINT:
        assert proc.returncode == 130 and "run the same command again" in err
        state = json.loads((runs / "batch.json").read_text())["jobs"]
        assert state["b"]["status"] == "pending", state
    proc = _batch(str(manifest), "--out", str(runs), "--workers", "1", "--threads", "1")
    assert proc.returncode == 0, proc.stderr
    state = json.loads((runs / "batch.json").read_text())["jobs"]
    assert all(state[n]["status"] == "done" and state[n]["steps"] == 40 for n in names), state
    assert state["a"]["attempts"] == 1 and len(_fits(runs / "a")) == 1
    assert state["c"]["attempts"] == 1
    # b went on from its checkpoint, in the run folder it had started
    assert state["b"]["attempts"] == 2 and "--resume" in _fits(runs / "b")[-1]
    assert len([p for p in (runs / "b" / "fit").iterdir() if p.is_dir()]) == 1
    # report: false (the manifest's) wrote no page
    assert "report" not in state["a"] and not list((runs / "a" / "fit").glob("*/report.html"))


def test_a_missing_engine_names_its_extra(scans, tmp_path, monkeypatch):
    from hybridneus.batch import load_manifest, make_executor, run_batch

    monkeypatch.setitem(sys.modules, "submitit", None)
    jobs = load_manifest(_manifest(tmp_path, [{"name": "a", "data": str(scans / "device")}]))
    engine = make_executor("slurm", tmp_path / "runs", 1, 1, {})
    with pytest.raises(ConfigError, match=r"needs the submitit package: pip install -e "
                                          r"\"\.\[slurm\]\""):
        run_batch(jobs, tmp_path / "runs", engine, progress=False)
    with pytest.raises(ConfigError, match="--executor dask: expected one of local, ray, slurm"):
        make_executor("dask", tmp_path / "runs", 1, 1, {})


def test_a_slurm_time_limit_checkpoints_the_fit_and_the_requeued_job_resumes(scans, tmp_path):
    pytest.importorskip("submitit")
    from hybridneus.batch import load_manifest
    from hybridneus.batch.executors import SubmititJob

    (job,) = load_manifest(_manifest(tmp_path, [{"name": "a", "data": str(scans / "device")}],
                                     iters=400, mesh=False))
    runs = tmp_path / "runs"
    task = SubmititJob()
    procs = []

    def started(proc) -> None:  # what submitit's signal handler finds running
        procs.append(proc)
        task._proc = proc
        _wait_for_file(runs / "a" / "fit", "*/checkpoints/last.pt")
        time.sleep(1.0)
        requeued.append(task.checkpoint(job.to_dict(), str(runs), 1))

    requeued: list = []
    from hybridneus.batch.executors import outcome

    status, _ = outcome(job.to_dict(), str(runs), 1, started)
    assert status == "interrupted" and procs[0].returncode == 130
    assert len(requeued) == 1 and requeued[0].function.__class__ is SubmititJob
    status, record = requeued[0].function(*requeued[0].args)
    assert status == "done" and record["steps"] == 400
    assert "--resume" in _fits(runs / "a")[-1]


def _wait_for_file(folder: Path, pattern: str, timeout: float = 300.0) -> None:
    end = time.monotonic() + timeout
    while not any(folder.glob(pattern)):
        if time.monotonic() > end:
            raise AssertionError(f"{folder}: no {pattern} in {timeout} s")
        time.sleep(0.2)


def test_each_running_job_gets_a_gpu_of_its_own(monkeypatch, tmp_path):
    import threading

    import hybridneus.batch.executors as executors
    from hybridneus.batch.manifest import JobSpec

    holding: dict[str, str] = {}
    clash = []
    lock = threading.Lock()

    def job(spec, runs, threads, started=None, env=None):
        gpu = env["CUDA_VISIBLE_DEVICES"]
        with lock:
            clash.extend(g for g in holding.values() if g == gpu)
            holding[spec["id"]] = gpu
        time.sleep(0.1)
        with lock:
            del holding[spec["id"]]
        return "done", {"gpu": gpu}

    monkeypatch.setattr(executors, "outcome", job)
    ended = {}
    executors.LocalExecutor(tmp_path, 2, 1, gpus=2).run(
        [JobSpec(id=f"j{i}", data="d") for i in range(6)],
        lambda i, event, value: ended.setdefault(i, value) if event == "done" else None)
    assert not clash and len(ended) == 6
    assert {v["gpu"] for v in ended.values()} == {"0", "1"}
    # more workers than GPUs: the GPUs are left to the fits' own choice
    assert executors.LocalExecutor(tmp_path, 3, 1, gpus=2).gpus == 0
