"""Where a batch's jobs run: a process per job on this machine, Ray tasks, or Slurm jobs
through submitit. Each executor calls :func:`~hybridneus.batch.job.run_job` for every job and
reports as jobs end, in the order they end.

Each runs a *task* per job: by default :func:`outcome` of :func:`~hybridneus.batch.job.run_job`;
any function of the same signature (``task(spec, runs, threads, started, env)`` returning
``(event, value)``) may stand in, as :func:`outcome` of the accuracy suite's own fit-and-score
job does.

``run(jobs, report)`` blocks until every job has ended, calling ``report(job_id, event,
value)`` with event ``"running"`` (value None), ``"done"`` (the job's record), ``"failed"``
(the one-line error) or ``"interrupted"`` (the batch was stopped: the job is left to the next
run). A ``KeyboardInterrupt`` stops what runs (a fit saves a checkpoint), starts nothing new,
and is raised again once every running job has reported.
"""

from __future__ import annotations

import signal
import threading
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ThreadPoolExecutor, wait
from pathlib import Path
from typing import Any

from hybridneus.batch.job import JobFailed, JobInterrupted, run_job
from hybridneus.batch.manifest import JobSpec
from hybridneus.errors import ConfigError

Report = Callable[[str, str, Any], None]
Task = Callable[..., tuple[str, Any]]
EXECUTORS = ("local", "ray", "slurm")


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return (text.splitlines()[0] if text else type(exc).__name__)[:300]


def outcome(spec: dict, runs: str, threads: int, started: Callable | None = None,
            env: dict[str, str] | None = None, job: Callable = run_job) -> tuple[str, Any]:
    """``("done", record)``, ``("failed", error)`` or ``("interrupted", None)`` of one job:
    what a remote worker sends back (exceptions do not cross every engine intact). ``job``:
    the function that runs it (:func:`~hybridneus.batch.job.run_job`'s signature)."""
    try:
        return "done", job(spec, runs, threads, started, env)
    except JobInterrupted:
        return "interrupted", None
    except JobFailed as exc:
        return "failed", str(exc)
    except KeyboardInterrupt:
        return "interrupted", None
    except Exception as exc:  # a worker must report, whatever broke
        return "failed", f"{type(exc).__name__}: {_first_line(exc)}"


#: Seconds a stopped batch waits before it passes the stop on to commands still running.
GRACE_S = 10.0


def _pass_on(live: set, lock: threading.Lock) -> None:
    with lock:
        for proc in live:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)


class LocalExecutor:
    """``workers`` jobs at a time on this machine, each command in a process of its own; on a
    machine with ``gpus`` GPUs each running job sees one of its own (``CUDA_VISIBLE_DEVICES``),
    when there are as many workers as GPUs or fewer."""

    def __init__(self, runs: Path, workers: int, threads: int, gpus: int = 0,
                 task: Task | None = None) -> None:
        self.runs, self.workers, self.threads = runs, workers, threads
        self.gpus = gpus if 0 < workers <= gpus else 0
        self.task = task

    def run(self, jobs: list[JobSpec], report: Report) -> None:
        stop = threading.Event()
        live: set = set()
        lock = threading.Lock()

        def started(proc) -> None:
            with lock:
                live.add(proc)
            if stop.is_set():
                proc.send_signal(signal.SIGINT)

        free = list(range(self.gpus))

        def work(job: JobSpec) -> tuple[str, Any]:
            if stop.is_set():
                return "interrupted", None
            report(job.id, "running", None)
            with lock:
                gpu = free.pop() if free else None
            env = None if gpu is None else {"CUDA_VISIBLE_DEVICES": str(gpu)}
            try:
                return (self.task or outcome)(job.to_dict(), str(self.runs), self.threads,
                                              started, env)
            finally:
                if gpu is not None:
                    with lock:
                        free.append(gpu)

        pool = ThreadPoolExecutor(max_workers=self.workers)
        futures: dict[Future, str] = {pool.submit(work, job): job.id for job in jobs}
        pending = set(futures)
        interrupted = False
        try:
            while pending:
                try:
                    done, pending = wait(pending, timeout=0.5, return_when=FIRST_COMPLETED)
                except KeyboardInterrupt:
                    if not interrupted:
                        interrupted = True
                        stop.set()
                        # a Ctrl-C at the terminal reached the commands too; a stop sent to
                        # the batch alone is passed on to what still runs after a grace
                        timer = threading.Timer(GRACE_S, _pass_on, (live, lock))
                        timer.daemon = True
                        timer.start()
                    continue
                for f in done:
                    report(futures[f], *f.result())
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
        if interrupted:
            raise KeyboardInterrupt


