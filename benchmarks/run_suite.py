"""Accuracy versus time on the shared assets: presets side by side, one JSON line per fit.

For every asset folder (default ``../shared/assets`` beside the repository) the suite
simulates a full-size dataset once (cached), then for every preset spec fits it for the
budget in a fresh subprocess (so peak memory is per fit), keeping snapshots of the field
along the way. Each snapshot is meshed at ``--res`` and scored with the paper's Chamfer
protocol, which gives the CD-versus-time curve; the final field also gets accuracy,
completeness, F-score, SDF-MAE, mesh time and, where the dataset has a test split with
frames, PSNR/SSIM after the log-space colour correction.

Preset specs: ``fast``, ``quality``, ``eventneus`` (the paper's deep MLPs), and ``<preset>-rgb``
(the same model trained on the rendered RGB frames instead of the events: the upper bound).

    python benchmarks/run_suite.py                                  # all assets, 15 min each
    python benchmarks/run_suite.py --scenes bunny --minutes 5 --presets fast fast-rgb
    python benchmarks/run_suite.py --noise-sweep bunny --minutes 5  # sensor-noise sweep
    python benchmarks/run_suite.py --report                         # tables + plots only

A machine without the meshing libraries (a GPU host) can fit with ``--fit-only``; each run
folder then holds ``fit.json`` and ``snapshots/``, and ``--score-runs RUN...`` scores them here
(the dataset found by name under ``--cache``).

Results are appended to ``benchmarks/results/suite.jsonl`` (earlier lines are kept, so
progress stays visible); ``--report`` prints markdown tables of the latest line per
(scene, preset, budget, noise, device) and writes the CD-versus-time plots to ``docs/benchmarks/``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import functools
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
DEFAULT_ASSETS = REPO.parent / "shared" / "assets"
DEFAULT_OUT = REPO / "benchmarks" / "results" / "suite.jsonl"
DEFAULT_PLOTS = REPO / "docs" / "benchmarks"
MESH_EXTS = ("obj", "off", "ply", "glb", "gltf", "stl")
# Sensor-noise levels of --noise-sweep: (threshold_sigma in log units, background events per
# pixel per frame interval).
NOISE_LEVELS = ((0.0, 0.0), (0.03, 0.02), (0.06, 0.05), (0.1, 0.1))


def preset_spec(spec: str) -> tuple[str, list[str]]:
    """``fast`` -> ("fast", []); ``fast-rgb`` -> ("fast", ["train.supervision=rgb"])."""
    if spec.endswith("-rgb"):
        return spec.removesuffix("-rgb"), ["train.supervision=rgb"]
    return spec, []


def find_scenes(assets: Path) -> dict[str, Path]:
    """Asset name -> its mesh file, for every sub-folder of ``assets`` holding one."""
    scenes = {}
    for folder in sorted(p for p in assets.iterdir() if p.is_dir()):
        for ext in MESH_EXTS:
            found = sorted(folder.glob(f"*.{ext}"))
            if found:
                scenes[folder.name] = found[0]
                break
    return scenes


def dataset_folder(scene: str, args, noise: tuple[float, float]) -> Path:
    """Where the suite caches the dataset of ``scene`` at its size and noise level."""
    tag = f"{scene}-{args.views}v-{args.width}x{args.height}-t{args.test_views}"
    if noise != (0.0, 0.0):
        tag += f"-noise{noise[0]:g}-{noise[1]:g}"
    return args.cache / tag


def dataset_for(scene: str, mesh: Path | None, args, noise: tuple[float, float]) -> Path:
    """Simulate (once) and return the dataset folder of ``scene`` at the suite's size.

    A dataset already in ``args.cache`` needs no mesh (``mesh`` None): a machine without the
    assets or the simulator's ray caster can fit a carried copy.
    """
    from hybridneus.simulate import NoiseConfig, SimulationConfig, simulate_dataset

    folder = dataset_folder(scene, args, noise)
    if not (folder / "scene.json").is_file():
        print(f"[suite] simulating {folder}", file=sys.stderr, flush=True)
        cfg = SimulationConfig(
            n_views=args.views, width=args.width, height=args.height, revolutions=8.0,
            val_views=0, test_views=args.test_views,
            noise=NoiseConfig(threshold_sigma=noise[0], background_rate=noise[1]),
        )
        simulate_dataset(str(mesh), folder, cfg)
    return folder


# --------------------------------------------------------------------------- one fit (child)


def _score_field(field, gt, res: int, cameras=None) -> dict:
    """Mesh ``field`` as ``hybridneus mesh`` does (with ``cameras``, the unseen pockets
    filled) and score it against ``gt``."""
    from hybridneus.evaluation.geometry import chamfer_distance
    from hybridneus.meshing import extract_mesh

    t = time.perf_counter()
    mesh = extract_mesh(field, res=res, progress=False, cameras=cameras)
    mesh_s = time.perf_counter() - t
    if len(mesh.faces) == 0:
        return {"chamfer": None, "faces": 0, "mesh_s": round(mesh_s, 2)}, mesh
    cd = chamfer_distance(mesh, gt)
    return {"chamfer": cd.chamfer, "accuracy": cd.accuracy, "completeness": cd.completeness,
            "fscore": cd.fscore, "faces": int(len(mesh.faces)), "mesh_s": round(mesh_s, 2)}, mesh


def _image_metrics(field, dataset, n_views: int) -> dict:
    """Mean colour-corrected PSNR/SSIM over ``n_views`` test cameras (foreground pixels)."""
    from hybridneus.evaluation import color_corrected_psnr_ssim
    from hybridneus.evaluation.images import foreground_mask, read_frame
    from hybridneus.rendering.views import inference_sampler, render_view

    split = dataset.splits.get("test")
    if split is None or split.rgb_paths is None or n_views <= 0:
        return {}
    sampler = inference_sampler(field)
    psnrs, ssims = [], []
    for i in np.unique(np.linspace(0, split.n_views - 1, min(n_views, split.n_views)).round()):
        i = int(i)
        gt = read_frame(split.rgb_paths[i], split.width, split.height)
        if gt is None:
            continue
        mask = foreground_mask(gt, dataset.preset.background)
        if mask.any():
            img = render_view(field, split.intrinsics[i], split.distortion[i], split.c2w[i],
                              split.width, split.height, sampler)
            m = color_corrected_psnr_ssim(img.color, gt, mask)
            psnrs.append(m.psnr)
            ssims.append(m.ssim)
    if not psnrs:
        return {}
    return {"psnr": float(np.mean(psnrs)), "ssim": float(np.mean(ssims))}


def fit_run(args) -> Path:
    """Fit one (dataset, preset spec, budget); return its run folder.

    Besides the trainer's own files the run folder gets ``snapshots/`` (the field along the
    way and at the end, each file self-contained: weights, step, schedule length, scene) and
    ``fit.json`` (what was fitted, where, for how long). That is all :func:`score_run` needs,
    so fits made on another machine (a GPU host without the meshing libraries) can be scored
    here from those files alone.
    """
    import torch

    from hybridneus.api import fit
    from hybridneus.fileio import atomic_path

    torch.set_num_threads(args.threads)
    preset, overrides = preset_spec(args.preset)
    budget = args.minutes * 60.0
    marks = [budget * k / args.curve for k in range(1, args.curve)]

    def save(trainer, snap_dir: Path) -> None:
        path = snap_dir / f"t{trainer.elapsed:07.1f}-s{trainer.step}.pt"
        with atomic_path(path) as tmp:
            torch.save({"model": trainer.field.state_dict(), "elapsed": trainer.elapsed,
                        "step": trainer.step, "total_steps": trainer.total_steps,
                        "scene": dict(trainer.scene)}, tmp)

    # The run folder is named by fit() once training starts; the snapshots wait beside it.
    staging = args.out_runs / f".snapshots-{os.getpid()}"
    last: list = []

    def snapshot(trainer, logs) -> None:
        # The save is not counted in the budget (the trainer's clock only counts its steps).
        last[:] = [trainer]
        if marks and trainer.elapsed >= marks[0]:
            marks.pop(0)
            save(trainer, staging)

    t0 = time.perf_counter()
    field = fit(
        args.dataset, preset, [snapshot],
        overrides=[f"train.minutes={args.minutes}", "train.iters=100000000",
                   f"train.threads={args.threads}", "train.preview_every=0", *overrides,
                   *args.overrides],
        out=args.out_runs, device=args.device, progress=False,
    )
    fit_wall = time.perf_counter() - t0
    run_dir = Path(field.run_dir)
    trainer = last[0]
    save(trainer, staging)
    staging.rename(run_dir / "snapshots")
    info = {
        # A fit with --set overrides is a variant of its preset, named apart in the results.
        "scene": args.scene, "preset": " ".join([args.preset, *args.overrides]),
        "overrides": args.overrides, "minutes": args.minutes, "noise": args.noise,
        "dataset": str(Path(args.dataset).resolve()),
        "device": args.device, "device_name": _device_name(args.device),
        "threads": args.threads, "steps": int(trainer.step),
        "fit_s": round(float(trainer.elapsed), 1), "fit_wall_s": round(fit_wall, 1),
        "inv_s": round(float(field.inv_s().detach()), 1),
        "fit_peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
    }
    with atomic_path(run_dir / "fit.json") as tmp:
        tmp.write_text(json.dumps(info, indent=1))
    return run_dir


def _device_name(device: str) -> str:
    import torch

    if device.startswith("cuda") and torch.cuda.is_available():
        return torch.cuda.get_device_name(torch.device(device))
    return f"{os.cpu_count()} cpus"


def score_run(run_dir: Path, res: int, image_views: int, cache: Path | None = None) -> dict:
    """Score a run folder made by :func:`fit_run`: the CD curve, the final field's metrics.

    ``cache``: where to look for the dataset (by folder name) when the path recorded in
    ``fit.json`` does not exist here (a fit made on another machine).
    """
    import torch

    from hybridneus.config import load_config
    from hybridneus.data import load_dataset
    from hybridneus.data.dataset import read_camera_centres
    from hybridneus.evaluation.geometry import sdf_mae
    from hybridneus.meshing.convert import load_mesh, save_mesh
    from hybridneus.training.runs import build_field

    for name in ("fit.json", "config.yaml"):
        if not (run_dir / name).is_file():
            raise SystemExit(f"{run_dir / name}: missing (not a run folder made by the suite)")
    info = json.loads((run_dir / "fit.json").read_text())
    dataset = Path(info["dataset"])
    if not (dataset / "gt_mesh.ply").is_file() and cache is not None:
        dataset = cache / dataset.name
    if not (dataset / "gt_mesh.ply").is_file():
        raise SystemExit(f"{run_dir / 'fit.json'}: dataset {dataset.name} not found here")
    cfg = load_config(run_dir / "config.yaml")
    gt = load_mesh(dataset / "gt_mesh.ply")
    snaps = sorted((run_dir / "snapshots").glob("t*.pt"),
                   key=lambda p: float(p.name[1:].split("-")[0]))
    if not snaps:
        raise SystemExit(f"{run_dir}: no snapshots/ to score")

    first = torch.load(snaps[0], map_location="cpu", weights_only=True)

    def load(path: Path):
        snap = first if path == snaps[0] else torch.load(path, map_location="cpu",
                                                          weights_only=True)
        f = build_field(cfg, snap["scene"])
        f.load_state_dict(snap["model"])
        f.update_step(int(snap["step"]), int(snap["total_steps"]))
        return f.eval(), snap

    # The untrained field (same seed, same construction as the trainer's) starts the curve.
    torch.manual_seed(cfg.train.seed)
    # Meshes are scored as `hybridneus mesh` makes them: the pockets no camera saw filled.
    cameras = read_camera_centres(dataset / cfg.data.split)
    initial, _ = _score_field(build_field(cfg, first["scene"]).eval(), gt, res, cameras)
    curve = [[0.0, 0, initial["chamfer"]]]
    for path in snaps[:-1]:
        f, snap = load(path)
        score, _ = _score_field(f, gt, res, cameras)
        curve.append([round(float(snap["elapsed"]), 1), int(snap["step"]), score["chamfer"]])
    field, snap = load(snaps[-1])
    final, mesh = _score_field(field, gt, res, cameras)
    curve.append([round(float(snap["elapsed"]), 1), int(snap["step"]), final["chamfer"]])
    plain, _ = _score_field(field, gt, res)  # as scored before session 15, for comparison
    report = {**info, "run": str(run_dir), "res": res, **final, "curve": curve,
              "chamfer_unfilled": plain["chamfer"]}
    if mesh is not None and len(mesh.faces):
        save_mesh(mesh, run_dir / "mesh.ply")
        report["sdf_mae"] = float(sdf_mae(mesh, gt).mae)
        report.update(_image_metrics(field, load_dataset(dataset), image_views))
    # Fitting alone (fit_peak_rss_mb, from fit.json), then fitting and scoring (rendering test
    # views with normals is the larger of the two for deep MLPs).
    report["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    return report


# --------------------------------------------------------------------------- driver


@functools.cache
def _git_commit() -> str:
    """HEAD when first asked (the suite asks at start, so a commit made during a fit is not
    credited with it), with ``+dirty`` if the code had uncommitted changes then."""
    git = ["git", "-C", str(REPO)]
    try:
        head = subprocess.run([*git, "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, check=True).stdout.strip()
        changed = subprocess.run(
            [*git, "status", "--porcelain", "--untracked-files=no", "--", "hybridneus",
             "grids", "cli", "benchmarks", ":(exclude)benchmarks/results"],
            capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("+dirty" if changed else "")


def launch(
    args, scene: str, dataset: Path, spec: str, noise: tuple[float, float]
) -> dict | None:
    """Run one fit (and, unless ``--fit-only``, its scoring) in a child process.

    A scored fit is appended to ``args.out``. A failed fit is reported on stderr and skipped
    (None), so one scene cannot stop a suite.
    """
    cmd = [sys.executable, str(Path(__file__).resolve()), "_job", "--scene", scene,
           "--dataset", str(dataset), "--preset", spec, "--minutes", str(args.minutes),
           "--threads", str(args.threads), "--device", args.device, "--res", str(args.res),
           "--curve", str(args.curve), "--image-views", str(args.image_views),
           "--out-runs", str(args.out_runs), "--noise", json.dumps(list(noise))]
    if args.fit_only:
        cmd.append("--fit-only")
    for override in args.overrides:
        cmd += ["--set", override]
    print(f"[suite] {scene} {spec} {args.minutes:g} min noise={noise} on {args.device}",
          file=sys.stderr, flush=True)
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, text=True)
    if proc.returncode != 0:
        print(f"[suite] {scene} {spec}: the fit failed (exit {proc.returncode}); skipped",
              file=sys.stderr, flush=True)
        return None
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    if args.fit_only:
        print(f"[suite] {scene} {spec}: {report['steps']} steps, run {report['run']}",
              file=sys.stderr, flush=True)
        return report
    return record(args, report)


def record(args, report: dict) -> dict:
    """Append a scored fit to the results file (with date and commit) and say its CD."""
    report.update(date=dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
                  commit=_git_commit())
    args.out.parent.mkdir(parents=True, exist_ok=True)
    with open(args.out, "a") as fh:
        fh.write(json.dumps(report) + "\n")
    cd = report.get("chamfer")
    print(f"[suite] {report['scene']} {report['preset']} on {report['device']}: CD "
          f"{cd if cd is None else round(cd, 4)} in {report['steps']} steps",
          file=sys.stderr, flush=True)
    return report


def read_results(path: Path) -> list[dict]:
    """The latest line per (scene, preset, minutes, noise, device) of a results file."""
    latest: dict[tuple, dict] = {}
    if path.is_file():
        for line in path.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                key = (r["scene"], r["preset"], r["minutes"], tuple(r["noise"]), r["device"])
                latest[key] = r
    return list(latest.values())


def _fmt(v, digits: int = 4) -> str:
    return "-" if v is None else f"{v:.{digits}f}" if isinstance(v, float) else str(v)


def report_tables(results: list[dict]) -> str:
    """Markdown: one table of all fits, means per preset, and the issue's three ratios."""
    clean = [r for r in results if tuple(r["noise"]) == (0.0, 0.0)]
    lines = ["| scene | preset | device | min | steps | CD | acc | comp | F@1% | SDF-MAE | PSNR |"
             " SSIM | mesh s | peak RSS MB (fit) |", "|" + "---|" * 14]
    for r in sorted(clean, key=lambda r: (r["scene"], r["device"], r["minutes"], r["preset"])):
        lines.append(
            f"| {r['scene']} | {r['preset']} | {r['device']} | {r['minutes']:g} | {r['steps']} | "
            f"{_fmt(r.get('chamfer'))} | {_fmt(r.get('accuracy'))} | "
            f"{_fmt(r.get('completeness'))} | {_fmt(r.get('fscore'), 3)} | "
            f"{_fmt(r.get('sdf_mae'))} | {_fmt(r.get('psnr'), 2)} | {_fmt(r.get('ssim'), 3)} | "
            f"{_fmt(r.get('mesh_s'), 1)} | {r.get('fit_peak_rss_mb', '-')} |")
    lines += ["", "| preset | device | min | scenes | mean CD |", "|---|---|---|---|---|"]
    groups: dict[tuple, list[float]] = {}
    for r in clean:
        if r.get("chamfer") is not None:
            groups.setdefault((r["preset"], r["device"], r["minutes"]), []).append(r["chamfer"])
    for (preset, device, minutes), cds in sorted(groups.items()):
        lines.append(f"| {preset} | {device} | {minutes:g} | {len(cds)} | {np.mean(cds):.4f} |")
    lines += ["", "| scene | device | min | CD events / CD rgb (goal <= 1.3) | time for the "
              "hybrid to reach the eventneus CD / eventneus time (goal <= 0.1) |",
              "|---|---|---|---|---|"]
    by = {(r["scene"], r["device"], r["minutes"], r["preset"]): r for r in clean}
    for scene, device, minutes in sorted({(r["scene"], r["device"], r["minutes"]) for r in clean}):
        ev = by.get((scene, device, minutes, "fast"))
        rgb = by.get((scene, device, minutes, "fast-rgb"))
        deep = by.get((scene, device, minutes, "eventneus"))
        ratio = "-"
        if ev and rgb and ev.get("chamfer") and rgb.get("chamfer"):
            ratio = f"{ev['chamfer'] / rgb['chamfer']:.2f}"
        reach = "-"
        if ev and deep and deep.get("chamfer") is not None:
            hits = [t for t, _, cd in ev["curve"] if cd is not None and cd <= deep["chamfer"]]
            reach = f"{min(hits) / deep['fit_s']:.3f}" if hits else "not reached"
        lines.append(f"| {scene} | {device} | {minutes:g} | {ratio} | {reach} |")
    noisy = [r for r in results if tuple(r["noise"]) != (0.0, 0.0)]
    if noisy:
        lines += ["", "Noise sweep:", "",
                  "| scene | preset | device | min | threshold sigma | background rate | CD |",
                  "|---|---|---|---|---|---|---|"]
        base = [r for r in clean if any(n["scene"] == r["scene"] and n["preset"] == r["preset"]
                                        and n["minutes"] == r["minutes"]
                                        and n["device"] == r["device"] for n in noisy)]
        for r in sorted(base + noisy, key=lambda r: (r["scene"], r["preset"], r["noise"])):
            lines.append(f"| {r['scene']} | {r['preset']} | {r['device']} | {r['minutes']:g} | "
                         f"{r['noise'][0]:g} | {r['noise'][1]:g} | {_fmt(r.get('chamfer'))} |")
    return "\n".join(lines)


