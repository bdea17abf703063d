"""``hybridneus info DATA``: what a dataset holds, its scene preset, and what a fit would
estimate from its events."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from hybridneus.cli.options import SetOption


def info(
    data: Annotated[Path, typer.Argument(help="Dataset folder, e.g. data/real/multimeter.")],
    set_: SetOption = None,
    preset: Annotated[str, typer.Option(help="Config preset the --set keys apply to.")] = "fast",
    split: Annotated[
        list[str] | None,
        typer.Option("--split", help="Only these splits (repeatable). Default: all."),
    ] = None,
    as_json: Annotated[bool, typer.Option("--json", help="One JSON object on stdout.")] = False,
) -> None:
    """Show a dataset's splits (views, events, polarity balance, time span, size), the scene
    preset and its source, and the values a fit would estimate from the events (polarity
    offset, crop, tonemap eps: the run's scene.yaml gets the same)."""
    import json
    import logging

    from hybridneus.cli.options import config_with
    from hybridneus.data import load_dataset

    cfg = config_with(preset, set_)
    # What loading warns about (an unknown preset key, ...) is shown; the estimators'
    # findings are printed below, so their logging copies are kept off the terminal.
    logger = logging.getLogger("hybridneus")
    logger.setLevel(logging.WARNING)
    ds = load_dataset(data, overrides=cfg.data.overrides() or None, splits=split or None)
    logger.setLevel(logging.ERROR)
    report = dataset_report(ds, cfg)
    if as_json:
        typer.echo(json.dumps(report, indent=2))
    else:
        _print(report)


def dataset_report(ds, cfg) -> dict[str, Any]:
    """Everything ``info`` shows, as plain JSON-ready values."""
    import numpy as np

    from hybridneus.data.estimate import estimate_scene, noise_and_balance

    splits = {}
    for s in ds.splits.values():
        ev = s.events
        n = len(ev)
        splits[s.name] = {
            "views": s.n_views, "events": n,
            "positive_share": round(ev.n_positive / n, 4) if n else None,
            "t_first": float(ev.t[0]) if n else None, "t_last": float(ev.t[-1]) if n else None,
            "width": s.width, "height": s.height,
            "rgb_frames": len(s.rgb_paths) if s.rgb_paths else 0,
            "polarity_stored_as": ev.polarity_note, "events_file": str(ev.path),
            "distortion": (np.median(s.distortion, axis=0).round(6).tolist()
                           if s.distortion.any() else None),
            "lens": s.lens.to_json() if s.lens is not None else None,
        }
    from hybridneus.recordings.frame import read_scene_frame

    frame = read_scene_frame(ds.root)
    out: dict[str, Any] = {"dataset": str(ds.root), "preset_source": ds.preset_source,
                           "preset": ds.preset.to_dict(), "stated": sorted(ds.stated),
                           "splits": splits, "notes": list(ds.notes),
                           "frame": frame.to_json() if frame is not None else None}
    if cfg.data.split in ds.splits:
        from hybridneus.data.hot import split_hot_pixels

        found = estimate_scene(ds, cfg.estimate, cfg.data, cfg.refine)
        # the fit's own count of the split as given, unless estimate.hot_pixels is off
        hot = found.hot if found.hot is not None else split_hot_pixels(ds[cfg.data.split])
        out["hot_pixels"] = {"line": hot.line(), "pixels": [list(xy) for xy in hot.pixels()],
                             "events": hot.events}
        noise, balance = found.noise, found.balance
        if balance is None:
            noise, balance = noise_and_balance(found.dataset[cfg.data.split])
        out["fit"] = {
            "split": cfg.data.split,
            "noise": noise,
            "polarity_balance": balance.offset,
            "estimated": found.taken,
            "preset": found.dataset.preset.to_dict(),
            "eps_start": found.eps_start,
            "findings": found.lines,
            "warnings": found.warnings,
        }
    return out


def _print(report: dict[str, Any]) -> None:
    import sys

    from rich.console import Console
    from rich.table import Table

    # Piped output (no terminal) still gets a table wide enough not to wrap its cells.
    console = Console(width=None if sys.stdout.isatty() else 130)

    def say(text: str) -> None:
        console.print(text, markup=False, highlight=False)

    table = Table(title=report["dataset"])
    for col in ("split", "views", "events", "+ / -", "time span", "size", "rgb", "polarity"):
        table.add_column(col, justify="right" if col in ("views", "events") else "left",
                         no_wrap=True)
    for name, s in report["splits"].items():
        pos = s["positive_share"]
        table.add_row(
            name, str(s["views"]), f"{s['events']:,}",
            "-" if pos is None else f"{pos:.1%} / {1 - pos:.1%}",
            f"{s['t_first']:.6g} .. {s['t_last']:.6g}" if s["events"] else "-",
            f"{s['width']}x{s['height']}",
            f"{s['rgb_frames']} files" if s["rgb_frames"] else "absent",
            "-1/+1" if s["polarity_stored_as"] == "-1/+1" else "0/1 -> -1/+1",
        )
    console.print(table)
    fit = report.get("fit")
    ptable = Table(title="scene preset" + (" (a fit's, with its estimates)" if fit else ""))
    for col in ("key", "value", "from"):
        ptable.add_column(col)
    values = fit["preset"] if fit else report["preset"]
    for key, value in values.items():
        if key == "background":
            value = ", ".join(f"{v:.4g} ({v * 255:.0f}/255)" for v in value)
        how = "estimated" if fit and key in fit["estimated"] else (
            "stated" if key in report["stated"] else "fallback")
        ptable.add_row(key, str(value), how)
    console.print(ptable)
    say(f"preset source: {report['preset_source']}")
    if fit:
        say(f"noise: {fit['noise']}")
        say(report["hot_pixels"]["line"] + (
            "; a fit and convert leave such pixels out"
            if report["hot_pixels"]["events"] else ""))
        for line in fit["findings"]:
            if not line.startswith(("events:", "hot pixels:")):  # shown above
                say(f"fit: {line}")
        for line in fit["warnings"]:
            say(f"warning: {line}")
    for name, s in report["splits"].items():
        say(f"{name}: events from {s['events_file']}, polarity stored as "
            f"{s['polarity_stored_as']}")
        if s["distortion"]:
            k1, k2 = s["distortion"][:2]
            say(f"{name}: radial distortion k1={k1:.4g}, k2={k2:.4g}")
        if s["lens"]:
            coeffs = ", ".join(f"{c:.4g}" for c in s["lens"]["coeffs"])
            say(f"{name}: {s['lens']['model']} lens ({coeffs}), undistorted at ray time")
    if report.get("frame"):
        f = report["frame"]
        say(f"frame: a converted recording, {f['scale']:.4g} normalised units per metre "
            f"(centre: {f['how']}); meshes are written back in the recording's frame")
    for note in report["notes"]:
        if "polarity stored as" not in note:  # already shown per split above
            say(f"note: {note}")
