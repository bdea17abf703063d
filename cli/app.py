"""The ``hybridneus`` Typer application: one sub-command per module in this package.

Command modules import torch, Open3D and the rest inside their functions, so that
``hybridneus --help`` stays fast.
"""

from __future__ import annotations

import importlib
import sys

import typer

from hybridneus.errors import HybridNeusError

#: Exit code of a command stopped by Ctrl-C (128 + SIGINT, what shells report).
INTERRUPTED = 130

app = typer.Typer(
    name="hybridneus",
    help="Coloured 3D meshes from a single colour event camera (EventNeuS, pure PyTorch).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

# (command name, module under hybridneus.cli, function name). Each module owns one command.
_COMMANDS: list[tuple[str, str, str]] = [
    ("info", "info", "info"),
    ("fit", "fit", "fit"),
    ("preview", "preview", "preview"),
    ("simulate", "simulate", "simulate"),
    ("convert", "convert", "convert"),
    ("mesh", "mesh", "mesh"),
    ("eval", "evaluate", "evaluate"),
    ("render", "render", "render"),
    ("demo", "demo", "demo"),
    ("batch", "batch", "batch"),
    ("report", "report", "report"),
]

for _name, _module, _func in _COMMANDS:
    app.command(_name)(getattr(importlib.import_module(f"hybridneus.cli.{_module}"), _func))


def main() -> None:
    """Console-script entry point: bad input becomes one line on stderr and exit code 2."""
    try:
        code = app(standalone_mode=False)
    except HybridNeusError as exc:
        typer.echo(f"error: {exc}", err=True)
        sys.exit(2)
    except typer.Exit as exc:
        sys.exit(exc.exit_code)
    except typer.Abort:
        typer.echo("aborted", err=True)
        sys.exit(INTERRUPTED)
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        sys.exit(INTERRUPTED)
    except Exception as exc:
        # Usage errors (unknown option, missing argument) come from the click that Typer
        # bundles; they know how to print themselves and carry exit code 2.
        show, code = getattr(exc, "show", None), getattr(exc, "exit_code", None)
        if callable(show) and isinstance(code, int):
            show()
            sys.exit(code)
        raise
    # Out of standalone mode Typer turns a Ctrl-C outside a command's own handling into a
    # returned 130 (its Exit), not a raise: without this the process would end 0, silently.
    if code == INTERRUPTED:
        typer.echo("interrupted", err=True)
    if isinstance(code, int) and code:
        sys.exit(code)

if __name__ == "__main__":
    main()
