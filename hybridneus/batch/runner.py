"""A whole batch: the manifest's jobs that are not done yet, on an executor, with the state
file kept current, a progress bar, and the summary and index page written at the end (also
after a Ctrl-C).
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hybridneus.batch.executors import EXECUTORS
from hybridneus.batch.state import BatchState
from hybridneus.batch.summary import COLUMNS, rows, write_summary
from hybridneus.errors import ConfigError
from hybridneus.report.index import write_index

if TYPE_CHECKING:
    from hybridneus.batch.executors import LocalExecutor, RayExecutor, SlurmExecutor

    Executor = LocalExecutor | RayExecutor | SlurmExecutor


def gpu_count() -> int:
    """The CUDA GPUs torch sees here (0 without CUDA)."""
    try:
        import torch
    except ImportError:
        return 0
    return torch.cuda.device_count() if torch.cuda.is_available() else 0


def default_workers() -> int:
    """One fit per GPU on a CUDA machine, else one per two cores."""
    return gpu_count() or max(1, (os.cpu_count() or 2) // 2)


def make_executor(name: str, runs: Path, workers: int, threads: int, options: dict[str, Any],
                  task=None):
    """The executor called ``name`` (one of :data:`~hybridneus.batch.executors.EXECUTORS`),
    running ``task`` for each job (default: :func:`~hybridneus.batch.executors.outcome`)."""
    from hybridneus.batch import executors

    if name == "local":
        return executors.LocalExecutor(runs, workers, threads, gpu_count(), task)
    if name == "ray":
        return executors.RayExecutor(runs, threads, options.get("num_cpus", max(threads, 1)),
                                     options.get("num_gpus", 0), options.get("address"), task)
    if name == "slurm":
        return executors.SlurmExecutor(runs, threads, options.get("slurm", {}),
                                       options.get("cluster"), task)
    raise ConfigError(f"--executor {name}: expected one of {', '.join(EXECUTORS)}")


def run_batch(jobs: list, runs: str | Path, executor: Executor, progress: bool = True,
              on_done: Callable[[str, dict[str, Any]], None] | None = None
              ) -> list[dict[str, Any]]:
    """Run the jobs of ``jobs`` that ``runs``' state does not list as done; return the
    summary's rows (every job of ``jobs``).

    Args:
        jobs: :class:`~hybridneus.batch.manifest.JobSpec` s, or any objects with an ``id``
            and a ``to_dict()`` that the executor's task takes.
        runs: the batch's folder (state, summary, the jobs' folders).
        executor: from :func:`make_executor`.
        progress: show the batch's progress bar.
        on_done: called with ``(job_id, record)`` as each job ends done.

    Raises:
        KeyboardInterrupt: after a Ctrl-C, once the running jobs have stopped and the state
            and summary are written.
    """
    from hybridneus.progress import make_progress

    runs = Path(runs)
    ids = [j.id for j in jobs]
    state = BatchState.load(runs, ids)
    todo = set(state.todo(ids))
    for i in todo:
        if state.jobs[i]["status"] == "running":  # a batch stopped or killed while it ran
            state.jobs[i]["status"] = "pending"
    state.save()
    log = logging.getLogger("hybridneus")
    skipped = len(ids) - len(todo)
    if skipped:
        log.info("%s: %d of %d jobs already done", runs, skipped, len(ids))
    lock = threading.Lock()
    times: dict[str, float] = {}
    with make_progress("jobs", disable=not progress) as bar:
        task = bar.add_task("batch", total=len(ids), completed=skipped)

        def show() -> None:
            c = state.counts(ids)
            bar.update(task, completed=c["done"] + c["failed"],
                       info=f"{c['running']} running, {c['done']} done, {c['failed']} failed")

        def report(job_id: str, event: str, value: Any) -> None:
            with lock:
                if event == "running":
                    times[job_id] = time.perf_counter()
                    state.update(job_id, status="running")
                elif event == "done":
                    state.update(job_id, status="done", **value)
                    if on_done is not None:
                        on_done(job_id, value)
                elif event == "failed":
                    state.update(job_id, status="failed", error=value)
                    log.warning("%s: failed: %s", job_id, value)
                else:
                    state.update(job_id, status="pending")
                show()

        show()
        try:
            if todo:
                executor.run([j for j in jobs if j.id in todo], report)
        finally:
            table = rows(ids, state.jobs)
            write_summary(runs, table)
            write_index(runs, table, COLUMNS)
    return table


__all__ = ["default_workers", "gpu_count", "make_executor", "run_batch"]
