"""``hybridneus eval``: Chamfer distance, F-score and SDF-MAE of a mesh against ground truth,
under the unit-cube protocol or EventNeuS's published one."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def evaluate(
    mesh: Annotated[Path, typer.Argument(help="Predicted mesh (PLY, OBJ, OFF, GLB, STL ...).")],
    gt: Annotated[Path, typer.Argument(help="Ground-truth mesh.")],
    json_out: Annotated[
        bool, typer.Option("--json", help="Print JSON instead of a table.")
    ] = False,
    samples: Annotated[
        int, typer.Option("--samples", help="Surface samples / SDF points.")
    ] = 10_000,
    seed: Annotated[int, typer.Option("--seed", help="Sampling seed.")] = 0,
    protocol: Annotated[
        str, typer.Option("--protocol", help="Chamfer protocol: unit-cube (both meshes in GT's "
                          "unit cube, the mean of the two directions) or eventneus (each mesh "
                          "centred on its centroid, farthest vertex at radius 1, the sum).")
    ] = "unit-cube",
    threshold: Annotated[
        float, typer.Option("--threshold", help="F-score distance (unit cube).")
    ] = 0.01,
    sign: Annotated[
        str, typer.Option("--sign", help="Inside test: auto, winding or rays.")
    ] = "auto",
    no_sdf: Annotated[bool, typer.Option("--no-sdf", help="Skip SDF-MAE.")] = False,
    parts: Annotated[
        bool, typer.Option("--parts", help="Also say how much of each connected part of GT "
                           "the mesh recovers (recall at --threshold, mean distance), and how "
                           "far each connected part of the mesh lies from GT (floaters).")
    ] = False,
    planes: Annotated[
        bool, typer.Option("--planes", help="Also say how flat the mesh keeps each planar face "
                           "of GT (RMS and median signed distance to the face's plane).")
    ] = False,
    errors: Annotated[
        Path | None,
        typer.Option("--errors", help="Also write a PNG: GT coloured by its distance to the "
                     "mesh above the mesh coloured by its distance to GT (a mesh in a run folder: "
                     "RUN/errors.png by default, its scores in RUN/eval.json)."),
    ] = None,
    error_max: Annotated[
        float, typer.Option("--error-max", help="Distance (unit cube) shown in the last colour.")
    ] = 0.02,
) -> None:
    """Compare MESH with GT: Chamfer distance (with its floor, GT against a second sampling of
    itself), F-score, SDF-MAE (always in GT's unit cube)."""
    import json
    import time

    from hybridneus.errors import ConfigError
    from hybridneus.evaluation import PROTOCOLS, chamfer_distance, chamfer_floor, sdf_mae
    from hybridneus.evaluation.inside import SIGN_METHODS
    from hybridneus.meshing import load_mesh

    if samples < 2:
        raise ConfigError(f"--samples {samples}: expected at least 2")
    if sign not in SIGN_METHODS:
        raise ConfigError(f"--sign {sign}: expected one of {', '.join(SIGN_METHODS)}")
    if error_max <= 0:
        raise ConfigError(f"--error-max {error_max}: expected a positive distance")
    if not threshold > 0:
        raise ConfigError(f"--threshold {threshold}: expected a positive distance")
    if protocol not in PROTOCOLS:
        raise ConfigError(f"--protocol {protocol}: expected one of {', '.join(PROTOCOLS)}")
    pred_mesh = load_mesh(mesh)
    gt_mesh = load_mesh(gt)
    start = time.perf_counter()
    try:
        cd = chamfer_distance(pred_mesh, gt_mesh, n_samples=samples, seed=seed,
                              threshold=threshold, protocol=protocol)
        floor = chamfer_floor(gt_mesh, n_samples=samples, seed=seed, protocol=protocol)
    except ValueError as exc:  # a mesh without extent
        raise ConfigError(f"{mesh} / {gt}: {exc}") from None
    result: dict = {"mesh": str(mesh), "gt": str(gt), "samples": samples, "seed": seed}
    result.update(cd.as_dict())
    result["floor"] = floor
    if not no_sdf:
        mae = sdf_mae(pred_mesh, gt_mesh, n_points=samples, seed=seed, sign_method=sign)
        result.update(
            {"sdf_mae": mae.mae, "sdf_mae_near": mae.mae_near, "sdf_mae_uniform": mae.mae_uniform}
        )
    if parts:
        from hybridneus.evaluation.parts import component_distances, part_completeness

        result["parts"] = [p.as_dict() for p in part_completeness(
            pred_mesh, gt_mesh, threshold=threshold, n_samples=2 * samples, seed=seed)]
        result["components"] = [c.as_dict() for c in component_distances(
            pred_mesh, gt_mesh, n_samples=2 * samples, seed=seed)]
    if planes:
        from hybridneus.evaluation.planes import plane_errors, plane_rms

        faces = plane_errors(pred_mesh, gt_mesh, seed=seed)
        result["planes"] = [f.as_dict() for f in faces]
        result["plane_rms"] = plane_rms(faces)
    result["seconds"] = round(time.perf_counter() - start, 3)
    # A mesh in a run folder: the scores and the error picture stay with the run, for its
    # report (hybridneus report).
    run = mesh.parent if (mesh.parent / "config.yaml").is_file() else None
    if errors is None and run is not None:
        errors = run / "errors.png"
    if errors is not None:
        from hybridneus.evaluation import save_error_image

        result["errors"] = str(save_error_image(pred_mesh, gt_mesh, errors, vmax=error_max))
    if run is not None:
        from hybridneus.fileio import atomic_path

        with atomic_path(run / "eval.json") as tmp:
            tmp.write_text(json.dumps(result, indent=2) + "\n")
    if json_out:
        typer.echo(json.dumps(result, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title=f"{mesh} vs {gt} ({protocol} protocol, {samples} samples, seed {seed})")
    table.add_column("metric")
    table.add_column("value", justify="right")
    rows = [
        ("Chamfer distance", "chamfer"),
        ("  floor (GT against itself)", "floor"),
        ("accuracy (pred -> gt)", "accuracy"),
        ("completeness (gt -> pred)", "completeness"),
        (f"F-score @ {threshold:g}", "fscore"),
        ("SDF-MAE (GT unit cube)", "sdf_mae"),
    ]
    for label, key in rows:
        if key in result:
            table.add_row(label, f"{result[key]:.5f}")
    Console().print(table)
    if parts:
        by_part = Table(title=f"GT parts, largest first (recall: share within {threshold:g})")
        for column in ("part", "area", "extents", "recall", "mean distance"):
            by_part.add_column(column, justify="right")
        for p in result["parts"]:
            by_part.add_row(str(p["index"]), f"{p['area']:.4f}",
                            " x ".join(f"{e:.3f}" for e in p["extents"]),
                            f"{p['recall']:.2f}", f"{p['completeness']:.4f}")
        Console().print(by_part)
        far = max(result["components"], key=lambda c: c["distance"], default=None)
        if far is not None:
            typer.echo(f"mesh: {len(result['components'])} connected parts; the farthest from "
                       f"GT (median distance) is part {far['index']}, {far['distance']:.4f} "
                       f"away, {far['faces']} faces")
    if planes:
        by_face = Table(title=f"GT planar faces, largest first: pooled RMS "
                        f"{result['plane_rms']:.5f} (offset: median signed, + outside)")
        for column in ("face", "area", "normal", "RMS", "offset", "coverage"):
            by_face.add_column(column, justify="right")
        for f in result["planes"]:
            by_face.add_row(str(f["index"]), f"{f['area']:.4f}",
                            " ".join(f"{v:+.2f}" for v in f["normal"]), f"{f['rms']:.5f}",
                            f"{f['offset']:+.5f}", f"{f['coverage']:.2f}")
        if not result["planes"]:
            by_face.add_row("none", "-", "-", "-", "-", "-")
        Console().print(by_face)
    if errors is not None:
        typer.echo(f"error picture: {result['errors']}")
    if run is not None:
        typer.echo(f"scores kept in {run / 'eval.json'} (hybridneus report {run} shows them)")
