"""Mesh-to-mesh metrics: Chamfer distance (+ F-score) under two protocols, and SDF-MAE.

``unit-cube`` (the default, as the EventNeuS paper describes it): both meshes are mapped by
the SAME similarity transform, the one that takes the ground truth's axis-aligned bounding box
into the unit cube: x' = (x - centre_gt) / L_gt + 0.5, with centre_gt the box centre and L_gt
its longest side. The ground truth then spans [0, 1] along its longest axis, and every
distance is in units of that side; a prediction that is off in scale or position is
measured, not normalised away. CD = (accuracy + completeness) / 2.

``eventneus`` (EventNeuS's published evaluation script, which its paper's table uses): EACH
mesh is centred on its own centroid (trimesh's, the area-weighted mean of its triangles'
centroids) and scaled so that its farthest vertex lies at radius 1; CD = accuracy +
completeness, the sum. A prediction off in position or scale is normalised on its own, so
this protocol forgives what the other measures; its numbers are larger than the other's on
the same meshes (a sum, not a mean, in a frame one to two times as large), so the two never
mix in one table.

Both: 10^4 points sampled uniformly by area on each surface (seeded), nearest neighbours
both ways with a KD-tree; accuracy = mean pred -> gt distance, completeness = mean gt -> pred;
F-score at threshold tau = 0.01 of the protocol's unit: 2 P R / (P + R), P = share of pred
samples within tau of gt samples, R = the converse. A protocol's floor (:func:`chamfer_floor`)
is the ground truth scored against a second sampling of itself: the sampling's own share of
any score, below which no mesh can go.

SDF-MAE: n points, half near the surfaces (points sampled on the two surfaces, a quarter of
all points each, moved by a uniform offset in [-1%, +1%] of the largest side of the box
enclosing both meshes, per coordinate), half uniform in that box; mean |SDF_gt - SDF_pred|
with signed distances from :func:`hybridneus.evaluation.inside.signed_distance`.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass

import numpy as np
import trimesh

from hybridneus.evaluation.inside import signed_distance

#: The Chamfer protocols (see the module docstring).
PROTOCOLS = ("unit-cube", "eventneus")


@dataclass(frozen=True)
class ChamferResult:
    """Chamfer distance and its parts, in the frame of ``protocol``."""

    chamfer: float
    accuracy: float
    completeness: float
    fscore: float
    precision: float
    recall: float
    threshold: float
    protocol: str = "unit-cube"

    def as_dict(self) -> dict[str, float]:
        """The fields as a plain dict (for JSON)."""
        return asdict(self)


@dataclass(frozen=True)
class SdfMaeResult:
    """SDF mean absolute error over the paper's hybrid sample, in the unit-cube frame."""

    mae: float
    mae_near: float
    mae_uniform: float
    n_points: int

    def as_dict(self) -> dict[str, float]:
        """The fields as a plain dict (for JSON)."""
        return asdict(self)


MeshLike = trimesh.Trimesh | str | os.PathLike


def as_mesh(mesh: MeshLike) -> trimesh.Trimesh:
    """A trimesh as is, or the mesh file at a path (MeshError if unreadable)."""
    if isinstance(mesh, trimesh.Trimesh):
        return mesh
    from hybridneus.meshing.convert import load_mesh

    return load_mesh(mesh)


def unit_cube_transform(gt: trimesh.Trimesh) -> tuple[np.ndarray, float]:
    """(centre (3,), scale) with x' = (x - centre) * scale + 0.5 mapping gt's box into [0, 1]^3."""
    lo, hi = np.asarray(gt.bounds, dtype=np.float64)
    extent = float((hi - lo).max())
    if not np.isfinite(extent) or extent <= 0.0:
        raise ValueError("ground-truth mesh has an empty bounding box")
    return 0.5 * (lo + hi), 1.0 / extent