class RayExecutor:
    """Ray tasks, each asking for ``num_cpus`` and ``num_gpus``; ``ray.init()`` starts a
    local Ray unless ``address`` names a running cluster (``auto`` or ``ray://host:10001``)."""

    def __init__(self, runs: Path, threads: int, num_cpus: float, num_gpus: float,
                 address: str | None, task: Task | None = None) -> None:
        self.runs, self.threads = runs, threads
        self.num_cpus, self.num_gpus, self.address = num_cpus, num_gpus, address
        self.task = task

    def run(self, jobs: list[JobSpec], report: Report) -> None:
        ray = _need("ray", "ray")
        if not ray.is_initialized():
            ray.init(address=self.address, include_dashboard=False, log_to_driver=False,
                     configure_logging=False)
        task = ray.remote(num_cpus=self.num_cpus, num_gpus=self.num_gpus,
                          max_retries=0)(self.task or outcome)
        refs = {}
        for job in jobs:
            refs[task.remote(job.to_dict(), str(self.runs), self.threads)] = job.id
            report(job.id, "running", None)
        interrupted = False
        while refs:
            try:
                ready, _ = ray.wait(list(refs), num_returns=1, timeout=0.5)
            except KeyboardInterrupt:
                interrupted = True
                for ref in refs:
                    ray.cancel(ref)  # a KeyboardInterrupt in the task: the fit checkpoints
                continue
            for ref in ready:
                job_id = refs.pop(ref)
                try:
                    report(job_id, *ray.get(ref))
                except ray.exceptions.TaskCancelledError:
                    report(job_id, "interrupted", None)
                except Exception as exc:  # the worker died (memory, a signal)
                    report(job_id, "failed", f"ray: {_first_line(exc)}")
        if interrupted:
            raise KeyboardInterrupt


class SubmititJob:
    """A job as submitit runs it on a Slurm node. Where Slurm's time limit comes before the
    job's end, submitit calls :meth:`checkpoint`: the running command is interrupted (a fit
    saves a checkpoint) and the job is requeued, to resume where it stopped."""

    def __init__(self, task: Task | None = None) -> None:
        self._proc = None
        self.task = task

    def __call__(self, spec: dict, runs: str, threads: int) -> tuple[str, Any]:
        def started(proc) -> None:
            self._proc = proc

        return (self.task or outcome)(spec, runs, threads, started)

    def checkpoint(self, spec: dict, runs: str, threads: int):
        import submitit

        proc, self._proc = self._proc, None
        if proc is not None and proc.poll() is None:
            proc.send_signal(signal.SIGINT)
            proc.wait()
        return submitit.helpers.DelayedSubmission(SubmititJob(self.task), spec, runs, threads)


class SlurmExecutor:
    """submitit: one Slurm array of one task per job (``cluster="local"`` runs the same code
    path in processes on this machine, as submitit's ``LocalExecutor``)."""

    def __init__(self, runs: Path, threads: int, parameters: dict[str, Any],
                 cluster: str | None = None, task: Task | None = None) -> None:
        self.runs, self.threads = runs, threads
        self.parameters, self.cluster = parameters, cluster
        self.task = task

    def run(self, jobs: list[JobSpec], report: Report) -> None:
        submitit = _need("submitit", "slurm")
        executor = submitit.AutoExecutor(folder=self.runs / ".submitit", cluster=self.cluster)
        executor.update_parameters(**self.parameters)
        with executor.batch():
            handles = [executor.submit(SubmititJob(self.task), job.to_dict(), str(self.runs),
                                       self.threads) for job in jobs]
        waiting = dict(zip(handles, (j.id for j in jobs), strict=True))
        for job in jobs:
            report(job.id, "running", None)
        import time

        interrupted = False
        while waiting:
            try:
                time.sleep(0.5)
                ended = [h for h in waiting if h.done()]
            except KeyboardInterrupt:
                interrupted = True
                for h in waiting:
                    h.cancel(check=False)  # Slurm signals the job; its fit checkpoints
                break
            for h in ended:
                job_id = waiting.pop(h)
                try:
                    report(job_id, *h.result())
                except Exception as exc:  # the job died on its node
                    report(job_id, "failed", f"slurm: {_first_line(exc)}")
        if interrupted:
            for job_id in waiting.values():
                report(job_id, "interrupted", None)
            raise KeyboardInterrupt


def _need(module: str, extra: str):
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        raise ConfigError(f"--executor {extra}: needs the {module} package: pip install -e "
                          f"\".[{extra}]\" in the hybridneus folder") from None


__all__ = ["EXECUTORS", "LocalExecutor", "RayExecutor", "SlurmExecutor", "SubmititJob",
           "outcome"]
