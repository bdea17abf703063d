"""A page opened in headless Chromium (Debian's ``chromium``, driven by Playwright): what its
scripts logged as errors, whether its plots and 3D canvases drew, and a screenshot.

Used by the browser tests (``python -m pytest -m browser``) and by ``bench_report.py`` for the
pictures in the docs, so that what the docs show is what the test saw.
"""

from __future__ import annotations

import os
import shutil
from dataclasses import dataclass, field
from pathlib import Path

#: Flags that keep Chromium off the network (a closed network refuses its background
#: connections by the dozen) and working as root in a container.
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-quic"]


def chromium() -> str | None:
    """The Chromium executable (``$CHROMIUM``, else ``chromium`` on the PATH), or None."""
    return os.environ.get("CHROMIUM") or shutil.which("chromium") or shutil.which(
        "chromium-browser")


@dataclass
class PageCheck:
    """What a page did in the browser: ``errors`` (uncaught exceptions, console errors and
    requests for anything but files and data URIs),
    ``canvases`` (for each WebGL canvas asked for, the spread of its pixel values: 0 when
    blank), ``plots`` (the plot divs that drew)."""

    errors: list[str] = field(default_factory=list)
    canvases: dict[str, float] = field(default_factory=dict)
    plots: list[str] = field(default_factory=list)


def check_page(path: str | Path, screenshot: str | Path | None = None,
               plots: tuple[str, ...] = (), canvases: tuple[str, ...] = (),
               selector: str | None = None, width: int = 1200, height: int = 900,
               timeout_s: float = 60.0) -> PageCheck:
    """Open the file ``path`` in headless Chromium and wait for each plotly div of ``plots``
    (its ids) to draw; measure each 3D view of ``canvases`` (ids of divs holding a WebGL
    canvas) by a screenshot of the div; write ``screenshot`` (of ``selector``, else the
    viewport's page top) when asked."""
    import io

    import numpy as np
    from PIL import Image
    from playwright.sync_api import sync_playwright

    exe = chromium()
    if exe is None:
        raise RuntimeError("no chromium executable (apt-get install chromium, or set $CHROMIUM)")
    out = PageCheck()
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=exe, args=FLAGS)
        try:
            page = browser.new_page(viewport={"width": width, "height": height})
            page.on("pageerror", lambda exc: out.errors.append(f"page: {exc}"))
            page.on("console", lambda m: out.errors.append(f"console: {m.text}")
                    if m.type == "error" else None)
            # a self-contained page asks for nothing but itself and its data URIs
            page.on("request", lambda r: None if r.url.startswith(("file:", "data:", "blob:"))
                    else out.errors.append(f"request: {r.url}"))
            page.goto(Path(path).resolve().as_uri(), timeout=timeout_s * 1e3)
            for div in plots:
                page.wait_for_selector(f"#{div} .main-svg", timeout=timeout_s * 1e3)
                out.plots.append(div)
            for div in canvases:
                page.wait_for_selector(f"#{div} canvas", timeout=timeout_s * 1e3)
            page.wait_for_timeout(1500)  # WebGL draws on the next animation frames
            for div in canvases:
                shot = page.query_selector(f"#{div}").screenshot()
                pixels = np.asarray(Image.open(io.BytesIO(shot)).convert("L"), dtype=float)
                out.canvases[div] = float(pixels.std())
            if screenshot is not None:
                Path(screenshot).parent.mkdir(parents=True, exist_ok=True)
                if selector is not None:
                    page.query_selector(selector).screenshot(path=str(screenshot))
                else:
                    page.evaluate("window.scrollTo(0, 0)")  # measuring a view scrolled to it
                    page.wait_for_timeout(300)
                    page.screenshot(path=str(screenshot))
        finally:
            browser.close()
    return out


__all__ = ["FLAGS", "PageCheck", "check_page", "chromium"]
