"""``hybridneus batch``: the fits of a manifest, on this machine, on Ray or on Slurm."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer


def batch(
    manifest: Annotated[Path, typer.Argument(help="The batch's YAML manifest (docs/batch.md).",
                                             show_default=False)],
    out: Annotated[Path, typer.Option("--out", help="Runs folder: one folder per job, the "
                                      "state file, the summary.", show_default=False)],
    executor: Annotated[str, typer.Option(help="local, ray or slurm.")] = "local",
    workers: Annotated[
        int | None,
        typer.Option(help="local: jobs at a time (default: one per GPU, else one per two "
                     "cores).", show_default=False),
    ] = None,
    threads: Annotated[
        int | None,
        typer.Option(help="torch threads of each fit (default: the cores shared among the "
                     "workers on a CPU; torch's own on a GPU).", show_default=False),
    ] = None,
    address: Annotated[
        str | None,
        typer.Option(help="ray: a running cluster (auto, or ray://HOST:10001); default: a "
                     "local Ray.", show_default=False),
    ] = None,
    cpus_per_task: Annotated[
        int | None, typer.Option(help="ray, slurm: cores asked for each job (default: "
                                 "--threads).", show_default=False)
    ] = None,
    gpus_per_task: Annotated[int, typer.Option(help="ray, slurm: GPUs asked for each job.")]
    = 0,
    partition: Annotated[
        str | None, typer.Option(help="slurm: the partition.", show_default=False)
    ] = None,
    time_limit: Annotated[
        int, typer.Option("--time", help="slurm: minutes a job may run before it is "
                          "checkpointed and requeued.")
    ] = 60,
    cluster: Annotated[
        str, typer.Option(help="slurm: slurm, or local to run the same code path in "
                          "processes here (submitit's LocalExecutor), to try a manifest.")
    ] = "slurm",
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar.")] = False,
) -> None:
    """Run every job of MANIFEST that OUT does not list as done; a rerun of the same command
    finishes what an earlier one left (interrupted fits resume).

    Writes OUT/batch.json (each job's state), OUT/<job>/ and OUT/summary.csv and .md. Exits
    with 1 when a job failed (the others still run), 130 after Ctrl-C.
    """
    import os

    from hybridneus.batch import default_workers, load_manifest, make_executor, run_batch
    from hybridneus.batch.executors import EXECUTORS
    from hybridneus.batch.runner import gpu_count
    from hybridneus.cli.options import log_to_stderr
    from hybridneus.errors import ConfigError
    from hybridneus.fileio import check_output

    if executor not in EXECUTORS:
        raise ConfigError(f"--executor {executor}: expected one of {', '.join(EXECUTORS)}")
    if cluster not in ("slurm", "local"):
        raise ConfigError(f"--cluster {cluster}: expected slurm or local")
    jobs = load_manifest(manifest)
    check_output(out, folder=True)
    workers = default_workers() if workers is None else workers
    if workers < 1:
        raise ConfigError(f"--workers {workers}: must be >= 1")
    if threads is None:
        on_gpu = gpus_per_task or (executor == "local" and gpu_count())
        threads = 0 if on_gpu else max(1, (os.cpu_count() or 1) // workers)
    if threads < 0:
        raise ConfigError(f"--threads {threads}: must be >= 0")
    cpus = cpus_per_task or max(threads, 1)
    slurm = {"timeout_min": time_limit, "cpus_per_task": cpus, "tasks_per_node": 1,
             "nodes": 1}
    if cluster == "slurm":
        slurm |= {"slurm_partition": partition} if partition else {}
        slurm |= {"slurm_gpus_per_task": gpus_per_task} if gpus_per_task else {}
    options = {"num_cpus": cpus, "num_gpus": gpus_per_task, "address": address,
               "slurm": slurm, "cluster": "local" if cluster == "local" else None}
    if not quiet:
        log_to_stderr()
    engine = make_executor(executor, out, workers, threads, options)
    try:
        table = run_batch(jobs, out, engine, progress=not quiet)
    except KeyboardInterrupt:
        typer.echo(f"interrupted; the state is in {out / 'batch.json'}: run the same command "
                   "again to finish", err=True)
        sys.exit(130)
    failed = [r for r in table if r["status"] == "failed"]
    _print(table)
    typer.echo(f"summary: {out / 'summary.csv'} and {out / 'summary.md'}")
    if failed:
        typer.echo(f"{len(failed)} of {len(table)} jobs failed (their errors are in the "
                   "summary); fix them and run the same command again", err=True)
        sys.exit(1)


def _print(table: list[dict]) -> None:
    from rich.console import Console
    from rich.table import Table

    from hybridneus.batch.summary import COLUMNS, cell

    shown = Table()
    for c in COLUMNS:
        shown.add_column(c, overflow="fold")
    for row in table:
        shown.add_row(*(cell(row[c]) for c in COLUMNS))
    Console(width=160).print(shown)
