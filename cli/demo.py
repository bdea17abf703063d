"""``hybridneus demo``: the whole pipeline on a built-in scene, as the commands a user types."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def demo_commands(
    out: Path, minutes: float, views: int, width: int, height: int, res: int, device: str
) -> list[list[str]]:
    """The ``hybridneus`` argument lists the demo runs, in order."""
    data, runs = out / "data" / "device", out / "runs"
    return [
        ["simulate", "builtin:device", str(data), "--views", str(views), "--width", str(width),
         "--height", str(height), "--val-views", "8", "--test-views", "8"],
        ["info", str(data)],
        ["preview", str(data), "--out", str(out / "preview"), "--n", "4"],
        ["fit", str(data), "--out", str(runs), "--minutes", str(minutes), "--device", device],
        ["mesh", "--runs-root", str(runs), "--res", str(res), "--color", "--device", device,
         "--out", str(out / "mesh.ply")],
        ["eval", str(out / "mesh.ply"), str(data / "gt_mesh.ply")],
        ["render", "--runs-root", str(runs), "--views", "all", "--max-views", "2",
         "--out", str(out / "render"), "--device", device],
    ]


def demo(
    out: Annotated[Path, typer.Option("--out", help="Folder for everything the demo writes.")]
    = Path("demo"),
    minutes: Annotated[float, typer.Option("--minutes", help="Training budget.")] = 4.0,
    views: Annotated[int, typer.Option("--views", help="Training views to simulate.")] = 300,
    width: Annotated[int, typer.Option("--width", help="Simulated image width.")] = 173,
    height: Annotated[int, typer.Option("--height", help="Simulated image height.")] = 130,
    res: Annotated[int, typer.Option("--res", help="Mesh resolution.")] = 256,
    device: Annotated[str, typer.Option("--device", help="auto, cpu, cuda or cuda:N.")] = "auto",
) -> None:
    """Simulate a textured handheld device, inspect it, fit it from events, extract a coloured
    mesh, score it against the ground truth and render pictures — printing each command."""
    import subprocess
    import sys

    from hybridneus.errors import ConfigError

    if minutes <= 0 or views < 10 or width < 32 or height < 32:
        raise ConfigError("--minutes must be > 0, --views >= 10, --width/--height >= 32")
    for args in demo_commands(out, minutes, views, width, height, res, device):
        typer.secho("$ hybridneus " + " ".join(args), bold=True, err=True)
        code = subprocess.run([sys.executable, "-m", "hybridneus.cli.app", *args]).returncode
        if code != 0:
            typer.echo(f"error: demo step `hybridneus {args[0]}` failed (exit {code})", err=True)
            raise typer.Exit(code)
    typer.echo(f"demo finished: mesh {out / 'mesh.ply'}, pictures in {out / 'render'}")
