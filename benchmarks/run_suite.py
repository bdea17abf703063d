"""Accuracy on the shared assets and on a generated set: presets and seeds, one JSON line a fit.

For every scene the suite simulates a full-size dataset once (cached), then for every seed and
preset spec fits it in a fresh child process (so peak memory is per fit) and scores it with the
paper's Chamfer protocol (benchmarks/suite_jobs.py). The fits are the jobs of a batch
(:mod:`hybridneus.batch`, docs/batch.md): one at a time by default, ``--workers N`` at a time
on a larger machine (one per GPU on a GPU host), or on Ray or Slurm (``--executor``); the
batch's state and each fit's report are kept under ``--out-runs``. Scenes are the shared assets
(``../shared/assets``), generated objects (``--generated N``: N objects of the kinds of
:mod:`hybridneus.simulate.generated` in turn, drawn from ``--generated-seed``; or named as
``generated:<kind>:<seed>``), or both. Fits run in the order scene, seed, preset, so presets
compared in one run are interleaved and share the machine's drift.

    python benchmarks/run_suite.py --seeds 0 1 2                      # assets, fast, 15 min
    python benchmarks/run_suite.py --scenes none --generated 6 --generated-seed 7
    python benchmarks/run_suite.py --scenes bunny --iters 2000 --presets fast eventneus fast-rgb
    python benchmarks/run_suite.py --generated 6 --iters 2000 --presets fast fast+train.lr=0.02
    python benchmarks/run_suite.py --scenes bunny --set priors.hull.enabled=false
    python benchmarks/run_suite.py --scenes generated:bowl:7 --spiral even --iters 2000
    python benchmarks/run_suite.py --seeds 0 1 2 --threads 1 --workers 8   # 8 fits at once

``--spiral`` simulates the training split along another camera path (docs/simulate.md); its
scenes are named apart (``gen-bowl-7-even``), so their lines never mix with the default
path's.

Preset specs: ``fast``, ``quality``, ``eventneus`` (the paper's deep MLPs), ``<preset>-rgb``
(the same model trained on the rendered RGB frames instead of the events: the upper bound),
``<preset>+KEY=VALUE[+KEY=VALUE...]`` (a variant, interleaved with the others of the run);
``--set`` overrides apply to every fit. Both kinds of variant are named apart in the
results. A machine without the meshing libraries (a GPU host) fits with ``--fit-only``;
``--score-runs RUN...`` scores the run folders later where they are. Lines go to
``benchmarks/results/suite.jsonl`` (benchmarks/common.py); ``python benchmarks/report.py``
turns them into docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import common

#: A fit's wall time and budget count from here (before torch is imported), as the CLI's
#: count from its start.
PROCESS_START = time.perf_counter()

DEFAULT_ASSETS = common.REPO.parent / "shared" / "assets"
MESH_EXTS = ("obj", "off", "ply", "glb", "gltf", "stl")
#: The training path of the EventNeRF synthetic scenes, which the suite simulates by default.
DEFAULT_SPIRAL = "seiffert"


def find_assets(assets: Path) -> dict[str, Path]:
    """Asset name -> its mesh file, for every sub-folder of ``assets`` holding one."""
    found = {}
    if not assets.is_dir():
        return found
    for folder in sorted(p for p in assets.iterdir() if p.is_dir()):
        for ext in MESH_EXTS:
            meshes = sorted(folder.glob(f"*.{ext}"))
            if meshes:
                found[folder.name] = meshes[0]
                break
    return found


def scene_name(source: str) -> str:
    """``generated:box:7`` -> ``gen-box-7``; an asset's name as it is."""
    if source.startswith("generated:"):
        kind, _, seed = source.removeprefix("generated:").partition(":")
        return f"gen-{kind}-{seed}"
    return source


def dataset_folder(name: str, args) -> Path:
    """Where the suite caches the dataset of scene ``name`` at its size, noise and path."""
    tag = f"{name}-{args.views}v-{args.width}x{args.height}-t{args.test_views}"
    if args.noise != (0.0, 0.0):
        tag += f"-noise{args.noise[0]:g}-{args.noise[1]:g}"
    if spiral_of(args) != DEFAULT_SPIRAL:
        tag += f"-{spiral_of(args)}"
    return args.cache / tag


def spiral_of(args) -> str:
    """The training path ``args`` ask for (namespaces made before ``--spiral``: the default)."""
    return getattr(args, "spiral", DEFAULT_SPIRAL)


