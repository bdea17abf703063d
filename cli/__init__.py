"""The ``hybridneus`` command-line tool (Typer). Installed as ``hybridneus.cli``."""
