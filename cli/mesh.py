"""``hybridneus mesh``: extract a (coloured) mesh from a trained run."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def mesh(
    run: Annotated[
        Path | None, typer.Argument(help="Run folder (default: the latest run under --runs-root).")
    ] = None,
    res: Annotated[int, typer.Option("--res", help="Grid points along the longest side.")] = 300,
    color: Annotated[
        bool, typer.Option("--color/--no-color", help="Attach vertex colours.")
    ] = False,
    format: Annotated[
        str | None,
        typer.Option("--format", help="ply, obj or glb. Default: --out's suffix, else ply.",
                     show_default=False),
    ] = None,
    out: Annotated[
        Path | None, typer.Option("--out", help="Output file (default <run>/mesh_<res>.<fmt>).")
    ] = None,
    device: Annotated[str, typer.Option("--device", help="auto, cpu, cuda or cuda:N.")] = "auto",
    no_postprocess: Annotated[
        bool, typer.Option("--no-postprocess", help="Keep the raw marching-cubes mesh.")
    ] = False,
    min_component: Annotated[
        float,
        typer.Option(
            "--min-component",
            help="Drop components smaller than this fraction of the mesh diagonal (0: keep all).",
        ),
    ] = 0.05,
    component_gap: Annotated[
        float,
        typer.Option(
            "--component-gap",
            help="Judge small components closer than this fraction of the mesh diagonal "
            "together (pieces of one thin wire; 0: each alone).",
        ),
    ] = 0.01,
    min_component_faces: Annotated[
        int,
        typer.Option(
            "--min-component-faces",
            help="Drop components with fewer faces (0: off).",
        ),
    ] = 0,
    keep_largest: Annotated[
        bool, typer.Option("--keep-largest", help="Keep only the largest connected component.")
    ] = False,
    decimate: Annotated[
        int, typer.Option("--decimate", help="Target face count (0: no decimation).")
    ] = 0,
    clip: Annotated[
        bool, typer.Option("--clip/--no-clip", help="Clip to the scene's crop cylinder.")
    ] = True,
    trim_crop: Annotated[
        bool,
        typer.Option(
            "--trim-crop/--keep-crop-cap",
            help="Drop the cap the crop cylinder puts on matter that reaches it (open mesh).",
        ),
    ] = False,
    remove_cavities: Annotated[
        bool,
        typer.Option(
            "--remove-cavities/--keep-cavities",
            help="Drop closed inner walls of hollows enclosed by matter (never seen by a camera).",
        ),
    ] = True,
    fill_unseen: Annotated[
        bool,
        typer.Option(
            "--fill-unseen/--keep-unseen",
            help="Fill pockets of empty space that no training camera saw (e.g. a cave opened "
            "from an unfilmed underside).",
        ),
    ] = True,
    frame: Annotated[
        str,
        typer.Option(
            "--frame",
            help="recording: a converted recording's mesh in its own metric frame; "
            "normalised: the unit-sphere frame the field was trained in (other datasets "
            "have only this one).",
        ),
    ] = "recording",
    chunk: Annotated[int, typer.Option("--chunk", help="Points per field query.")] = 2**18,
    preview: Annotated[
        bool, typer.Option("--preview/--no-preview", help="Write a PNG preview.")
    ] = True,
    runs_root: Annotated[Path, typer.Option("--runs-root", help="Where runs live.")] = Path("runs"),
) -> None:
    """Extract the surface of a trained run as a mesh (PLY/OBJ/GLB) plus a PNG preview."""
    import time

    from hybridneus.errors import ConfigError
    from hybridneus.meshing import MESH_FORMATS, CropVolume, PostprocessOptions, save_mesh
    from hybridneus.meshing.extract import ExtractionStats, extract_mesh
    from hybridneus.meshing.render import save_preview
    from hybridneus.training.runs import (
        latest_run,
        load_cameras,
        load_checkpoint,
        load_field,
        resolve_run,
    )

    suffix = Path(out).suffix.lstrip(".").lower() if out is not None else ""
    fmt = (format or suffix or "ply").lower()
    if fmt not in MESH_FORMATS:
        what = f"--format {format}" if format else f"--out {out}"
        raise ConfigError(f"{what}: expected one of {', '.join(MESH_FORMATS)}")
    if out is not None and suffix != fmt:
        raise ConfigError(f"--out {out}: a mesh in {fmt} format needs the suffix .{fmt}")
    if frame not in ("recording", "normalised"):
        raise ConfigError(f"--frame {frame}: expected recording or normalised")
    if res < 8 or res > 2048:
        raise ConfigError(f"--res {res}: expected 8 .. 2048")
    if chunk < 1:
        raise ConfigError(f"--chunk {chunk}: expected >= 1")
    if decimate < 0 or min_component < 0 or min_component_faces < 0 or component_gap < 0:
        raise ConfigError(
            "--decimate/--min-component/--component-gap/--min-component-faces must be >= 0")
    if out is not None:
        from hybridneus.fileio import check_output

        check_output(out)  # before minutes of meshing, not after
    run_dir = resolve_run(run) if run is not None else latest_run(runs_root)
    state = load_checkpoint(run_dir)  # read once: the field and the cameras are both in it
    field = load_field(run_dir, device=device, checkpoint=state)
    fill = fill_unseen and not no_postprocess
    cameras = load_cameras(run_dir, checkpoint=state) if fill else None
    if fill and cameras is None:
        typer.echo(f"{run_dir}: no camera poses saved or found; unseen space left as it is")

    crop = CropVolume.of_field(field)
    options = PostprocessOptions(
        enabled=not no_postprocess,
        min_component_diameter=min_component or None,
        component_gap=component_gap,
        min_component_faces=min_component_faces or None,
        keep_largest=keep_largest,
        remove_cavities=remove_cavities,
        decimate=decimate or None,
        trim_crop=trim_crop,
    )
    stats = ExtractionStats()
    start = time.perf_counter()
    result = extract_mesh(
        field,
        res=res,
        crop=crop,
        clip=clip,
        color=color,
        chunk=chunk,
        postprocess=options,
        stats=stats,
        cameras=cameras,
    )
    elapsed = time.perf_counter() - start
    if len(result.faces) == 0:
        from hybridneus.errors import MeshError

        raise MeshError(f"{run_dir}: the field has no zero level inside the volume at res {res}")
    saved_frame = state.get("scene", {}).get("frame")
    where = ""
    if saved_frame is not None and frame == "recording":
        import numpy as np

        from hybridneus.recordings.frame import SceneFrame

        scene_frame = SceneFrame.from_json(saved_frame, str(run_dir))
        result.apply_transform(np.linalg.inv(scene_frame.matrix()))
        where = ", in the recording's frame"
    path = Path(out) if out is not None else run_dir / f"mesh_{res}.{fmt}"
    save_mesh(result, path, fmt)
    typer.echo(
        f"{path}: {len(result.vertices)} vertices, {len(result.faces)} faces"
        f"{', coloured' if color else ''}{where} ({elapsed:.1f} s, "
        f"{100 * stats.active_fraction:.1f}% of the {res}-grid evaluated"
        f"{f'; {stats.filled_voxels} unseen voxels filled' if stats.filled_voxels else ''})"
    )
    if preview:
        png = save_preview(result, path.with_suffix(".png"))
        typer.echo(f"{png}: preview")
