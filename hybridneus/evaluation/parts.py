"""Which parts of the ground truth a mesh recovers (completeness per connected component of
the ground truth), and which parts of the mesh lie away from it (per connected component of
the mesh).

One Chamfer number mixes a lost wire with a lumpy face. Split into its connected components
(a cage's wires, the body inside, a device's button), the ground truth says part by part how
much of it the mesh reaches: the share of the part's surface within ``threshold`` of the mesh
(its recall) and the mean distance (exact point to triangle distances from surface samples),
both in the ground truth's unit cube.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from hybridneus.evaluation.geometry import MeshLike, as_mesh, normalize_pair, sample_surface
from hybridneus.evaluation.inside import unsigned_distance


@dataclass
class PartResult:
    """One ground-truth component against the mesh (unit-cube units).

    Attributes:
        index: rank of the part by surface area (0: the largest).
        area: its surface area.
        extents: its bounding box's size along x, y, z.
        completeness: mean distance from the part's surface samples to the mesh.
        recall: share of those samples within ``threshold`` of the mesh.
        samples: how many samples the part got.
    """

    index: int
    area: float
    extents: tuple[float, float, float]
    completeness: float
    recall: float
    samples: int

    def as_dict(self) -> dict:
        return asdict(self)


def part_completeness(
    mesh: MeshLike,
    gt: MeshLike,
    threshold: float = 0.01,
    n_samples: int = 20_000,
    seed: int = 0,
    max_parts: int = 32,
) -> list[PartResult]:
    """Completeness of ``mesh`` on each connected component of ``gt``, largest first.

    ``n_samples`` surface samples are shared out by area, with at least 200 per part so that
    a thin wire is measured too; at most ``max_parts`` parts are reported.
    """
    pred, truth = normalize_pair(as_mesh(mesh), as_mesh(gt))
    parts = sorted(truth.split(only_watertight=False), key=lambda m: -m.area)[:max_parts]
    total = sum(p.area for p in parts)
    out = []
    for i, part in enumerate(parts):
        n = max(200, int(round(n_samples * part.area / total)))
        points = sample_surface(part, n, seed + 1 + i)
        distance = unsigned_distance(pred, points) if len(pred.faces) else np.full(n, np.inf)
        out.append(PartResult(i, float(part.area), tuple(float(e) for e in part.extents),
                              float(distance.mean()), float((distance < threshold).mean()), n))
    return out


@dataclass
class ComponentResult:
    """One connected component of the mesh against the ground truth (unit-cube units).

    Attributes:
        index: rank of the component by surface area (0: the largest).
        area: its surface area.
        faces: its triangle count.
        distance: median distance of its surface samples to the ground truth (a floater, a
            fragment invented in empty space, lies far as a whole).
    """

    index: int
    area: float
    faces: int
    distance: float

    def as_dict(self) -> dict:
        return asdict(self)


def component_distances(
    mesh: MeshLike, gt: MeshLike, n_samples: int = 20_000, seed: int = 0, max_parts: int = 256,
) -> list[ComponentResult]:
    """How far each connected component of ``mesh`` lies from ``gt``, largest first (at most
    ``max_parts``; samples shared out by area, at least 50 per component)."""
    pred, truth = normalize_pair(as_mesh(mesh), as_mesh(gt))
    if not len(pred.faces):
        return []
    pred.merge_vertices()
    parts = sorted(pred.split(only_watertight=False), key=lambda m: -m.area)[:max_parts]
    total = sum(p.area for p in parts)
    out = []
    for i, part in enumerate(parts):
        n = max(50, int(round(n_samples * part.area / total))) if total > 0 else 50
        points = sample_surface(part, n, seed + 1 + i)
        out.append(ComponentResult(i, float(part.area), int(len(part.faces)),
                                   float(np.median(unsigned_distance(truth, points)))))
    return out