_COLOURS = ((200, 60, 0), (0, 120, 220), (0, 150, 0), (150, 0, 150), (0, 0, 0),
            (0, 170, 200), (120, 120, 0), (200, 0, 90), (90, 60, 30), (130, 130, 130))


def _plot_scene(scene: str, runs: list[dict]) -> np.ndarray:
    """Chamfer (log scale) against fit seconds, a line and a legend entry per run."""
    import cv2

    w, h, pad, legend = 860, 360, 50, 230
    img = np.full((h, w, 3), 255, np.uint8)
    right = w - legend  # the plot's right edge; the legend lives beyond it
    pts = [(t, cd) for r in runs for t, _, cd in r["curve"] if cd]
    # a fit that lost its surface has only the initial sphere's point, at t = 0
    t1 = max([t for t, _ in pts] + [1.0]) * 1.05
    cds = [c for _, c in pts] or [0.015]
    y0, y1 = np.log10(min(cds)) - 0.05, np.log10(max(cds)) + 0.05

    def xy(t: float, cd: float) -> tuple[int, int]:
        return (int(pad + t / t1 * (right - 2 * pad)),
                int(h - pad - (np.log10(cd) - y0) / (y1 - y0) * (h - 2 * pad)))

    font, black = cv2.FONT_HERSHEY_SIMPLEX, (0, 0, 0)
    cv2.rectangle(img, (pad, pad), (right - pad, h - pad), (180, 180, 180), 1)
    for cd in (0.006, 0.01, 0.015, 0.02, 0.03, 0.05, 0.1, 0.2):
        if y0 <= np.log10(cd) <= y1:
            _, y = xy(0, cd)
            cv2.line(img, (pad - 4, y), (pad, y), black, 1)
            cv2.putText(img, f"{cd:g}", (4, y + 4), font, 0.35, black, 1)
            if cd == 0.015:  # the goal
                cv2.line(img, (pad, y), (right - pad, y), (200, 200, 200), 1)
    for k, r in enumerate(sorted(runs, key=lambda r: (r["preset"], r["device"], r["minutes"]))):
        colour = _COLOURS[k % len(_COLOURS)]
        poly = [xy(t, cd) for t, _, cd in r["curve"] if cd]
        for p in poly:
            cv2.circle(img, p, 3, colour, -1, cv2.LINE_AA)
        if len(poly) > 1:
            cv2.polylines(img, [np.array(poly, np.int32)], False, colour, 1, cv2.LINE_AA)
        label = f"{r['preset']} {r['device']} ({r['minutes']:g} min)"
        cv2.putText(img, label, (right - pad + 20, pad + 16 + 16 * k), font, 0.45, colour, 1,
                    cv2.LINE_AA)
    cv2.putText(img, f"{scene}: Chamfer (log) vs fit seconds (0 to {t1:.0f} s)",
                (pad, pad - 12), font, 0.45, black, 1, cv2.LINE_AA)
    return img


