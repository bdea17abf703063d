"""What a batch has done, kept in ``RUNS/batch.json`` so that the same command run again
picks up where the last one stopped.

Each job is ``pending``, ``running``, ``done`` or ``failed`` (with its one-line error). The
file is rewritten whole, to a temporary name and renamed, after every change: a batch killed
at any moment leaves the last complete state. A job found ``running`` when a batch starts was
interrupted (the batch was stopped or killed) and is run again; its fit resumes from its last
checkpoint.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

from hybridneus.errors import ConfigError

STATE_FILE = "batch.json"
STATUSES = ("pending", "running", "done", "failed")


class BatchState:
    """The jobs' records in one runs folder.

    Each record holds ``status`` and, as they become known, ``error``, ``run`` (the fit's run
    folder), ``mesh``, ``steps``, ``wall_s``, ``chamfer``, ``fscore``, ``attempts`` and
    ``finished`` (ISO time).
    """

    def __init__(self, runs: Path, jobs: dict[str, dict[str, Any]]) -> None:
        self.runs = runs
        self.jobs = jobs

    @classmethod
    def load(cls, runs: str | Path, ids: list[str]) -> BatchState:
        """The state in ``runs`` (a new one when there is none) with a record for each of
        ``ids``; records of jobs the manifest no longer lists are kept as they are."""
        runs = Path(runs)
        path = runs / STATE_FILE
        jobs: dict[str, dict[str, Any]] = {}
        if path.exists():
            try:
                doc = json.loads(path.read_text())
                jobs = doc["jobs"]
                if not isinstance(jobs, dict) or not all(
                        isinstance(r, dict) and r.get("status") in STATUSES
                        for r in jobs.values()):
                    raise ValueError("a job without a known status")
            except (OSError, ValueError, KeyError, TypeError) as exc:
                raise ConfigError(f"{path}: not a batch state file ({exc}); move it away to "
                                  "start the batch afresh") from None
        for i in ids:
            jobs.setdefault(i, {"status": "pending", "attempts": 0})
        return cls(runs, jobs)

    def todo(self, ids: list[str]) -> list[str]:
        """The jobs of ``ids`` left to run: all but the done ones, in order."""
        return [i for i in ids if self.jobs[i]["status"] != "done"]

    def update(self, job_id: str, **fields: Any) -> None:
        """Change a job's record and write the file."""
        record = self.jobs[job_id]
        record.update(fields)
        if fields.get("status") == "running":
            record["attempts"] = record.get("attempts", 0) + 1
            record.pop("error", None)
        if fields.get("status") in ("done", "failed"):
            record["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        self.save()

    def counts(self, ids: list[str]) -> dict[str, int]:
        out = dict.fromkeys(STATUSES, 0)
        for i in ids:
            out[self.jobs[i]["status"]] += 1
        return out

    def save(self) -> None:
        from hybridneus.fileio import atomic_path

        self.runs.mkdir(parents=True, exist_ok=True)
        with atomic_path(self.runs / STATE_FILE) as tmp:
            tmp.write_text(json.dumps({"jobs": self.jobs}, indent=1) + "\n")


__all__ = ["BatchState", "STATE_FILE", "STATUSES"]
