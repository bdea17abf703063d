"""One fit of the accuracy suite and its scoring, each run in a child process of run_suite.py.

:func:`fit_run` trains and keeps snapshots of the field along the way (``snapshots/``) plus
``fit.json``; :func:`score_run` needs nothing else, so a fit made on another machine (a GPU
host without the meshing libraries) is scored here from those files alone. Meshes are scored
by the paper's Chamfer protocol as ``hybridneus mesh`` makes them (``res`` points across the
crop's box, unseen pockets filled, cavities removed), and also without each of those two
clean-ups, which prices them without another fit. The final mesh is also scored by
EventNeuS's published protocol (``chamfer_eventneus``), and each line carries both
protocols' floors for its scene (the ground truth against a second sampling of itself). What
Chamfer mixes is also scored apart: the RMS distance to the ground truth's flat faces (at each
snapshot too, ``plane_curve``), each part's recall and the farthest connected part of the mesh.
"""

from __future__ import annotations

import json
import os
import resource
import time
from pathlib import Path

import common
import numpy as np


def preset_spec(spec: str) -> tuple[str, list[str]]:
    """A preset and its overrides: ``fast`` -> ("fast", []); ``fast-rgb`` -> ("fast",
    ["train.supervision=rgb"]); ``fast+k=v+k2=v2`` -> ("fast", ["k=v", "k2=v2"]), so that
    variants compared in one suite run are interleaved with their preset."""
    name, *overrides = spec.split("+")
    if name.endswith("-rgb"):
        return name.removesuffix("-rgb"), ["train.supervision=rgb", *overrides]
    return name, overrides


