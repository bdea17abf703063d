"""The table of every config key, for docs/training.md (``python -m hybridneus.config.table``)."""

from __future__ import annotations

import dataclasses
from typing import Any

from hybridneus.config.overrides import _section_fields, _type_name
from hybridneus.config.tree import Config


def config_table() -> list[tuple[str, str, str, str]]:
    """Rows ``(key, type, default of fast, comment)`` for the documentation table."""
    rows: list[tuple[str, str, str, str]] = []
    cfg = Config()
    for section in dataclasses.fields(cfg):
        sub = getattr(cfg, section.name)
        if not dataclasses.is_dataclass(sub):
            rows.append((section.name, "str", repr(sub), "preset the tree started from"))
            continue
        rows += _section_rows(section.name, sub)
    return rows


def _section_rows(prefix: str, sub: Any) -> list[tuple[str, str, str, str]]:
    import inspect

    rows = []
    comments = _field_comments(inspect.getsource(type(sub)))
    for name, tp in _section_fields(sub).items():
        value = getattr(sub, name)
        if dataclasses.is_dataclass(value):
            rows += _section_rows(f"{prefix}.{name}", value)
        else:
            rows.append((f"{prefix}.{name}", _type_name(tp), repr(value), comments.get(name, "")))
    return rows


def _field_comments(source: str) -> dict[str, str]:
    out = {}
    for line in source.splitlines():
        stripped = line.strip()
        if ":" in stripped and "#" in stripped and not stripped.startswith(("#", '"')):
            name = stripped.split(":", 1)[0].strip()
            out[name] = stripped.split("#", 1)[1].strip()
        elif stripped.startswith("enabled:"):
            out["enabled"] = "switch the prior on or off"
    return out


def config_markdown() -> str:
    """The table as markdown, as docs/training.md holds it."""
    rows = ["| key | type | `fast` default | meaning |", "|---|---|---|---|"]
    for key, tp, default, comment in config_table():
        meaning = comment.replace("|", "\\|")  # a pipe would end the table's cell
        rows.append(f"| `{key}` | {tp} | `{default}` | {meaning} |")
    return "\n".join(rows) + "\n"


if __name__ == "__main__":
    print(config_markdown(), end="")