def plot_curves(results: list[dict], folder: Path) -> list[Path]:
    """One PNG per scene (``suite-<scene>.png``): CD against fit seconds per preset.

    Presets as shipped only: ``--set`` variants are in the tables, not in the plots.
    """
    import cv2

    from hybridneus.fileio import atomic_path

    written = []
    for scene in sorted({r["scene"] for r in results}):
        runs = [r for r in results if r["scene"] == scene and tuple(r["noise"]) == (0.0, 0.0)
                and not r.get("overrides")]
        if not any(cd for r in runs for _, _, cd in r["curve"]):
            continue
        ok, buf = cv2.imencode(".png", _plot_scene(scene, runs))
        path = folder / f"suite-{scene}.png"
        folder.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as tmp:
            tmp.write_bytes(buf.tobytes())
        written.append(path)
    return written


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "_job":
        ap = argparse.ArgumentParser()
        for name in ("--scene", "--dataset", "--preset", "--device"):
            ap.add_argument(name, required=True)
        for name, kind in (("--minutes", float), ("--threads", int), ("--res", int),
                           ("--curve", int), ("--image-views", int)):
            ap.add_argument(name, type=kind, required=True)
        ap.add_argument("--out-runs", type=Path, required=True)
        ap.add_argument("--noise", type=json.loads, required=True)
        ap.add_argument("--fit-only", action="store_true")
        ap.add_argument("--set", dest="overrides", action="append", default=[])
        job = ap.parse_args(sys.argv[2:])
        run_dir = fit_run(job)
        if job.fit_only:
            report = {**json.loads((run_dir / "fit.json").read_text()), "run": str(run_dir)}
        else:
            report = score_run(run_dir, job.res, job.image_views)
        print(json.dumps(report))
        return

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    ap.add_argument("--assets", type=Path, default=DEFAULT_ASSETS)
    ap.add_argument("--scenes", nargs="+", help="asset names (default: every asset folder)")
    ap.add_argument("--presets", nargs="+", default=["fast", "eventneus", "fast-rgb"])
    ap.add_argument("--minutes", type=float, default=15.0, help="fit budget per run")
    ap.add_argument("--curve", type=int, default=5, help="points on the CD-vs-time curve")
    ap.add_argument("--res", type=int, default=300, help="marching-cubes resolution")
    ap.add_argument("--views", type=int, default=999)
    ap.add_argument("--width", type=int, default=346)
    ap.add_argument("--height", type=int, default=260)
    ap.add_argument("--test-views", type=int, default=8, help="test split for PSNR/SSIM")
    ap.add_argument("--image-views", type=int, default=4, help="test views rendered per fit")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench"))
    ap.add_argument("--out-runs", type=Path, default=Path("/tmp/hybridneus-bench/suite-runs"))
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON-lines results file")
    ap.add_argument("--plots", type=Path, default=DEFAULT_PLOTS)
    ap.add_argument("--noise-sweep", metavar="SCENE",
                    help="instead of the presets grid: fit SCENE with the first preset at "
                    f"each noise level {NOISE_LEVELS}")
    ap.add_argument("--noise-levels", nargs="+", metavar="SIGMA:RATE",
                    help="noise levels of the sweep, threshold sigma : background rate "
                    "(default: every level of NOISE_LEVELS)")
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="config override for every fit (the results name the preset with it)")
    ap.add_argument("--report", action="store_true", help="only print tables, write plots")
    ap.add_argument("--fit-only", action="store_true",
                    help="fit and keep each run's snapshots/ and fit.json, score nothing (for a "
                    "machine without the meshing libraries; score them later with --score-runs)")
    ap.add_argument("--score-runs", nargs="+", type=Path, metavar="RUN",
                    help="score run folders made with --fit-only (datasets looked up in --cache "
                    "by name) and append them to the results")
    args = ap.parse_args()
    _git_commit()

    if args.score_runs:
        for run_dir in args.score_runs:
            record(args, score_run(run_dir, args.res, args.image_views, args.cache))
    elif not args.report:
        scenes = find_scenes(args.assets) if args.assets.is_dir() else {}
        wanted = [args.noise_sweep] if args.noise_sweep else (args.scenes or list(scenes))
        if not wanted:
            raise SystemExit(f"{args.assets}: no asset folder with a mesh")
        levels: tuple[tuple[float, float], ...] = ((0.0, 0.0),)
        if args.noise_sweep:
            levels = NOISE_LEVELS
            if args.noise_levels:
                levels = tuple(tuple(float(v) for v in lv.split(":")) for lv in args.noise_levels)
        specs = args.presets[:1] if args.noise_sweep else args.presets
        # Before any fit: a scene that can be neither simulated nor found in the cache would
        # otherwise stop the suite only when its turn comes, hours in.
        for scene in wanted:
            for noise in levels:
                folder = dataset_folder(scene, args, noise)
                if scene not in scenes and not (folder / "scene.json").is_file():
                    raise SystemExit(f"{args.assets}: no asset {scene!r} (found {sorted(scenes)})"
                                     f" and no cached {folder}")
        for scene in wanted:
            for noise in levels:
                data = dataset_for(scene, scenes.get(scene), args, noise)
                for spec in specs:
                    launch(args, scene, data, spec, noise)
    if args.fit_only:
        return
    results = read_results(args.out)
    print(report_tables(results))
    for path in plot_curves(results, args.plots):
        print(f"[suite] wrote {path}", file=sys.stderr)


if __name__ == "__main__":
    main()