def fit_run(job, started: float) -> Path:
    """Fit ``job.dataset`` with ``job.preset`` for ``job.minutes`` or ``job.iters``; return
    the run folder (with ``snapshots/`` and ``fit.json``). ``started``: the
    ``time.perf_counter()`` of the process's start, from which the budget and the wall time
    count (as the CLI's do)."""
    import torch

    from hybridneus.api import fit
    from hybridneus.fileio import atomic_path

    torch.set_num_threads(job.threads)
    preset, overrides = preset_spec(job.preset)
    budget = ([f"train.minutes={job.minutes}"] if job.minutes
              else [f"train.iters={job.iters}", "train.minutes=0"])
    staging = job.out_runs / f".snapshots-{os.getpid()}"
    state: dict = {}

    def save(trainer) -> None:
        path = staging / f"t{trainer.elapsed:07.1f}-s{trainer.step}.pt"
        with atomic_path(path) as tmp:
            torch.save({"model": trainer.field.state_dict(), "elapsed": trainer.elapsed,
                        "step": trainer.step, "total_steps": trainer.total_steps,
                        "knots": [[int(k), float(q)] for k, q in trainer.timeline.knots],
                        "scene": dict(trainer.scene)}, tmp)

    def snapshot(trainer, logs) -> None:
        if "first_step_s" not in state:
            state["first_step_s"] = time.perf_counter() - started - logs["step_seconds"]
        state["trainer"] = trainer
        # a budget re-plans total_steps as it goes, so a mark is passed, not hit
        marks = [trainer.total_steps * k // job.curve for k in range(1, job.curve)]
        saved = state.get("saved", 0)
        if saved < len(marks) and trainer.step >= marks[saved]:
            save(trainer)
            state["saved"] = saved + 1

    field = fit(job.dataset, preset, [snapshot],
                overrides=[*budget, f"train.threads={job.threads}", "train.preview_every=0",
                           *overrides, *job.overrides],
                out=job.out_runs, device=job.device, progress=False, started=started)
    wall = time.perf_counter() - started
    trainer = state["trainer"]
    save(trainer)
    run_dir = Path(field.run_dir)
    staging.rename(run_dir / "snapshots")
    variant = [o for o in job.overrides if not o.startswith("train.seed=")]
    info = {
        "scene": job.scene, "preset": " ".join([job.preset, *variant]),
        "overrides": variant, "seed": trainer.cfg.train.seed,
        "minutes": job.minutes, "iters": job.iters, "noise": job.noise,
        "dataset": str(Path(job.dataset).resolve()), "device": job.device,
        "steps": int(trainer.step), "total_steps": int(trainer.total_steps),
        "stopped_early": bool(trainer.stopped_early), "restores": _restores(trainer),
        "fit_s": round(float(trainer.elapsed), 1), "fit_wall_s": round(wall, 1),
        "first_step_s": round(float(state["first_step_s"]), 2),
        "inv_s": round(float(field.inv_s().detach()), 1),
        "fit_peak_rss_mb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024),
        "machine": common.machine(job.device),  # where it was fitted, not where it is scored
        # the fitted code, which a line scored later on another commit is credited to
        **dict(zip(("commit", "dirty"), common.git_state(), strict=True)),
        "fit_command": os.environ.get(common.FIT_COMMAND),
    }
    with atomic_path(run_dir / "fit.json") as tmp:
        tmp.write_text(json.dumps(info, indent=1))
    return run_dir


def _restores(trainer) -> int:
    guard = [p for p in trainer.priors if p.name == "collapse_guard"]
    return int(guard[0].restores) if guard else 0


def score_field(field, gt, res: int, cameras=None, keep_cavities: bool = False,
                component_gap: float | None = None):
    """Mesh ``field`` as ``hybridneus mesh`` does and score it against ``gt``.

    ``keep_cavities`` and ``component_gap`` (None: the default) change one clean-up step, so
    that a line also shows what that step does to the same field.
    """
    from hybridneus.evaluation.geometry import chamfer_distance
    from hybridneus.meshing import PostprocessOptions, extract_mesh

    t = time.perf_counter()
    post = PostprocessOptions(remove_cavities=not keep_cavities)
    if component_gap is not None:
        post.component_gap = component_gap
    mesh = extract_mesh(field, res=res, progress=False, cameras=cameras, postprocess=post)
    mesh_s = time.perf_counter() - t
    if len(mesh.faces) == 0:
        return {"chamfer": None, "faces": 0, "mesh_s": round(mesh_s, 2)}, mesh
    cd = chamfer_distance(mesh, gt)
    return {"chamfer": cd.chamfer, "accuracy": cd.accuracy, "completeness": cd.completeness,
            "fscore": cd.fscore, "faces": int(len(mesh.faces)), "mesh_s": round(mesh_s, 2)}, mesh


def _plane_rms(mesh, gt, cameras) -> float | None:
    """The pooled plane RMS of ``mesh`` over the faces a camera sees (None without a mesh or
    such a face)."""
    from hybridneus.evaluation.planes import plane_errors, plane_rms

    if mesh is None or not len(mesh.faces):
        return None
    rms = plane_rms(plane_errors(mesh, gt, cameras=cameras))
    return None if np.isnan(rms) else rms


def _shape_metrics(mesh, gt, cameras, plane_curve: list, final_at: list) -> dict:
    """What Chamfer mixes, apart: the flat faces' errors (``planes``, ``plane_rms`` and its
    curve, the snapshots' ``plane_curve`` with the final mesh's point at ``final_at``, its
    elapsed seconds and step, appended), the recall of each ground-truth part
    (``part_recall``, largest part first) and the median distance of the mesh's farthest
    connected part (``farthest_part``), all in the unit cube (hybridneus.evaluation.planes
    and .parts; a face no camera sees is listed with ``views`` 0 and left out of
    ``plane_rms``)."""
    from hybridneus.evaluation.parts import component_distances, part_completeness
    from hybridneus.evaluation.planes import plane_errors, plane_rms

    faces = plane_errors(mesh, gt, cameras=cameras)
    out = {"part_recall": [round(p.recall, 3) for p in part_completeness(mesh, gt)],
           "farthest_part": max((c.distance for c in component_distances(mesh, gt)),
                                default=None)}
    if faces:
        rms = plane_rms(faces)
        out.update({"plane_rms": rms,
                    "plane_curve": [*plane_curve, [*final_at, None if np.isnan(rms) else rms]],
                    "planes": [{"normal": [round(v, 3) for v in f.normal],
                                "area": round(f.area, 4), "rms": round(f.rms, 5),
                                "offset": round(f.offset, 5), "coverage": round(f.coverage, 3),
                                "views": f.views}
                               for f in faces]})
    return out


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
        gt = read_frame(split.rgb_paths[int(i)], split.width, split.height)
        if gt is None:
            continue
        mask = foreground_mask(gt, dataset.preset.background)
        if mask.any():
            img = render_view(field, split.intrinsics[int(i)], split.distortion[int(i)],
                              split.c2w[int(i)], split.width, split.height, sampler,
                              lens=split.lens)
            m = color_corrected_psnr_ssim(img.color, gt, mask)
            psnrs.append(m.psnr)
            ssims.append(m.ssim)
    if not psnrs:
        return {}
    return {"psnr": float(np.mean(psnrs)), "ssim": float(np.mean(ssims))}


def snapshots(run_dir: Path) -> list[Path]:
    """A run's snapshots (``snapshots/t<elapsed>-s<step>.pt``), oldest step first."""
    return sorted((run_dir / "snapshots").glob("t*.pt"),
                  key=lambda p: int(p.stem.split("-s")[1]))


def load_snapshot(cfg, path: Path):
    """(field in eval mode, snapshot dict) of one :func:`fit_run` snapshot."""
    import torch

    from hybridneus.training.runs import build_field
    from hybridneus.training.state import position

    snap = torch.load(path, map_location="cpu", weights_only=True)
    f = build_field(cfg, snap["scene"])
    f.load_state_dict(snap["model"])
    f.update_step(position(snap), int(snap["total_steps"]))
    return f.eval(), snap


def score_run(run_dir: Path, res: int, image_views: int, cache: Path | None = None) -> dict:
    """The Chamfer-versus-time curve and the final field's metrics of a :func:`fit_run` folder.

    ``cache``: where to look for the dataset (by folder name) when the path recorded in
    ``fit.json`` does not exist here (a fit made on another machine).
    """
    from hybridneus.config import load_config
    from hybridneus.data import load_dataset
    from hybridneus.data.dataset import read_camera_centres
    from hybridneus.evaluation.geometry import chamfer_distance, chamfer_floor, sdf_mae
    from hybridneus.meshing.convert import load_mesh, save_mesh

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
    snaps = snapshots(run_dir)
    if not snaps:
        raise SystemExit(f"{run_dir}: no snapshots/ to score")

    cameras = read_camera_centres(dataset / cfg.data.split)
    curve, plane_curve = [], []
    for path in snaps[:-1]:
        f, snap = load_snapshot(cfg, path)
        score, m = score_field(f, gt, res, cameras)
        curve.append([round(float(snap["elapsed"]), 1), int(snap["step"]), score["chamfer"]])
        plane_curve.append([round(float(snap["elapsed"]), 1), int(snap["step"]),
                            _plane_rms(m, gt, cameras)])
    field, snap = load_snapshot(cfg, snaps[-1])
    final, mesh = score_field(field, gt, res, cameras)
    final_at = [round(float(snap["elapsed"]), 1), int(snap["step"])]
    curve.append([*final_at, final["chamfer"]])
    unfilled, _ = score_field(field, gt, res)
    cavities, _ = score_field(field, gt, res, cameras, keep_cavities=True)
    ungrouped, ungrouped_mesh = score_field(field, gt, res, cameras, component_gap=0.0)
    # "volume": res points span the field's crop box, as in `hybridneus mesh`; lines
    # without it were meshed over the whole cube [-1, 1]^3, with voxels 2-3x larger
    report = {**info, "run": str(run_dir), "res": res, "volume": common.CROP_VOLUME, **final,
              "curve": curve,
              "chamfer_unfilled": unfilled["chamfer"], "chamfer_cavities": cavities["chamfer"],
              "chamfer_ungrouped": ungrouped["chamfer"],
              "floor": chamfer_floor(gt),
              "floor_eventneus": chamfer_floor(gt, protocol="eventneus")}
    if mesh is not None and len(mesh.faces):
        report["chamfer_eventneus"] = chamfer_distance(mesh, gt, protocol="eventneus").chamfer
        save_mesh(mesh, run_dir / "mesh.ply")
        if len(ungrouped_mesh.faces):  # for before/after pictures (benchmarks/pictures.py)
            save_mesh(ungrouped_mesh, run_dir / "mesh_ungrouped.ply")
        report["sdf_mae"] = float(sdf_mae(mesh, gt).mae)
        report.update(_shape_metrics(mesh, gt, cameras, plane_curve, final_at))
        report.update(_image_metrics(field, load_dataset(dataset), image_views))
    report["peak_rss_mb"] = round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    return report