def suite_name(source: str, args) -> str:
    """The name the suite's lines give ``source``: :func:`scene_name`, and the camera path
    when it is not the default one."""
    name = scene_name(source)
    return name if spiral_of(args) == DEFAULT_SPIRAL else f"{name}-{spiral_of(args)}"


def simulation_source(source: str, assets: dict[str, Path]) -> tuple[str, dict]:
    """What ``simulate_dataset`` takes for ``source`` (an asset's mesh file, or the source as
    given), and the ``SimulationConfig`` fields a generated object is made with (its size and
    shading; none for other sources)."""
    if source.startswith("generated:"):
        from hybridneus.simulate.generated import generated_conditions, parse_source

        radius, shading = generated_conditions(*parse_source(source))
        return source, {"object_radius": radius, "shading": shading}
    return (str(assets[source]) if source in assets else source), {}


def dataset_for(source: str, assets: dict[str, Path], args) -> Path:
    """Simulate (once) and return the dataset folder of ``source``; a cached one needs no
    mesh, so a machine without the assets can fit a carried copy."""
    from hybridneus.simulate import NoiseConfig, SimulationConfig, simulate_dataset

    folder = dataset_folder(scene_name(source), args)
    if (folder / "scene.json").is_file():
        return folder
    if not source.startswith("generated:") and source not in assets:
        raise SystemExit(f"{args.assets}: no asset {source!r} (found {sorted(assets)}) and no "
                         f"cached {folder}")
    mesh, extra = simulation_source(source, assets)
    print(f"[suite] simulating {folder}", file=sys.stderr, flush=True)
    cfg = SimulationConfig(
        n_views=args.views, width=args.width, height=args.height, revolutions=8.0,
        val_views=0, test_views=args.test_views,
        noise=NoiseConfig(threshold_sigma=args.noise[0], background_rate=args.noise[1]),
        spiral=spiral_of(args), **extra)
    simulate_dataset(mesh, folder, cfg)
    return folder


def davis346_dataset(source: str, assets: dict[str, Path], cache: Path, duration: float,
                     seed: int = 0) -> Path:
    """Simulate (once) and return ``source`` as a DAVIS346 at indoor light would record it over
    ``duration`` seconds (999 views, 346x260, its thresholds and ``davis346_noise``, whose
    rates depend on the seconds a view takes); cached per duration and seed."""
    from hybridneus.simulate import (
        DAVIS346_THRESHOLD,
        EventModel,
        SimulationConfig,
        davis346_noise,
        simulate_dataset,
    )

    folder = cache / f"{scene_name(source)}-999v-346x260-davis346-{duration:g}s-seed{seed}"
    if (folder / "scene.json").is_file():
        return folder
    mesh, extra = simulation_source(source, assets)
    print(f"[suite] simulating {folder}", file=sys.stderr, flush=True)
    c, o = DAVIS346_THRESHOLD
    simulate_dataset(mesh, folder, SimulationConfig(
        n_views=999, width=346, height=260, revolutions=8.0, val_views=0, test_views=0,
        events=EventModel(threshold=c, polarity_offset=o),
        noise=davis346_noise(duration / 998), seed=seed, **extra))
    return folder


@dataclass(frozen=True)
class SuiteJob:
    """One fit of the suite as a batch job: the ``_job`` child's command line."""

    id: str
    cmd: tuple[str, ...]

    def to_dict(self) -> dict:
        return {"id": self.id, "cmd": list(self.cmd)}


