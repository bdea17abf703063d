"""``hybridneus preview DATA --out DIR``: PNGs of event frames (and rgb frames when present)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from hybridneus.cli.options import SetOption


def preview(
    data: Annotated[Path, typer.Argument(help="Dataset folder, e.g. data/real/multimeter.")],
    out: Annotated[Path, typer.Option("--out", help="Folder for the PNG files.")],
    split: Annotated[str, typer.Option("--split", help="Split to preview.")] = "train",
    n: Annotated[int, typer.Option("--n", min=1, help="Number of views (evenly spaced).")] = 8,
    window: Annotated[
        float | None,
        typer.Option("--window", help="Window length in views. Default: the preset's max."),
    ] = None,
    background: Annotated[
        str, typer.Option("--background", help="'white' or 'black' behind the events.")
    ] = "white",
    set_: SetOption = None,
) -> None:
    """Write PNGs of event frames (red positive, blue negative) ending at evenly spaced views,
    side by side with the view's rgb frame where one is readable."""
    import logging

    import cv2
    import numpy as np

    from hybridneus.cli.options import config_with
    from hybridneus.data import event_frame, load_dataset
    from hybridneus.data.pictures import event_image
    from hybridneus.errors import ConfigError
    from hybridneus.fileio import atomic_path

    if background not in ("white", "black"):
        raise ConfigError(f"--background: expected 'white' or 'black', got {background!r}")
    logging.getLogger("hybridneus.data").setLevel(logging.WARNING)  # notes off, warnings on
    cfg = config_with("fast", set_)
    ds = load_dataset(data, overrides=cfg.data.overrides() or None, splits=[split])
    sp = ds.splits[split]
    if sp.n_views < 2:
        raise ConfigError(f"{sp.path}: preview needs at least 2 views")
    length = float(ds.preset.max_window if window is None else window)
    if length <= 0:
        raise ConfigError(f"--window: must be > 0 views, got {window}")
    dt = sp.t_max / (sp.n_views - 1)
    first = 0 if ds.preset.cyclic else 1
    views = np.unique(np.linspace(first, sp.n_views - 1, min(n, sp.n_views - first)).round())
    written = 0
    for v in views.astype(int):
        t1 = v * dt
        t0 = max(t1 - length * dt, -sp.t_max if ds.preset.cyclic else 0.0)
        frame = event_frame(sp, t0, t1, 0.0)  # raw polarity sums show the structure best
        img = np.ascontiguousarray(event_image(frame, background)[..., ::-1])  # BGR for cv2
        if sp.rgb_paths is not None:
            rgb = cv2.imread(str(sp.rgb_paths[v]), cv2.IMREAD_COLOR)
            if rgb is not None:  # real scenes ship unreadable placeholders
                rgb = cv2.resize(rgb, (sp.width, sp.height), interpolation=cv2.INTER_AREA)
                img = np.concatenate([img, rgb], axis=1)
        name = out / f"{split}_{sp.view_names[v]}_events.png"
        with atomic_path(name) as tmp:
            if not cv2.imwrite(str(tmp), img):
                raise ConfigError(f"{name}: cannot write PNG")
        written += 1
    typer.echo(f"wrote {written} PNGs to {out} ({split}, windows of {length:g} views)")
