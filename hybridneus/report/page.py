"""The report as one HTML file that opens from disk: plotly's script and every picture are
inside it (pictures as data URIs), so it needs no server and no network."""

from __future__ import annotations

import base64
import html
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import yaml

STYLE = """
body { font-family: system-ui, sans-serif; margin: 0 auto; max-width: 1100px;
       padding: 0 1.2em 3em; color: #222; }
h1 { font-size: 1.5em; margin-bottom: 0.2em; }
h2 { font-size: 1.2em; border-bottom: 1px solid #ddd; padding-bottom: 0.2em; margin-top: 2em; }
.meta { color: #666; margin-top: 0; }
table { border-collapse: collapse; margin: 0.5em 0; }
td, th { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: left;
         font-variant-numeric: tabular-nums; }
th { background: #f4f4f4; }
figure { display: inline-block; margin: 0.4em 0.8em 0.4em 0; vertical-align: top; }
figure img { image-rendering: pixelated; max-width: 100%; border: 1px solid #eee; }
figcaption { color: #555; font-size: 0.9em; }
pre { background: #f7f7f7; padding: 0.6em; overflow-x: auto; font-size: 0.85em; }
.note { color: #666; }
"""


def document(title: str, body: Iterable[str], script: str = "") -> str:
    """A whole page: ``body``'s HTML parts, with ``script`` (plotly's bundle) in the head."""
    head = [f"<meta charset='utf-8'><title>{esc(title)}</title>", f"<style>{STYLE}</style>"]
    if script:
        head.append(f"<script type='text/javascript'>{script}</script>")
    return ("<!DOCTYPE html>\n<html lang='en'><head>" + "".join(head) + "</head><body>\n"
            + "\n".join(body) + "\n</body></html>\n")


def esc(value: Any) -> str:
    return html.escape(str(value), quote=True)


def section(title: str, anchor: str, parts: Iterable[str]) -> str:
    """A titled section (``id`` ``anchor``, for links and screenshots) of HTML ``parts``."""
    return (f"<section id='{esc(anchor)}'><h2>{esc(title)}</h2>\n" + "\n".join(parts)
            + "</section>")


def paragraph(text: str, cls: str = "") -> str:
    return f"<p class='{esc(cls)}'>{esc(text)}</p>" if cls else f"<p>{esc(text)}</p>"


def table(header: list[str], rows: Iterable[Iterable[Any]], raw: bool = False) -> str:
    """An HTML table; cells are escaped unless ``raw`` (cells built here, such as links)."""
    head = "".join(f"<th>{esc(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{c if raw else esc(fmt(c))}</td>" for c in row)
                   + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def fmt(value: Any) -> str:
    """A cell: floats to 5 significant digits, None as '-', lists inline."""
    if value is None:
        return "-"
    if isinstance(value, float):
        return f"{value:.5g}"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(fmt(v) for v in value) + "]"
    if isinstance(value, dict):
        return ", ".join(f"{k}: {fmt(v)}" for k, v in value.items())
    return str(value)


def picture(path: Path, caption: str = "", scale: float = 1.0) -> str:
    """A PNG from disk inlined as a data URI, shown ``scale`` times its size, with its
    caption."""
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    size = ""
    if scale != 1.0:
        from PIL import Image

        with Image.open(path) as img:
            size = f" width='{round(img.width * scale)}'"
    cap = f"<figcaption>{esc(caption)}</figcaption>" if caption else ""
    return (f"<figure><img alt='{esc(caption or path.name)}'{size} "
            f"src='data:image/png;base64,{data}'>{cap}</figure>")


def plot(fig, div_id: str) -> str:
    """A plotly figure's div and the call that draws it (the script is in the head)."""
    return fig.to_html(full_html=False, include_plotlyjs=False, div_id=div_id,
                       config={"displaylogo": False, "responsive": True})


def details(summary: str, text: str) -> str:
    return f"<details><summary>{esc(summary)}</summary><pre>{esc(text)}</pre></details>"


def yaml_text(data: Any) -> str:
    return yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)


def link(href: str, text: str) -> str:
    return f"<a href='{esc(href)}'>{esc(text)}</a>"


__all__ = ["document", "esc", "fmt", "link", "paragraph", "picture", "plot", "section",
           "table", "yaml_text"]
