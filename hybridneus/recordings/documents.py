"""JSON and YAML documents the readers take (turntables, calibrations, transforms)."""

from __future__ import annotations

import json
from pathlib import Path

from hybridneus.errors import RecordingError


def read_text(path: Path) -> str:
    """The file's text, or a one-line error naming it."""
    try:
        return path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: cannot read ({exc})") from None


def parse_mapping(path: Path, text: str) -> dict:
    """``text`` (of ``path``: JSON by its suffix, else YAML) as a mapping."""
    try:
        if path.suffix.lower() == ".json":
            doc = json.loads(text)
        else:
            import yaml

            doc = yaml.safe_load(text)
    except Exception as exc:  # json.JSONDecodeError or yaml.YAMLError
        raise RecordingError(f"{path}: cannot parse ({str(exc).splitlines()[0]})") from None
    if not isinstance(doc, dict):
        raise RecordingError(f"{path}: expected a mapping at the top level")
    return doc


def read_mapping(path: Path) -> dict:
    """A JSON or YAML file as a mapping."""
    return parse_mapping(path, read_text(path))


__all__ = ["parse_mapping", "read_mapping", "read_text"]
