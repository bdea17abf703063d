"""The run report of a real fit: its size, the time to write it, and how it looks.

1. The scene simulated as the suite simulates it (999 views, 346x260, cached in ``--cache``),
   fitted with ``hybridneus fit --minutes`` (or ``--run``: an existing run folder of it),
   meshed with ``hybridneus mesh --res 300 --color`` and scored with ``hybridneus eval`` (its
   ``eval.json`` and ``errors.png`` land in the run folder).
2. ``hybridneus report RUN`` timed as a command (Python's start and imports included) and
   ``hybridneus.report.write_report`` timed in a warm process, medians of ``--repeat``.
3. The report opened in headless Chromium (``browser.check_page``, as the browser tests do):
   script errors, whether the plots and the 3D view drew; screenshots of its top and of its
   event windows into ``--images``. Then the documentation site built (``mkdocs build
   --strict``) and its front page shot the same way.

One line to ``benchmarks/results/report.jsonl``.

    python benchmarks/bench_report.py --scene bunny --minutes 15
"""

from __future__ import annotations

import argparse
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import common


def _cli(*args: str) -> str:
    done = subprocess.run([sys.executable, "-m", "hybridneus.cli.app", *args],
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"hybridneus {args[0]}: {done.stderr.strip().splitlines()[-1:]}")
    return done.stdout


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    ap.add_argument("--scene", default="bunny", help="a shared asset or a simulate source")
    ap.add_argument("--assets", type=Path, default=common.REPO.parent / "shared" / "assets")
    ap.add_argument("--minutes", type=float, default=15.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--res", type=int, default=300)
    ap.add_argument("--run", type=Path, help="an existing run folder of the scene (no fit)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench"))
    ap.add_argument("--images", type=Path, default=common.REPO / "docs" / "images")
    common.add_arguments(ap, "report")
    args = ap.parse_args()
    common.check_tree(args)

    import run_suite
    from browser import check_page

    from hybridneus.report import write_report

    assets = run_suite.find_assets(args.assets)
    ns = SimpleNamespace(views=999, width=346, height=260, test_views=8, noise=(0.0, 0.0),
                         cache=args.cache, assets=args.assets)
    data = run_suite.dataset_for(args.scene, assets, ns)
    run = args.run
    if run is None:
        print(f"[report] fitting {args.scene} for {args.minutes:g} min", file=sys.stderr)
        out = _cli("fit", str(data), "--minutes", f"{args.minutes:g}", "--seed",
                   str(args.seed), "--out", str(args.cache / "report-runs"), "--quiet")
        run = Path(re.search(r"^run: (.+) \(step \d+\)$", out, re.M)[1])
    mesh = run / f"mesh_{args.res}.ply"
    if not mesh.is_file():
        _cli("mesh", str(run), "--res", str(args.res), "--color")
    _cli("eval", str(mesh), str(data / "gt_mesh.ply"))

    cold = []
    for _ in range(args.repeat):
        tick = time.perf_counter()
        _cli("report", str(run))
        cold.append(time.perf_counter() - tick)
    write_report(run)  # warm-up: imports, plotly's bundle read
    warm = []
    for _ in range(args.repeat):
        tick = time.perf_counter()
        path = write_report(run)
        warm.append(time.perf_counter() - tick)

    args.images.mkdir(parents=True, exist_ok=True)
    seen = check_page(path, args.images / "report.png", plots=("curves", "mesh-view"),
                      canvases=("mesh-view",))
    views = check_page(path, args.images / "report-views.png", selector="#views",
                       height=1400)
    site = args.cache / "site"
    built = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "-d",
                            str(site)], cwd=common.REPO, capture_output=True, text=True)
    if built.returncode != 0:
        raise SystemExit(f"mkdocs build --strict: {built.stderr.strip()[-1500:]}")
    # wide enough for the site's navigation column, which narrower windows fold away
    front = check_page(site / "index.html", args.images / "site.png", width=1400)

    import json

    from hybridneus.report.figures import VIEWER_FACES
    from hybridneus.report.figures import mesh_figure as _mesh_figure

    _, shown, faces = _mesh_figure(mesh, VIEWER_FACES)
    scores = json.loads((run / "eval.json").read_text())
    scene = (run / "scene.yaml").read_text()
    steps = int(re.search(r"^steps: (\d+)$", scene, re.M)[1])
    record = {"bench": "report", **common.stamp(None), "scene": args.scene,
              "minutes": args.minutes, "seed": args.seed, "steps": steps, "res": args.res,
              "chamfer": round(scores["chamfer"], 5), "mesh_faces": faces,
              "shown_faces": shown, "size_mb": round(path.stat().st_size / 2**20, 2),
              "write_s_command": round(statistics.median(cold), 2),
              "write_s": round(statistics.median(warm), 2),
              "browser": {"errors": seen.errors + views.errors,
                          "site_errors": front.errors,
                          "plots": seen.plots,
                          "canvas_std": round(seen.canvases.get("mesh-view", 0.0), 1)},
              "run": str(run)}
    common.append(args.out, record)
    print(json.dumps(record))


if __name__ == "__main__":
    main()
