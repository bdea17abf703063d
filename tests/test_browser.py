"""A run report and the documentation site, opened in headless Chromium.

Marked ``browser`` (left out of the default run): ``python -m pytest -m browser`` needs Debian's
``chromium`` (or ``$CHROMIUM``) and Playwright; CI installs both.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from conftest import scanned_run

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

pytestmark = pytest.mark.browser


def test_a_report_draws_its_plots_and_its_mesh_with_no_script_error(tmp_path):
    from browser import check_page

    from hybridneus.cli.app import app

    run = scanned_run(tmp_path)
    app(["report", str(run)], standalone_mode=False)
    shot = tmp_path / "report.png"
    seen = check_page(run / "report.html", shot, plots=("curves", "mesh-view"),
                      canvases=("mesh-view",), selector="#mesh-view")
    assert seen.errors == []
    assert seen.plots == ["curves", "mesh-view"]
    # a blank WebGL canvas is one flat colour; the shaded mesh spreads its pixel values
    assert seen.canvases["mesh-view"] > 5.0
    assert shot.stat().st_size > 5_000


def test_the_documentation_site_builds_strict_and_opens_clean(tmp_path):
    from browser import check_page

    site = tmp_path / "site"
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d",
                           str(site)], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    for page in ("index.html", "report.html", "api.html", "recordings.html"):
        assert (site / page).is_file(), page
    api = (site / "api.html").read_text()
    assert "write_report" in api and "chamfer_distance" in api  # the reference was generated
    shot = tmp_path / "site.png"
    seen = check_page(site / "index.html", shot)
    assert seen.errors == [] and shot.stat().st_size > 5_000