def suite_job(args, name: str, dataset: Path, spec: str, seed: int) -> SuiteJob:
    """The job that fits (and unless ``--fit-only`` scores) one run in a child process."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "_job", "--scene", name,
           "--dataset", str(dataset), "--preset", spec, "--minutes", str(args.minutes or 0),
           "--iters", str(args.iters or 0), "--threads", str(args.threads),
           "--device", args.device, "--res", str(args.res), "--curve", str(args.curve),
           "--image-views", str(args.image_views), "--out-runs", str(args.out_runs),
           "--noise", json.dumps(list(args.noise))]
    if args.fit_only:
        cmd.append("--fit-only")
    for override in [*args.overrides, f"train.seed={seed}"]:
        cmd += ["--set", override]
    safe = "".join(c if c.isalnum() or c in "-_.=" else "_" for c in f"{name}-{spec}-s{seed}")
    return SuiteJob(id=safe, cmd=tuple(cmd))


def fit_and_score(spec: dict, runs: str, threads: int, started=None, env=None) -> dict:
    """A batch job (:func:`hybridneus.batch.job.run_job`'s signature): the ``_job`` child,
    its report kept in ``RUNS/<id>/report.json``; returns the batch's record of it.

    Raises:
        JobFailed, JobInterrupted: as :func:`hybridneus.batch.job.run_command` does.
    """
    from hybridneus.batch.job import run_command

    folder = Path(runs) / spec["id"]
    folder.mkdir(parents=True, exist_ok=True)
    out = run_command(spec["cmd"], "fit", folder / "job.log", started, env)
    report = json.loads(out.strip().splitlines()[-1])
    (folder / "report.json").write_text(json.dumps(report))
    return {"steps": report.get("steps"), "wall_s": report.get("fit_wall_s"),
            "chamfer": report.get("chamfer"), "fscore": report.get("fscore"),
            "run": report.get("run"), "report": str(folder / "report.json")}


def run_jobs(args, jobs: list[SuiteJob]) -> None:
    """The suite's fits through ``hybridneus batch``'s executors (``--workers`` at a time, or
    Ray or Slurm), a result line appended as each ends; a failed fit is reported and skipped,
    so one scene cannot stop a suite."""
    from hybridneus.batch import make_executor, run_batch
    from hybridneus.batch.executors import outcome

    # the children record the command that fitted them, for a line scored later by another one
    os.environ[common.FIT_COMMAND] = os.environ.get(common.FIT_COMMAND) or common.command()
    runs = args.out_runs / time.strftime("suite-%Y%m%d-%H%M%S")
    options = {"num_cpus": args.threads, "num_gpus": 1 if args.device.startswith("cuda") else 0,
               "slurm": {"timeout_min": 24 * 60, "cpus_per_task": args.threads}}
    engine = make_executor(args.executor, runs, args.workers, args.threads, options,
                           task=functools.partial(outcome, job=fit_and_score))

    def done(job_id: str, record_: dict) -> None:
        report = json.loads(Path(record_["report"]).read_text())
        if args.fit_only:
            print(f"[suite] {job_id}: {report['steps']} steps, run {report['run']}",
                  file=sys.stderr, flush=True)
        else:
            record(args, report)

    budget = f"{args.minutes:g} min" if args.minutes else f"{args.iters} steps"
    print(f"[suite] {len(jobs)} fits of {budget} on {args.device}, {args.workers} at a time "
          f"({args.executor}); batch state in {runs}", file=sys.stderr, flush=True)
    rows = run_batch(jobs, runs, engine, progress=False, on_done=done)
    for row in rows:
        if row["status"] != "done":
            print(f"[suite] {row['job']}: {row['error'] or row['status']}; skipped",
                  file=sys.stderr, flush=True)


def record(args, report: dict) -> dict:
    """Append a scored fit to the results file, stamped (benchmarks/common.py)."""
    line = {"bench": "suite", **common.stamp(args.threads, report["device"]), **report}
    common.append(args.out, line)
    cd = report.get("chamfer")
    print(f"[suite] {report['scene']} {report['preset']} seed {report['seed']}: CD "
          f"{cd if cd is None else round(cd, 4)} in {report['steps']} steps",
          file=sys.stderr, flush=True)
    return line


def _job() -> None:
    import suite_jobs

    ap = argparse.ArgumentParser()
    for name in ("--scene", "--dataset", "--preset", "--device"):
        ap.add_argument(name, required=True)
    for name, kind in (("--minutes", float), ("--iters", int), ("--threads", int),
                       ("--res", int), ("--curve", int), ("--image-views", int)):
        ap.add_argument(name, type=kind, required=True)
    ap.add_argument("--out-runs", type=Path, required=True)
    ap.add_argument("--noise", type=json.loads, required=True)
    ap.add_argument("--fit-only", action="store_true")
    ap.add_argument("--set", dest="overrides", action="append", default=[])
    job = ap.parse_args(sys.argv[2:])
    from hybridneus.errors import HybridNeusError

    try:
        run_dir = suite_jobs.fit_run(job, PROCESS_START)
    except HybridNeusError as exc:  # a bad setting or dataset: one line, as the CLI says it
        raise SystemExit(f"error: {exc}") from None
    if job.fit_only:
        report = {**json.loads((run_dir / "fit.json").read_text()), "run": str(run_dir)}
    else:
        report = suite_jobs.score_run(run_dir, job.res, job.image_views)
    print(json.dumps(report))


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "_job":
        _job()
        return
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n".join(__doc__.splitlines()[1:]))
    ap.add_argument("--assets", type=Path, default=DEFAULT_ASSETS)
    ap.add_argument("--scenes", nargs="+",
                    help="asset names and generated:<kind>:<seed> (default: every asset; "
                    "'none' for none)")
    ap.add_argument("--generated", type=int, default=0, metavar="N",
                    help="add N generated objects, the kinds in turn")
    ap.add_argument("--generated-seed", type=int, default=0, help="draws the generated set")
    ap.add_argument("--presets", nargs="+", default=["fast"],
                    help="preset specs: a preset, PRESET-rgb (frames instead of events), "
                    "PRESET+KEY=VALUE[+KEY=VALUE...] (a variant)")
    ap.add_argument("--seeds", nargs="+", type=int, default=[0])
    budget = ap.add_mutually_exclusive_group()
    budget.add_argument("--minutes", type=float, help="fit budget (default 15)")
    budget.add_argument("--iters", type=int, help="fixed steps instead of a budget")
    ap.add_argument("--curve", type=int, default=3, help="points on the CD curve")
    ap.add_argument("--res", type=int, default=300, help="marching-cubes resolution")
    ap.add_argument("--views", type=int, default=999)
    ap.add_argument("--width", type=int, default=346)
    ap.add_argument("--height", type=int, default=260)
    ap.add_argument("--test-views", type=int, default=8, help="test split for PSNR/SSIM")
    ap.add_argument("--image-views", type=int, default=0, help="test views rendered per fit")
    ap.add_argument("--noise", type=lambda s: tuple(float(v) for v in s.split(":")),
                    default=(0.0, 0.0), metavar="SIGMA:RATE",
                    help="sensor noise: threshold sigma : background events per pixel and view")
    ap.add_argument("--spiral", choices=("seiffert", "even", "circle"), default=DEFAULT_SPIRAL,
                    help="camera path of the training split (default: Seiffert's spiral, the "
                    "EventNeRF scenes' path)")
    ap.add_argument("--threads", type=int, default=2, help="torch threads of each fit")
    ap.add_argument("--workers", type=int, default=1,
                    help="fits at a time (hybridneus batch's local executor); timings "
                    "compared across lines need the same count")
    ap.add_argument("--executor", choices=("local", "ray", "slurm"), default="local",
                    help="where the fits run (docs/batch.md)")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/hybridneus-bench"))
    ap.add_argument("--out-runs", type=Path, default=Path("/tmp/hybridneus-bench/suite-runs"))
    ap.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE",
                    help="config override for every fit (the results name the preset with it)")
    ap.add_argument("--fit-only", action="store_true",
                    help="fit and keep each run's snapshots/ and fit.json, score nothing")
    ap.add_argument("--score-runs", nargs="+", type=Path, metavar="RUN",
                    help="score run folders made with --fit-only (datasets looked up in --cache "
                    "by name)")
    common.add_arguments(ap, "suite")
    args = ap.parse_args()
    if args.minutes is None and args.iters is None:
        args.minutes = 15.0
    common.check_tree(args)
    if args.score_runs:
        import suite_jobs

        for run_dir in args.score_runs:
            record(args, suite_jobs.score_run(run_dir, args.res, args.image_views, args.cache))
        return
    assets = find_assets(args.assets)
    sources = list(assets) if args.scenes is None else [s for s in args.scenes if s != "none"]
    if args.generated:
        from hybridneus.simulate.generated import generated_set

        sources += [f"generated:{k}:{s}" for k, s in generated_set(args.generated,
                                                                   args.generated_seed)]
    if not sources:
        raise SystemExit("no scenes: name --scenes, or give --generated N")
    # every dataset before the first fit: a scene that cannot be made should stop the suite
    # now, not when its turn comes hours in
    datasets = {suite_name(s, args): dataset_for(s, assets, args) for s in sources}
    args.out_runs.mkdir(parents=True, exist_ok=True)
    run_jobs(args, [suite_job(args, name, folder, spec, seed)
                    for name, folder in datasets.items()
                    for seed in args.seeds for spec in args.presets])


if __name__ == "__main__":
    main()
