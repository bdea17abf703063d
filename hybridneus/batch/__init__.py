"""Many fits at once: a manifest of jobs run on this machine, on Ray or on Slurm, resumable.

- :func:`load_manifest` reads the YAML manifest into :class:`JobSpec` s;
- :func:`run_job` runs one job (convert, fit, mesh, eval) as a user would;
- :func:`run_batch` runs the jobs not done yet on an executor
  (:mod:`hybridneus.batch.executors`), keeping ``RUNS/batch.json`` and writing the summary.
"""

from hybridneus.batch.job import run_job
from hybridneus.batch.manifest import JobSpec, load_manifest
from hybridneus.batch.runner import default_workers, make_executor, run_batch

__all__ = ["JobSpec", "default_workers", "load_manifest", "make_executor", "run_batch",
           "run_job"]
