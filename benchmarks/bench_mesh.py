"""Mesh extraction time: analytic field vs an untrained default HybridField, with/without colour.

    python benchmarks/bench_mesh.py                 # res 300 and 512, both fields
    python benchmarks/bench_mesh.py --quick         # res 128 only, one repeat
    python benchmarks/bench_mesh.py --res 300 512 1024 --fields analytic
    python benchmarks/bench_mesh.py --run runs/bunny-...   # a trained run (the real target)

The HybridField stands in for a trained one: same architecture and cost per query (the
"fast" preset); its geometric initialisation is a sphere of radius 0.9 x crop radius, cut
flat by the real-scene crop's top, i.e. an object filling the crop like a real scene's.
Timings are medians over --repeats runs after one warm-up; other processes on the machine
make them noisy.
"""

from __future__ import annotations

import argparse
import statistics
import time

import common
import torch


def make_field(kind: str, run: str | None = None):
    """(field, crop or None) for ``analytic``, ``hybrid`` (untrained) or ``trained`` (``run``)."""
    from hybridneus.meshing import CropVolume
    from hybridneus.model.analytic import TorusField

    if kind == "trained":
        from hybridneus.training.runs import load_field

        field = load_field(run, device="cpu")
        return field, CropVolume(*(float(v) for v in field.crop))
    if kind == "analytic":
        return TorusField(0.5, 0.2), None
    from hybridneus.config import preset_config
    from hybridneus.model.field import HybridField

    torch.manual_seed(0)  # the hash tables' random init shapes the surface a little
    cfg = preset_config("fast")
    crop = (0.25, -0.35, 0.15)
    field = HybridField(cfg.grid, cfg.field, background=(0.62, 0.62, 0.62), crop=crop).eval()
    return field, CropVolume(*crop)


def time_once(field, crop, res: int, color: bool) -> tuple[float, dict, int, float]:
    """(seconds, stage times, faces, active fraction) of one extract_mesh call."""
    from hybridneus.meshing import ExtractionStats, extract_mesh

    stats = ExtractionStats()
    start = time.perf_counter()
    mesh = extract_mesh(field, res=res, crop=crop, color=color, progress=False, stats=stats)
    return time.perf_counter() - start, dict(stats.times), len(mesh.faces), stats.active_fraction


def query_cost(field, n: int = 2**16) -> tuple[float, float]:
    """Microseconds per point of ``field.sdf`` and of ``field.color`` (median of 3)."""
    pts = (torch.rand(n, 3) - 0.5) * 0.5
    dirs = torch.nn.functional.normalize(torch.randn(n, 3), dim=-1)
    out = []
    for fn in (lambda: field.sdf(pts), lambda: field.color(pts, dirs)):
        times = []
        for _ in range(3):
            start = time.perf_counter()
            with torch.no_grad():
                fn()
            times.append(time.perf_counter() - start)
        out.append(1e6 * statistics.median(times) / n)
    return out[0], out[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--res", type=int, nargs="+", default=[300, 512])
    parser.add_argument("--fields", nargs="*", default=["analytic", "hybrid"])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2, help="torch CPU threads")
    parser.add_argument("--quick", action="store_true", help="res 128, one repeat")
    parser.add_argument("--run", help="a trained run folder: time its field (adds 'trained')")
    common.add_arguments(parser, "mesh")
    args = parser.parse_args()
    common.check_tree(args)
    if args.run:
        args.fields = [*args.fields, "trained"] if "trained" not in args.fields else args.fields
    if args.quick:
        args.res, args.repeats = [128], 1
    torch.set_num_threads(args.threads)
    print(f"torch threads {torch.get_num_threads()}; median of {args.repeats} after a warm-up")
    print("| field | res | colour | seconds | faces | evaluated |", end="")
    print(" coarse | fine | MC | post | colour |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for kind in args.fields:
        field, crop = make_field(kind, args.run)
        time_once(field, crop, 64, True)  # warm-up (imports, allocator, thread pool)
        sdf_us, color_us = query_cost(field)
        print(f"<!-- {kind}: sdf {sdf_us:.2f} us/point, color {color_us:.2f} us/point -->")
        for res in args.res:
            for color in (False, True):
                runs = [time_once(field, crop, res, color) for _ in range(args.repeats)]
                seconds = statistics.median(r[0] for r in runs)
                t = runs[0][1]
                print(
                    f"| {kind} | {res} | {'yes' if color else 'no'} | {seconds:.2f} | "
                    f"{runs[0][2]} | {100 * runs[0][3]:.1f}% | {t.get('coarse', 0):.2f} | "
                    f"{t.get('fine_eval', 0):.2f} | {t.get('marching_cubes', 0):.2f} | "
                    f"{t.get('postprocess', 0):.2f} | {t.get('color', 0):.2f} |",
                    flush=True,
                )
                common.append(args.out, {
                    "bench": "mesh", "field": kind, "res": res, "color": color,
                    "seconds": round(seconds, 3), "faces": runs[0][2],
                    "phases_s": {k: round(v, 3) for k, v in t.items()},
                    **common.stamp(torch.get_num_threads())})


if __name__ == "__main__":
    main()