def normalize_pair(
    pred: trimesh.Trimesh, gt: trimesh.Trimesh
) -> tuple[trimesh.Trimesh, trimesh.Trimesh]:
    """Copies of ``pred`` and ``gt`` mapped by :func:`unit_cube_transform` of ``gt``."""
    centre, scale = unit_cube_transform(gt)

    def apply(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
        v = (np.asarray(mesh.vertices, dtype=np.float64) - centre) * scale + 0.5
        return trimesh.Trimesh(v, np.asarray(mesh.faces), process=False)

    return apply(pred), apply(gt)


def normalize_eventneus(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """A copy of ``mesh`` centred on its (area-weighted) centroid and scaled so that its
    farthest vertex lies at radius 1 (the ``eventneus`` protocol)."""
    v = np.asarray(mesh.vertices, dtype=np.float64) - np.asarray(mesh.centroid, np.float64)
    radius = float(np.linalg.norm(v, axis=1).max()) if len(v) else 0.0
    if not np.isfinite(radius) or radius <= 0.0:
        raise ValueError("mesh has no extent to normalise (a point, or no vertices)")
    return trimesh.Trimesh(v / radius, np.asarray(mesh.faces), process=False)


def _seeds(seed: int, n: int) -> list[np.random.SeedSequence]:
    """Independent, reproducible child seeds, so that two meshes never share a sample stream."""
    return np.random.SeedSequence(seed).spawn(n)


def sample_surface(mesh: trimesh.Trimesh, n: int, seed) -> np.ndarray:
    """``n`` points (n, 3) uniform by area on ``mesh``, reproducible for a given seed."""
    rng = np.random.default_rng(seed)
    points, _ = trimesh.sample.sample_surface(mesh, n, seed=rng)
    return np.asarray(points, dtype=np.float64)


def chamfer_distance(
    pred: MeshLike,
    gt: MeshLike,
    n_samples: int = 10_000,
    seed: int = 0,
    threshold: float = 0.01,
    normalize: bool = True,
    protocol: str = "unit-cube",
) -> ChamferResult:
    """Chamfer distance of ``pred`` against ``gt`` under ``protocol`` (module docstring).

    Args:
        pred: predicted mesh (a trimesh or a mesh file path).
        gt: ground-truth mesh (defines the ``unit-cube`` normalisation).
        n_samples: surface samples per mesh.
        seed: sampling seed; the same seed gives the same numbers.
        threshold: F-score distance, in the protocol's units.
        normalize: normalise as the protocol says (False: world units, the mean of the two
            directions).
        protocol: ``unit-cube`` or ``eventneus``.

    Raises:
        ValueError: an unknown protocol, or (``eventneus``) a mesh without extent.
    """
    from scipy.spatial import cKDTree

    if protocol not in PROTOCOLS:
        raise ValueError(f"protocol: expected one of {', '.join(PROTOCOLS)}, got {protocol!r}")
    pred, gt = as_mesh(pred), as_mesh(gt)
    if normalize and protocol == "eventneus":
        pred, gt = normalize_eventneus(pred), normalize_eventneus(gt)
    elif normalize:
        pred, gt = normalize_pair(pred, gt)
    s_pred, s_gt = _seeds(seed, 2)
    p = sample_surface(pred, n_samples, s_pred)
    g = sample_surface(gt, n_samples, s_gt)
    d_pred, _ = cKDTree(g).query(p, k=1)
    d_gt, _ = cKDTree(p).query(g, k=1)
    accuracy, completeness = float(d_pred.mean()), float(d_gt.mean())
    precision = float((d_pred < threshold).mean())
    recall = float((d_gt < threshold).mean())
    fscore = 2 * precision * recall / (precision + recall) if precision + recall > 0 else 0.0
    summed = normalize and protocol == "eventneus"
    return ChamferResult(
        chamfer=(accuracy + completeness) * (1.0 if summed else 0.5),
        accuracy=accuracy,
        completeness=completeness,
        fscore=fscore,
        precision=precision,
        recall=recall,
        threshold=threshold,
        protocol=protocol,
    )


def chamfer_floor(gt: MeshLike, n_samples: int = 10_000, seed: int = 0,
                  protocol: str = "unit-cube") -> float:
    """The Chamfer distance of ``gt`` against a second sampling of itself under
    ``protocol``: the part of any score that is the sampling's, below which no mesh can go."""
    gt = as_mesh(gt)
    return chamfer_distance(gt, gt, n_samples, seed, protocol=protocol).chamfer


def sdf_mae_points(
    pred: trimesh.Trimesh, gt: trimesh.Trimesh, n_points: int = 10_000, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """The hybrid sample: (points (n_points, 3), is_near (n_points,) bool).

    The first half lies near the surfaces (a quarter from each mesh, perturbed within +-1% of
    the largest side of the joint box), the second half is uniform in the joint box.
    """
    s_pred, s_gt, s_noise, s_box = _seeds(seed, 4)
    lo = np.minimum(pred.bounds[0], gt.bounds[0])
    hi = np.maximum(pred.bounds[1], gt.bounds[1])
    n_near = n_points // 2
    n_pred = n_near // 2
    near = np.concatenate(
        [sample_surface(pred, n_pred, s_pred), sample_surface(gt, n_near - n_pred, s_gt)]
    )
    offset = 0.01 * float((hi - lo).max())
    near += np.random.default_rng(s_noise).uniform(-offset, offset, size=near.shape)
    uniform = np.random.default_rng(s_box).uniform(lo, hi, size=(n_points - n_near, 3))
    is_near = np.zeros(n_points, dtype=bool)
    is_near[:n_near] = True
    return np.concatenate([near, uniform]), is_near


def sdf_mae(
    pred: MeshLike,
    gt: MeshLike,
    n_points: int = 10_000,
    seed: int = 0,
    normalize: bool = True,
    sign_method: str = "auto",
) -> SdfMaeResult:
    """Mean |SDF_gt - SDF_pred| over the paper's hybrid sample (see module docstring).

    Args:
        pred: predicted mesh (a trimesh or a mesh file path).
        gt: ground-truth mesh.
        n_points: sample size (half near the surfaces, half uniform).
        seed: sampling seed.
        normalize: map both meshes into gt's unit cube first (False: world units).
        sign_method: ``auto``, ``winding`` or ``rays`` (:mod:`hybridneus.evaluation.inside`).
    """
    pred, gt = as_mesh(pred), as_mesh(gt)
    if normalize:
        pred, gt = normalize_pair(pred, gt)
    points, is_near = sdf_mae_points(pred, gt, n_points, seed)
    err = np.abs(
        signed_distance(gt, points, sign_method, seed)
        - signed_distance(pred, points, sign_method, seed)
    )
    return SdfMaeResult(
        mae=float(err.mean()),
        mae_near=float(err[is_near].mean()),
        mae_uniform=float(err[~is_near].mean()),
        n_points=int(n_points),
    )
