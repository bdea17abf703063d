"""A simulated scene through ``hybridneus convert`` and back, fitted both ways; and mono vs colour.

1. Simulate a shared asset at full size (999 views, 346x260, RGGB; cached as the suite caches
   it) and the same scene from a monochrome sensor.
2. Re-express the colour scene as a recording: events in an HDF5 file (DSEC layout, integer
   microseconds plus ``t_offset``) written by h5py, a 200 Hz TUM pose track in a metric world
   frame (rotated, scaled by 0.37 m per unit, shifted) on a clock 0.25 s ahead of the events,
   and a calibration JSON in OpenCV's pixel convention.
3. ``hybridneus convert`` it (the CLI, as a user runs it) with the true threshold and a
   ``--box`` around the object (its bounding box grown by 5% per side in the metric frame,
   as a user would measure it; the simulated scene's preset states its crop too).
4. Fit the original layout, the converted one and the mono scene with the same preset, seed
   and number of steps (fixed steps, so the comparison does not depend on the machine's
   load), mesh each as ``hybridneus mesh`` does, and score every mesh in the original
   scene's frame with the paper's Chamfer protocol.

One line per run goes to ``benchmarks/results/recordings.jsonl``:
``converted_ratio`` (converted / original, the target is at most 1.10) and ``mono_ratio``
(mono / colour, at most 1.3).

    python benchmarks/bench_roundtrip.py --scene bunny --iters 4500
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import common
import numpy as np

T0 = 1000.25  # event-clock seconds of view 0
DT = 0.01  # seconds between views
OFFSET = 0.25  # pose clock = event clock + OFFSET
POSE_HZ = 200.0
SCALE = 0.37
EULER_DEG = (20.0, -35.0, 70.0)
SHIFT = np.array([1.5, -0.3, 2.0])


def datasets(args) -> tuple[Path, Path]:
    """(colour, mono) dataset folders, simulated once into the suite's cache."""
    import run_suite

    from hybridneus.simulate import EventModel, SimulationConfig, simulate_dataset

    ns = SimpleNamespace(views=999, width=346, height=260, test_views=8, noise=(0.0, 0.0),
                         cache=args.cache, assets=args.assets)
    assets = run_suite.find_assets(args.assets)
    colour = run_suite.dataset_for(args.scene, assets, ns)
    mono = run_suite.dataset_folder(args.scene, ns).with_name(colour.name + "-mono")
    if not (mono / "scene.json").is_file():
        print(f"[roundtrip] simulating {mono}", file=sys.stderr, flush=True)
        cfg = SimulationConfig(n_views=999, width=346, height=260, revolutions=8.0,
                               val_views=0, test_views=8, events=EventModel(mosaic="mono"))
        simulate_dataset(str(assets[args.scene]), mono, cfg)
    return colour, mono


def simulated_variant(args, suffix: str, bench: str, **settings) -> Path:
    """The scene at ``args.views`` views and ``args.width`` x ``args.height``, simulated once
    with extra ``SimulationConfig`` settings (a capture's pose errors, unequal thresholds) and
    cached beside the suite's datasets as ``<scene>-<views>v-<width>x<height>-<suffix>``."""
    import run_suite

    from hybridneus.simulate import SimulationConfig, simulate_dataset

    folder = args.cache / (f"{args.scene.replace(':', '-')}-{args.views}v-"
                           f"{args.width}x{args.height}-{suffix}")
    if not (folder / "scene.json").is_file():
        source, extra = run_suite.simulation_source(args.scene,
                                                    run_suite.find_assets(args.assets))
        cfg = SimulationConfig(n_views=args.views, width=args.width, height=args.height,
                               val_views=0, test_views=8, **settings, **extra)
        print(f"[{bench}] simulating {folder}", file=sys.stderr, flush=True)
        simulate_dataset(source, folder, cfg)
    return folder


