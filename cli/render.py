"""``hybridneus render``: pictures of a trained run (test views, mesh orbit, event sheets)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

VIEW_KINDS = ("test", "orbit", "events", "all")


def _to_uint8(img):
    import numpy as np

    return (np.clip(img, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def _write_png(path: Path, rgb) -> None:
    import cv2

    from hybridneus.fileio import atomic_path

    with atomic_path(path) as tmp:
        if not cv2.imwrite(str(tmp), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR)):
            raise OSError(f"{path}: could not write PNG")


def _render_test_views(field, dataset, split_name: str, out: Path, max_views: int, stride: int):
    import json

    import numpy as np

    from hybridneus.errors import DatasetError
    from hybridneus.evaluation import color_corrected_psnr_ssim
    from hybridneus.evaluation.images import foreground_mask, read_frame
    from hybridneus.fileio import atomic_path
    from hybridneus.progress import make_progress
    from hybridneus.rendering.views import inference_sampler, render_view

    if split_name not in dataset.splits:
        raise DatasetError(f"{dataset.root}: no split {split_name!r} to render")
    split = dataset.splits[split_name]
    views = np.unique(np.linspace(0, split.n_views - 1, min(max_views, split.n_views)).round())
    sampler = inference_sampler(field)
    background = np.asarray(dataset.preset.background, dtype=np.float32)
    rows = []
    with make_progress("view") as progress:
        task = progress.add_task(f"render {split_name}", total=len(views))
        for i in views.astype(int):
            img = render_view(field, split.intrinsics[i], split.distortion[i], split.c2w[i],
                              split.width, split.height, sampler, stride=stride,
                              lens=split.lens)
            name = f"{split_name}_{i:05d}"
            normal = _to_uint8(0.5 * (img.normal + 1.0))
            depth = img.depth / max(float(img.depth[img.opacity > 0.5].max(initial=1e-6)), 1e-6)
            depth = np.where(img.opacity > 0.5, depth, 0.0)
            depth_rgb = _to_uint8(np.repeat(depth[..., None], 3, axis=-1))
            _write_png(out / f"{name}_color.png", _to_uint8(img.color))
            _write_png(out / f"{name}_normal.png", normal)
            _write_png(out / f"{name}_depth.png", depth_rgb)
            row = {"view": int(i)}
            gt = None
            if split.rgb_paths is not None and stride == 1:
                gt = read_frame(split.rgb_paths[i], split.width, split.height)
            if gt is not None:
                mask = foreground_mask(gt, background)
                if mask.any():
                    m = color_corrected_psnr_ssim(img.color, gt, mask)
                    row.update(psnr=m.psnr, ssim=m.ssim)
            rows.append(row)
            info = f"psnr {row['psnr']:.2f}" if "psnr" in row else ""
            progress.update(task, advance=1, info=info)
    summary: dict = {"split": split_name, "views": rows}
    scored = [r for r in rows if "psnr" in r]
    if scored:
        summary["mean_psnr"] = float(np.mean([r["psnr"] for r in scored]))
        summary["mean_ssim"] = float(np.mean([r["ssim"] for r in scored]))
    with atomic_path(out / "metrics.json") as tmp:
        tmp.write_text(json.dumps(summary, indent=2))
    return summary


def _render_orbit(field, run_dir: Path, out: Path, frames: int, size: int) -> Path:
    import cv2
    import numpy as np
    from PIL import Image

    from hybridneus.fileio import atomic_path
    from hybridneus.meshing import load_mesh
    from hybridneus.meshing.extract import extract_mesh
    from hybridneus.meshing.render import render_views
    from hybridneus.progress import make_progress
    from hybridneus.training.runs import load_cameras

    meshes = sorted(run_dir.glob("mesh_*.ply"), key=lambda p: p.stat().st_mtime)
    if meshes:
        mesh = load_mesh(meshes[-1])
    else:  # meshed as `hybridneus mesh` would
        mesh = extract_mesh(field, res=160, color=True, cameras=load_cameras(run_dir))
    images = []
    with make_progress("frame") as progress:
        task = progress.add_task("orbit", total=frames)
        for k in range(frames):
            azimuth = 360.0 * k / frames
            img = render_views(mesh, size=size, azimuths=(azimuth,), elevation=20.0)
            _write_png(out / f"orbit_{k:03d}.png", img)
            images.append(img)
            progress.update(task, advance=1)
    gif = out / "orbit.gif"
    with atomic_path(gif) as tmp:
        first, *rest = [Image.fromarray(im) for im in images]
        first.save(tmp, format="GIF", save_all=True, append_images=rest, duration=80, loop=0)
    mp4 = out / "orbit.mp4"
    with atomic_path(mp4) as tmp:
        writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), 12.0, (size, size))
        for im in images:
            writer.write(cv2.cvtColor(np.ascontiguousarray(im), cv2.COLOR_RGB2BGR))
        writer.release()
    return gif


def _render_event_sheet(field, dataset, split_name: str, out: Path, windows: int, stride: int):
    import numpy as np

    from hybridneus.rendering.views import inference_sampler, predicted_event_frame
    from hybridneus.training.previews import diverging_bgr

    split = dataset.splits[split_name]
    preset = dataset.preset
    dt = split.t_max / (split.n_views - 1)
    length = min(preset.max_window, split.n_views - 1) * dt * 0.5
    ends = np.linspace(length, split.t_max, windows + 1)[1:]
    sampler = inference_sampler(field)
    rows = []
    for t1 in ends:
        pred, rec = predicted_event_frame(field, split, preset, t1 - length, t1, sampler, stride)
        scale = float(np.percentile(np.abs(rec), 99)) or 1.0
        # diverging_bgr returns BGR; the sheet is written through an RGB->BGR conversion.
        pair = [diverging_bgr(rec, scale)[..., ::-1], diverging_bgr(pred, scale)[..., ::-1]]
        gap = np.full((pair[0].shape[0], 4, 3), 255, np.uint8)
        rows.append(np.concatenate([pair[0], gap, pair[1]], axis=1))
    sheet = np.concatenate(
        [np.concatenate([r, np.full((4, r.shape[1], 3), 255, np.uint8)]) for r in rows]
    )
    path = out / "events_vs_render.png"
    _write_png(path, sheet)
    return path


def render(
    run: Annotated[
        Path | None, typer.Argument(help="Run folder (default: the latest run under --runs-root).")
    ] = None,
    views: Annotated[
        str, typer.Option("--views", help="test, orbit, events or all.")
    ] = "test",
    out: Annotated[
        Path | None, typer.Option("--out", help="Output folder (default <run>/render).")
    ] = None,
    split: Annotated[str, typer.Option("--split", help="Split whose cameras to render.")] = "test",
    max_views: Annotated[int, typer.Option("--max-views", help="At most this many views.")] = 8,
    stride: Annotated[
        int, typer.Option("--stride", help="Render every n-th pixel (faster, smaller images).")
    ] = 1,
    frames: Annotated[int, typer.Option("--frames", help="Frames in the mesh orbit.")] = 36,
    size: Annotated[int, typer.Option("--size", help="Orbit frame size in pixels.")] = 384,
    windows: Annotated[int, typer.Option("--windows", help="Windows in the event sheet.")] = 4,
    data: Annotated[
        Path | None, typer.Option("--data", help="Dataset folder, if it moved since the fit.")
    ] = None,
    device: Annotated[str, typer.Option("--device", help="auto, cpu, cuda or cuda:N.")] = "auto",
    runs_root: Annotated[Path, typer.Option("--runs-root", help="Where runs live.")] = Path("runs"),
) -> None:
    """Render a trained run: colour/normal/depth at the test cameras (with PSNR/SSIM against
    the rgb frames where they exist), a mesh orbit (PNGs, GIF, MP4), and a sheet of recorded
    event frames next to the field's predicted log-brightness changes."""
    from hybridneus.data import load_dataset
    from hybridneus.errors import ConfigError
    from hybridneus.training.runs import latest_run, load_field, load_run_config, resolve_run

    if views not in VIEW_KINDS:
        raise ConfigError(f"--views {views}: expected one of {', '.join(VIEW_KINDS)}")
    if max_views < 1 or stride < 1 or frames < 1 or windows < 1 or size < 16:
        raise ConfigError("--max-views/--stride/--frames/--windows must be >= 1, --size >= 16")
    run_dir = resolve_run(run) if run is not None else latest_run(runs_root)
    from hybridneus.errors import DatasetError
    from hybridneus.fileio import check_output

    out_dir = check_output(Path(out) if out is not None else run_dir / "render", folder=True)
    field = load_field(run_dir, device=device)

    kinds = ("test", "orbit", "events") if views == "all" else (views,)
    dataset = None
    if "test" in kinds or "events" in kinds:
        cfg = load_run_config(run_dir)
        path = data if data is not None else Path(cfg.data.path)
        dataset = load_dataset(path, overrides=cfg.data.overrides() or None)
        if "test" in kinds and split not in dataset.splits:
            raise DatasetError(f"{dataset.root}: no split {split!r} to render (it has "
                               f"{', '.join(dataset.splits)})")
        _use_trained_poses(run_dir, dataset, cfg.data.split)
    out_dir.mkdir(parents=True, exist_ok=True)  # only once the inputs are known good
    if "test" in kinds:
        summary = _render_test_views(field, dataset, split, out_dir, max_views, stride)
        if "mean_psnr" in summary:
            typer.echo(
                f"{split}: PSNR {summary['mean_psnr']:.2f} dB, SSIM {summary['mean_ssim']:.3f} "
                f"over {len(summary['views'])} views (log-space colour correction)"
            )
        typer.echo(f"{out_dir}: colour, normal and depth PNGs, metrics.json")
    if "orbit" in kinds:
        typer.echo(f"{_render_orbit(field, run_dir, out_dir, frames, size)}: orbit (+ PNGs, MP4)")
    if "events" in kinds:
        train = "train" if "train" in dataset.splits else next(iter(dataset.splits))
        path = _render_event_sheet(field, dataset, train, out_dir, windows, max(stride, 1))
        typer.echo(f"{path}: recorded events (left) vs rendered log-difference (right)")


def _use_trained_poses(run_dir: Path, dataset, split: str) -> None:
    """A run that smoothed its track (``refine.pose_smoothing``) renders its training
    ``split`` from the poses it trained on."""
    import numpy as np

    from hybridneus.training.runlog import POSES

    path = run_dir / POSES
    if not path.is_file():
        return
    refined = np.load(path)["refined"]
    if split in dataset.splits and refined.shape == dataset.splits[split].c2w.shape:
        dataset.splits[split].c2w = refined
        typer.echo(f"{split}: the run's smoothed poses ({path.name})")
