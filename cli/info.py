"""``hybridneus info DATA``: what a dataset holds and which preset will be used."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer


def info(
    data: Annotated[Path, typer.Argument(help="Dataset folder, e.g. data/real/multimeter.")],
    preset_override: Annotated[
        list[str] | None,
        typer.Option(
            "--preset-override",
            "-o",
            help="Replace a preset field, key=value (repeatable), e.g. threshold=0.2.",
        ),
    ] = None,
    split: Annotated[
        list[str] | None,
        typer.Option("--split", help="Only these splits (repeatable). Default: all."),
    ] = None,
) -> None:
    """Show a dataset's splits (views, events, polarity balance, time span, resolution) and
    the preset in use with its source."""
    import logging
    import sys

    import numpy as np
    from rich.console import Console
    from rich.table import Table

    from hybridneus.data import load_dataset, parse_override_strings

    # The notes are printed below; keep the logging copies of them off the terminal.
    logging.getLogger("hybridneus.data").setLevel(logging.ERROR)
    overrides = parse_override_strings(preset_override)
    ds = load_dataset(data, overrides=overrides or None, splits=split or None)
    # Piped output (no terminal) still gets a table wide enough not to wrap its cells.
    console = Console(width=None if sys.stdout.isatty() else 130)

    table = Table(title=f"{ds.root}")
    for col in ("split", "views", "events", "+ / -", "time span", "size", "rgb", "polarity"):
        table.add_column(col, justify="right" if col in ("views", "events") else "left",
                         no_wrap=True)
    for s in ds.splits.values():
        ev = s.events
        n = len(ev)
        n_pos = ev.n_positive
        table.add_row(
            s.name,
            str(s.n_views),
            f"{n:,}",
            f"{n_pos / n:.1%} / {(n - n_pos) / n:.1%}",
            f"{float(ev.t[0]):.6g} .. {float(ev.t[-1]):.6g}",
            f"{s.width}x{s.height}",
            f"{len(s.rgb_paths)} files" if s.rgb_paths else "absent",
            "-1/+1" if ev.polarity_note == "-1/+1" else "0/1 -> -1/+1",
        )
    console.print(table)

    p = ds.preset
    ptable = Table(title="preset")
    ptable.add_column("key")
    ptable.add_column("value")
    for key, value in p.to_dict().items():
        if key == "background":
            value = ", ".join(f"{v:.4g} ({v * 255:.0f}/255)" for v in value)
        ptable.add_row(key, str(value))
    console.print(ptable)
    console.print(f"preset source: {ds.preset_source}", markup=False, highlight=False)
    if "train" in ds.splits:
        from hybridneus.config import DataConfig
        from hybridneus.data.balance import polarity_balance
        from hybridneus.data.contrast import event_extent, loss_eps
        from hybridneus.data.denoise import denoised_split

        defaults = DataConfig()
        filtered, report = denoised_split(ds.splits["train"], defaults.denoise_slab)
        state = "on" if defaults.denoise else "off"
        console.print(f"noise: {report.line()} (data.denoise, {state} by default)",
                      markup=False, highlight=False)
        balance = polarity_balance(ds.splits["train"], defaults.denoise_slab,
                                   (filtered, report))
        console.print(f"{balance.line()}; {_offset_use(ds, balance)}", markup=False,
                      highlight=False)
        # what a fit with the defaults takes
        train = filtered if defaults.denoise else ds.splits["train"]
        offset = balance.suggested()
        estimated = defaults.offset_from_events and "polarity_offset" not in ds.stated
        if estimated and offset is not None:
            p = replace(p, polarity_offset=offset)
        eps, why = loss_eps(p.tonemap_eps, event_extent(train, p), defaults.eps_max)
        console.print(f"fit: tonemap eps {eps:g}, {why} (data.eps_from_events)",
                      markup=False, highlight=False)
    for s in ds.splits.values():
        console.print(f"{s.name}: events from {s.events.path}, polarity stored as "
                      f"{s.events.polarity_note}", markup=False, highlight=False)
        if s.distortion.any():
            k = np.median(s.distortion, axis=0)
            console.print(f"{s.name}: radial distortion k1={k[0]:.4g}, k2={k[1]:.4g}",
                          markup=False, highlight=False)
    for note in ds.notes:
        if "polarity stored as" in note:  # already shown per split above
            continue
        console.print(f"note: {note}", markup=False, highlight=False)


def _offset_use(ds, balance) -> str:
    """What a fit with the defaults does with the estimate ``balance``."""
    offset, stated = balance.suggested(), ds.preset.polarity_offset
    if "polarity_offset" not in ds.stated:
        if offset is None:
            return f"a fit keeps the preset's {stated:g}"
        return f"a fit uses {offset:g} (data.offset_from_events)"
    if balance.disagrees(stated):
        return (f"the preset's {stated:g} disagrees: --set data.polarity_offset={offset:g} "
                "uses the events'")
    return f"a fit keeps the preset's {stated:g}"