def write_recording(dataset: Path, out: Path) -> dict:
    """The dataset's train split as an HDF5 event file, a TUM track and a calibration."""
    import h5py
    import hdf5plugin
    from scipy.spatial.transform import Rotation, Slerp

    from hybridneus.data import load_dataset

    ds = load_dataset(dataset, splits="train")
    sp = ds["train"]
    R = Rotation.from_euler("xyz", EULER_DEG, degrees=True).as_matrix()
    c2w = sp.c2w.copy()
    c2w[:, :3, :3] = R @ sp.c2w[:, :3, :3]
    c2w[:, :3, 3] = SCALE * sp.c2w[:, :3, 3] @ R.T + SHIFT
    view_t = T0 + np.arange(sp.n_views) * DT
    n_pose = int(round((view_t[-1] - view_t[0]) * POSE_HZ)) + 1
    tp = T0 + OFFSET + np.arange(n_pose) / POSE_HZ
    tp[-1] = view_t[-1] + OFFSET
    rot = Slerp(view_t + OFFSET, Rotation.from_matrix(c2w[:, :3, :3]))(tp)
    pos = np.stack([np.interp(tp, view_t + OFFSET, c2w[:, k, 3]) for k in range(3)], 1)
    out.mkdir(parents=True, exist_ok=True)
    np.savetxt(out / "poses.txt", np.column_stack([tp, pos, rot.as_quat()]), fmt="%.15g",
               header="timestamp tx ty tz qx qy qz qw")
    common.write_calibration(sp, out / "calib.json")
    ev = sp.events
    t_us = np.round((T0 + ev.t * DT) * 1e6).astype(np.int64)
    base = int(t_us[0]) - 1000
    with h5py.File(out / "events.h5", "w") as f:
        g = f.create_group("events")
        g.create_dataset("t", data=t_us - base, chunks=True, **hdf5plugin.Blosc())
        g.create_dataset("x", data=ev.x.astype(np.uint16), chunks=True, **hdf5plugin.Zstd())
        g.create_dataset("y", data=ev.y.astype(np.uint16), chunks=True, **hdf5plugin.Zstd())
        g.create_dataset("p", data=(ev.p > 0).astype(np.uint8), chunks=True)
        f.create_dataset("t_offset", data=np.int64(base))
    from hybridneus.meshing.convert import load_mesh

    corners = np.asarray(load_mesh(dataset / "gt_mesh.ply").bounds)
    size = corners[1] - corners[0]
    box = SCALE * (corners + np.array([-0.05, 0.05])[:, None] * size) @ R.T + SHIFT
    return {"n_events": len(ev), "threshold": ds.preset.threshold, "views": sp.n_views,
            "mosaic": ds.preset.mosaic, "end": float(view_t[-1]),
            "box": np.concatenate([box.min(0), box.max(0)])}



def add_fit_arguments(ap, iters: int) -> None:
    """The options of a benchmark that simulates one scene at full size and fits it with
    :func:`fit` and :func:`score` (bench_poses, bench_threshold)."""
    ap.add_argument("--scene", default="bunny", help="a shared asset or a simulate source")
    ap.add_argument("--assets", type=Path, default=common.REPO.parent / "shared" / "assets")
    ap.add_argument("--views", type=int, default=999)
    ap.add_argument("--width", type=int, default=346)
    ap.add_argument("--height", type=int, default=260)
    ap.add_argument("--preset", default="fast")
    ap.add_argument("--iters", type=int, default=iters)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--res", type=int, default=300)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench"))

def fit(args, name: str, dataset: Path, sets: tuple[str, ...] = ()) -> Path:
    """Fit with the suite's child job (fixed steps, config overrides ``sets``); the run
    folder."""
    cmd = [sys.executable, str(Path(__file__).with_name("run_suite.py")), "_job",
           "--scene", name, "--dataset", str(dataset), "--preset", args.preset,
           "--minutes", "0", "--iters", str(args.iters), "--threads", str(args.threads),
           "--device", "cpu", "--res", str(args.res), "--curve", "1", "--image-views", "0",
           "--out-runs", str(args.cache / "roundtrip-runs"), "--noise", "[0, 0]",
           "--fit-only", "--set", f"train.seed={args.seed}",
           *[a for v in sets for a in ("--set", v)]]
    print(f"[roundtrip] fitting {name}: {args.preset}, {args.iters} steps", file=sys.stderr,
          flush=True)
    proc = subprocess.run(cmd, stdout=subprocess.PIPE, text=True, check=True)
    return Path(json.loads(proc.stdout.strip().splitlines()[-1])["run"])


