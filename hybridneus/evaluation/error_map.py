"""Where a mesh is wrong: surface distances to the ground truth as coloured pictures.

The Chamfer distance is one number; these pictures say where it comes from. The ground truth is
coloured by how far each of its points lies from the mesh (a missing wire, a hole in a plate light
up: completeness), the mesh by how far each of its points lies from the ground truth (floaters, a
slab grown thick, a lumpy face light up: accuracy). Both in the ground truth's unit cube, as the
Chamfer protocol measures them, and both drawn from the same viewpoints so they line up.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import trimesh

from hybridneus.evaluation.geometry import MeshLike, as_mesh, normalize_pair
from hybridneus.evaluation.inside import unsigned_distance
from hybridneus.fileio import atomic_path


def vertex_errors(mesh: MeshLike, target: MeshLike) -> np.ndarray:
    """Distance (V,) from each vertex of ``mesh`` to the surface of ``target`` (exact point
    to triangle distances, :func:`hybridneus.evaluation.inside.unsigned_distance`)."""
    return unsigned_distance(as_mesh(target), np.asarray(as_mesh(mesh).vertices))


#: Light grey (no error; the shape stays readable) through yellow to red (``vmax`` and above).
_STOPS = np.array([[0.0, 215, 215, 215], [0.5, 250, 200, 40], [1.0, 190, 20, 20]])


def error_colors(values: np.ndarray, vmax: float) -> np.ndarray:
    """RGB (N, 3) uint8 of ``values`` on the error scale from 0 to ``vmax``."""
    levels = np.clip(np.asarray(values, dtype=np.float64) / vmax, 0.0, 1.0)
    rgb = [np.interp(levels, _STOPS[:, 0], _STOPS[:, c]) for c in (1, 2, 3)]
    return (np.stack(rgb, axis=-1) + 0.5).astype(np.uint8)


def colored_by(mesh: trimesh.Trimesh, values: np.ndarray, vmax: float) -> trimesh.Trimesh:
    """A copy of ``mesh`` whose vertex colours show ``values`` (:func:`error_colors`)."""
    rgb = error_colors(values, vmax)
    out = trimesh.Trimesh(vertices=mesh.vertices, faces=mesh.faces, process=False)
    out.visual.vertex_colors = np.concatenate([rgb, np.full((len(rgb), 1), 255, np.uint8)], 1)
    return out


def error_image(
    mesh: MeshLike,
    gt: MeshLike,
    vmax: float = 0.02,
    size: int = 256,
    azimuths: tuple[float, ...] = (30.0, 120.0, 210.0, 300.0),
) -> np.ndarray:
    """Ground truth (top row, coloured by completeness error) above ``mesh`` (bottom row,
    coloured by accuracy error), with a colour bar -> (H, W, 3) uint8.

    Distances are in the ground truth's unit cube; ``vmax`` (default twice the F-score
    threshold) is the distance drawn in the colour map's last colour.
    """
    from hybridneus.meshing.render import render_views

    pred, truth = normalize_pair(as_mesh(mesh), as_mesh(gt))
    frame = _frame([m for m in (truth, pred) if len(m.faces)])  # floaters stay in view
    rows = []
    for shown, other, label in ((truth, pred, "ground truth: distance to the mesh"),
                                (pred, truth, "mesh: distance to the ground truth")):
        if len(shown.faces) == 0:
            rows.append(_caption(np.full((size, size * len(azimuths), 3), 255, np.uint8),
                                 f"{label.split(':')[0]}: empty"))
            continue
        errors = vertex_errors(shown, other) if len(other.faces) else np.full(
            len(shown.vertices), vmax)
        views = render_views(colored_by(shown, errors, vmax), size=size, azimuths=azimuths,
                             frame=frame)
        rows.append(_caption(views, label))
    return np.concatenate([*rows, _colour_bar(rows[0].shape[1], vmax)], axis=0)


def save_error_image(mesh: MeshLike, gt: MeshLike, path: str | os.PathLike,
                     vmax: float = 0.02, size: int = 256) -> Path:
    """Write :func:`error_image` as a PNG (atomically); returns the path."""
    from PIL import Image

    path = Path(path)
    image = error_image(mesh, gt, vmax=vmax, size=size)
    with atomic_path(path, suffix=".png") as tmp:
        Image.fromarray(image).save(tmp, format="PNG")
    return path


def _frame(meshes: list[trimesh.Trimesh]) -> tuple[np.ndarray, float]:
    lo = np.min([m.bounds[0] for m in meshes], axis=0)
    hi = np.max([m.bounds[1] for m in meshes], axis=0)
    return 0.5 * (lo + hi), 0.55 * float(np.linalg.norm(hi - lo))


def _caption(image: np.ndarray, text: str) -> np.ndarray:
    import cv2

    image = np.ascontiguousarray(image)
    cv2.putText(image, text, (6, 16), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1,
                cv2.LINE_AA)
    return image


def _colour_bar(width: int, vmax: float, height: int = 28) -> np.ndarray:
    import cv2

    bar = np.full((height, width, 3), 255, np.uint8)
    ramp = error_colors(np.linspace(0.0, vmax, width // 2), vmax)
    bar[4:14, 6:6 + len(ramp)] = ramp[None]
    cv2.putText(bar, f"0 .. {vmax:g} (GT unit cube)", (12 + len(ramp), 14),
                cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1, cv2.LINE_AA)
    return bar
