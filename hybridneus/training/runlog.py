"""What a training run writes: config, scene record, checkpoints, metrics.csv, TensorBoard,
previews."""

from __future__ import annotations

import csv
import io
import os
import time
from pathlib import Path
from typing import Any

from hybridneus.config import save_config
from hybridneus.fileio import atomic_path
from hybridneus.training import runs

#: The training poses of a run that smoothed its track (see :meth:`RunLogger.save_poses`).
POSES = "poses_refined.npz"
#: Views whose windows the end of a fit renders for its report (``previews/view_<i>.png``).
VIEWS = 4
_FIXED = ["step", "elapsed_s", "loss/total", "loss/event", "loss/eikonal"]


class RunLogger:
    """Writes one run folder (see :mod:`hybridneus.training.runs` for the layout).

    Args:
        run_dir: the run folder (created by :func:`runs.new_run_dir`).
        runs_root: folder holding the ``latest`` pointer.
        resume_step: when resuming, rows of ``metrics.csv`` after this step are dropped.
    """

    def __init__(self, run_dir: Path, runs_root: Path | None, resume_step: int = 0) -> None:
        self.run_dir = Path(run_dir)
        self.runs_root = Path(runs_root) if runs_root is not None else None
        self.metrics_path = self.run_dir / "metrics.csv"
        self._saved_at = time.perf_counter()
        self.history: list[dict[str, float]] = []
        self.columns: list[str] | None = None
        self._load_metrics(resume_step)
        self.tb = _tensorboard_writer(self.run_dir / "tb")

    def _load_metrics(self, resume_step: int) -> None:
        if not self.metrics_path.is_file():
            return
        text = self.metrics_path.read_bytes().decode("utf-8", errors="replace")
        rows = list(csv.DictReader(io.StringIO(text.replace("\x00", ""))))  # NULs: a crash
        for row in rows:
            # a row a killed write cut short or ran into the next is dropped: cells missing
            # (None) or too many (a list under the key None)
            if None in row or any(v is None for v in row.values()):
                continue
            try:
                values = {k: float(v) for k, v in row.items() if v != ""}
            except ValueError:
                continue
            if values.get("step", 0) <= resume_step:
                self.history.append(values)
        if rows:
            self.columns = [k for k in rows[0] if k is not None]
        self._rewrite_metrics()

    def _rewrite_metrics(self) -> None:
        if self.columns is None:
            return
        buf = io.StringIO()
        writer = csv.DictWriter(buf, fieldnames=self.columns, extrasaction="ignore")
        writer.writeheader()
        for row in self.history:
            writer.writerow({k: _fmt(row.get(k)) for k in self.columns})
        with atomic_path(self.metrics_path) as tmp:
            tmp.write_text(buf.getvalue())

    def start(self, trainer) -> None:
        """Write ``config.yaml`` and ``scene.yaml``, and remove what killed saves left.
        ``latest`` moves to this run when it finishes, so a failed fit never moves it."""
        from hybridneus.training.scene import FILENAME

        save_config(trainer.cfg, self.run_dir / "config.yaml")
        trainer.record.save(self.run_dir / FILENAME)
        runs.remove_stale_temporaries(self.run_dir)
        self._saved_at = time.perf_counter()

    def after_step(self, trainer, logs: dict[str, float]) -> None:
        """Log metrics, write previews and checkpoints on their schedules."""
        t = trainer.cfg.train
        step = trainer.step
        if step % max(t.log_every, 1) == 0 or step == 1:
            row = {"step": float(step), "elapsed_s": trainer.elapsed, **logs}
            self._append(row)
            if self.tb is not None:
                for key, value in logs.items():
                    self.tb.add_scalar(key, value, step)
        if t.preview_every > 0 and step % t.preview_every == 0:
            self.preview(trainer)
        due = t.checkpoint_every > 0 and step % t.checkpoint_every == 0
        late = 0 < t.checkpoint_seconds <= time.perf_counter() - self._saved_at
        if due or late:
            self.checkpoint(trainer)

    def _append(self, row: dict[str, float]) -> None:
        self.history.append(row)
        if self.columns is None:
            self.columns = _FIXED + sorted(k for k in row if k not in _FIXED)
            new = True
        else:
            new = False
        extra = [k for k in row if k not in self.columns]
        if extra:
            self.columns += sorted(extra)
            self._rewrite_metrics()
            return
        with open(self.metrics_path, "a", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=self.columns, extrasaction="ignore")
            if new or os.path.getsize(self.metrics_path) == 0:
                writer.writeheader()
            writer.writerow({k: _fmt(row.get(k)) for k in self.columns})

    def checkpoint(self, trainer) -> Path:
        """Save the trainer's full state atomically (the one before stays as
        ``previous.pt``)."""
        path = runs.save_checkpoint(self.run_dir, trainer.state_dict())
        self._saved_at = time.perf_counter()
        return path

    def save_poses(self, trainer, refined) -> None:
        """``poses_refined.npz`` (``given`` and ``refined`` (n_views, 4, 4) camera-to-world,
        ``views``: the view names) and ``previews/poses.png``, how far smoothing moved each
        view."""
        import numpy as np

        from hybridneus.data.track import pose_errors
        from hybridneus.training.previews import write_pose_changes

        given = np.asarray(trainer.data.given_c2w, dtype=np.float64)
        with atomic_path(self.run_dir / POSES) as tmp:
            np.savez(tmp, given=given, refined=refined,
                     views=np.asarray(trainer.split.view_names))
        degrees, moved = pose_errors(refined, given)
        write_pose_changes(degrees, moved, self.run_dir / "previews" / "poses.png")

    def preview(self, trainer) -> None:
        """Write ``previews/step_<n>.png`` and ``previews/curve.png``."""
        from hybridneus.training.previews import write_curve, write_preview

        write_preview(trainer, self.run_dir / "previews" / f"step_{trainer.step:07d}.png")
        write_curve(self.history, self.run_dir / "previews" / "curve.png")

    def views(self, trainer, n: int = VIEWS) -> list[Path]:
        """``previews/view_<i>.png``: the window preview (:func:`write_preview`) of ``n``
        views spread over the sequence, for the run's report."""
        from hybridneus.training.previews import write_preview

        last = trainer.split.n_views - 1
        picks = sorted({round(last * (k + 0.5) / n) for k in range(n)})
        paths = [self.run_dir / "previews" / f"view_{i:05d}.png" for i in picks]
        for i, path in zip(picks, paths, strict=True):
            write_preview(trainer, path, view=i)
        return paths

    def finish(self, trainer) -> None:
        """Final checkpoint, curve and (if any) preview; close TensorBoard. ``scene.yaml`` is
        written again: a budgeted fit may have re-planned its length, and one stopped at its
        deadline says so (``stopped_at``)."""
        from hybridneus.training.scene import FILENAME

        self.checkpoint(trainer)
        refined = trainer.trained_poses()
        if refined is not None:
            self.save_poses(trainer, refined)
        if trainer.stopped_early:
            trainer.record.stopped_at = trainer.step
        trainer.record.save(self.run_dir / FILENAME)
        if self.runs_root is not None:
            runs.set_latest(self.runs_root, self.run_dir)
        if self.history:
            from hybridneus.training.previews import write_curve

            write_curve(self.history, self.run_dir / "previews" / "curve.png")
        if not trainer.interrupted and trainer.cfg.train.preview_every > 0:
            self.views(trainer)
        if self.tb is not None:
            self.tb.flush()
            self.tb.close()


def _fmt(value: Any) -> str:
    if value is None:
        return ""
    if float(value).is_integer() and abs(value) < 1e15:
        return str(int(value))
    return f"{value:.6g}"


def _tensorboard_writer(path: Path):
    """A SummaryWriter when ``tensorboard`` is installed, else ``None`` (optional extra)."""
    try:
        from torch.utils.tensorboard import SummaryWriter
    except Exception:  # ImportError, or a broken optional install: logging is optional
        return None
    return SummaryWriter(str(path))