def score(args, run_dir: Path, dataset: Path, to_original=None) -> dict:
    """Chamfer of the run's mesh against the original scene's ground truth, in its frame."""
    import suite_jobs

    from hybridneus.config import load_config
    from hybridneus.data.dataset import read_camera_centres
    from hybridneus.evaluation.geometry import chamfer_distance
    from hybridneus.meshing import extract_mesh
    from hybridneus.meshing.convert import load_mesh

    cfg = load_config(run_dir / "config.yaml")
    field, snap = suite_jobs.load_snapshot(cfg, suite_jobs.snapshots(run_dir)[-1])
    mesh = extract_mesh(field, res=args.res, progress=False,
                        cameras=read_camera_centres(dataset / cfg.data.split))
    if to_original is not None:
        mesh.vertices = to_original(np.asarray(mesh.vertices))
    gt = load_mesh(args.gt)
    info = json.loads((run_dir / "fit.json").read_text())
    cd = chamfer_distance(mesh, gt)
    return {"chamfer": round(cd.chamfer, 5), "steps": info["steps"], "fit_s": info["fit_s"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    ap.add_argument("--scene", default="bunny", help="a shared asset")
    ap.add_argument("--assets", type=Path, default=common.REPO.parent / "shared" / "assets")
    ap.add_argument("--preset", default="fast")
    ap.add_argument("--iters", type=int, default=4500)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--res", type=int, default=300)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench"))
    common.add_arguments(ap, "recordings")
    args = ap.parse_args()
    common.check_tree(args)
    from scipy.spatial.transform import Rotation

    from hybridneus.recordings import read_scene_frame

    colour, mono = args.datasets if getattr(args, "datasets", None) else datasets(args)
    args.gt = colour / "gt_mesh.ply"
    rec_dir = args.cache / f"{colour.name}-recording"
    rec = write_recording(colour, rec_dir)
    converted = args.cache / f"{colour.name}-converted"
    if converted.exists():
        shutil.rmtree(converted)
    cli = Path(sys.executable).with_name("hybridneus")
    cmd = [str(cli), "convert", str(rec_dir / "events.h5"), str(converted),
           "--poses", str(rec_dir / "poses.txt"), "--calib", str(rec_dir / "calib.json"),
           "--views", str(rec["views"]), "--start", f"{T0!r}", "--end", f"{rec['end']!r}",
           "--clock-offset", f"{OFFSET!r}", "--sensor", rec["mosaic"],
           "--threshold", f"{rec['threshold']!r}", "--quiet",
           "--box", ",".join(f"{v:.6f}" for v in rec["box"])]
    t = time.perf_counter()
    subprocess.run(cmd, check=True)
    convert_s = time.perf_counter() - t
    frame = read_scene_frame(converted)
    R = Rotation.from_euler("xyz", EULER_DEG, degrees=True).as_matrix()

    def to_original(v: np.ndarray) -> np.ndarray:
        return ((frame.to_recording(v) - SHIFT) @ R) / SCALE

    runs = {"original": (colour, None), "converted": (converted, to_original),
            "mono": (mono, None)}
    scores = {}
    for name, (folder, back) in runs.items():
        run_dir = fit(args, f"{args.scene}-{name}", folder)
        scores[name] = score(args, run_dir, folder, back)
        print(f"[roundtrip] {name}: CD {scores[name]['chamfer']}", file=sys.stderr, flush=True)
    o, c, m = (scores[k]["chamfer"] for k in ("original", "converted", "mono"))
    line = {"bench": "roundtrip", **common.stamp(args.threads), "scene": args.scene,
            "preset": args.preset, "iters": args.iters, "seed": args.seed, "format": "hdf5",
            "n_events": rec["n_events"], "convert_s": round(convert_s, 1),
            "chamfer_original": o, "chamfer_converted": c, "chamfer_mono": m,
            "converted_ratio": round(c / o, 3), "mono_ratio": round(m / o, 3),
            "fits": scores}
    common.append(args.out, line)
    print(json.dumps(line))


if __name__ == "__main__":
    main()
