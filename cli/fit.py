"""``hybridneus fit``: train a hybrid NeuS field from an event dataset."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated

import typer


def fit(
    data: Annotated[
        Path | None,
        typer.Argument(
            help="Dataset folder (EventNeRF layout). Optional with --resume.", show_default=False
        ),
    ] = None,
    preset: Annotated[
        str, typer.Option(help="Configuration preset: fast (CPU), quality or eventneus.")
    ] = "fast",
    device: Annotated[str, typer.Option(help="auto, cpu, cuda or cuda:N.")] = "auto",
    set_: Annotated[
        list[str] | None,
        typer.Option(
            "--set",
            help="Override a config key, e.g. --set train.lr=0.005 --set data.threshold=0.2 "
            "(repeatable; see docs/training.md).",
            show_default=False,
        ),
    ] = None,
    config: Annotated[
        Path | None,
        typer.Option(help="Start from a YAML config (e.g. a run's config.yaml).",
                     show_default=False),
    ] = None,
    out: Annotated[Path, typer.Option(help="Runs folder; each fit makes runs/<scene>-<time>.")]
    = Path("runs"),
    resume: Annotated[
        Path | None,
        typer.Option(help="Continue this run folder from its last checkpoint.",
                     show_default=False),
    ] = None,
    iters: Annotated[
        int | None, typer.Option(help="Training steps (default: the preset's).",
                                 show_default=False)
    ] = None,
    minutes: Annotated[
        float | None,
        typer.Option(help="Wall-clock budget of the whole fit, turned into a step count "
                     "before the first step (saved in the run's scene.yaml).",
                     show_default=False),
    ] = None,
    seed: Annotated[int | None, typer.Option(help="Random seed.", show_default=False)] = None,
    quiet: Annotated[bool, typer.Option(help="No progress bar.")] = False,
    report: Annotated[bool, typer.Option(help="Write the run's report.html at the end "
                                         "(see hybridneus report).")] = True,
) -> None:
    """Train on DATA's event stream and write a run folder (config, checkpoints, previews).

    Ctrl-C saves a checkpoint (--resume RUN continues); `hybridneus mesh` meshes runs/latest.
    """
    import os
    import time

    started = time.perf_counter()
    # Transparent huge pages for PyTorch's CPU allocator: large fresh buffers fault in much
    # faster (measured in docs/anchors); must be set before torch is first imported.
    os.environ.setdefault("THP_MEM_ALLOC_ENABLE", "1")
    from hybridneus.api import fit as api_fit
    from hybridneus.cli.options import log_to_stderr
    from hybridneus.config import load_config, preset_config
    from hybridneus.errors import ConfigError

    overrides = list(set_ or [])
    if iters is not None and minutes is not None:
        raise ConfigError("--iters and --minutes: give one (a budget decides the steps)")
    if iters is not None:
        if iters < 1:
            raise ConfigError(f"--iters {iters}: must be >= 1")
        overrides += [f"train.iters={iters}", "train.minutes=0"]
    if minutes is not None:
        if minutes <= 0:
            raise ConfigError(f"--minutes {minutes}: must be > 0")
        overrides.append(f"train.minutes={minutes}")
    if seed is not None:
        overrides.append(f"train.seed={seed}")
    if resume is None and data is None:
        raise ConfigError("DATA: missing dataset folder (or give --resume RUN)")
    if resume is not None:
        cfg = None
    elif config is not None:
        cfg = load_config(config)
    else:
        cfg = preset_config(preset)
    if not quiet:  # the library's progress notes (e.g. the crop from the events) on stderr
        log_to_stderr()
    field = api_fit(
        data,
        cfg,
        overrides=overrides,
        out=out,
        resume=resume,
        device=device,
        progress=not quiet,
        started=started,
        report=report,
    )
    run_dir = field.run_dir
    if field.interrupted:
        typer.echo(
            f"interrupted at step {field.trainer_step}; checkpoint saved in {run_dir}\n"
            f"continue with: hybridneus fit --resume {run_dir}",
            err=True,
        )
        sys.exit(130)
    typer.echo(f"run: {run_dir} (step {field.trainer_step})")
    typer.echo("next: hybridneus mesh  (uses runs/latest)")
