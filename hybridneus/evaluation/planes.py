"""How flat a mesh keeps the flat faces of its ground truth: RMS distance to their planes.

Chamfer mixes a lumpy face with a missing part; this measures the lumps. The ground truth's
planar faces are its facets (trimesh's groups of adjacent coplanar triangles) of at least
``min_area`` of its surface. The mesh is sampled uniformly by area; a sample counts for the
face whose triangle holds its closest ground-truth point, when that point lies at least
``border`` inside the face's outline (so that the rounding of an edge or a corner, a separate
error, is left out) and the sample lies within ``max_distance`` of it (so that a floater or a
neighbouring part is left out). Its error is its signed distance to the face's plane, positive
outside. Everything is in the ground truth's unit cube (as :mod:`.geometry`'s ``unit-cube``
protocol), so the numbers compare with its Chamfer distances.

Per face: the RMS of the signed distances (the lumps and any offset of the whole face), their
median (the offset alone: a face sunk into a dish or standing out), and the share of the
face's interior that the counted samples cover (a face the mesh lost scores no RMS at all, so
read the two together). :func:`plane_rms` pools all faces' samples into one RMS.

A face no camera looks at (the underside of an object standing on a table, under a path that
stays above it) is not evidence of anything the fit did with the events: given the camera
centres, each face says how many cameras lie in front of its plane by at least
``MIN_ELEVATION`` degrees, and :func:`plane_rms` leaves out the faces none does.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
import trimesh

from hybridneus.evaluation.geometry import (
    MeshLike,
    as_mesh,
    normalize_pair,
    sample_surface,
    unit_cube_transform,
)

#: A camera sees a face's side when it lies at least this many degrees above the face's plane,
#: seen from the face's centre (a face seen only edge-on is not seen).
MIN_ELEVATION = 5.0


@dataclass
class PlaneResult:
    """One planar face of the ground truth against the mesh (unit-cube units).

    Attributes:
        index: rank of the face by area (0: the largest).
        area: the face's area.
        normal: its outward unit normal.
        rms: root mean square of the counted samples' signed distances to the face's plane.
        offset: their median (positive: the mesh stands out of the face; negative: sunk).
        coverage: counted samples per unit of the face's interior area, over the mesh's
            samples per unit of its own area (about 1 where the mesh covers the face once).
        samples: how many mesh samples counted for the face.
        views: how many of the given camera centres see the face's side (see the module
            docstring); None when no cameras were given.
    """

    index: int
    area: float
    normal: tuple[float, float, float]
    rms: float
    offset: float
    coverage: float
    samples: int
    views: int | None = None

    def as_dict(self) -> dict:
        return asdict(self)


def planar_faces(gt: trimesh.Trimesh, min_area: float = 0.02) -> list[np.ndarray]:
    """The facets of ``gt`` (arrays of triangle indices) holding at least ``min_area`` of its
    surface, largest first."""
    merged = gt.copy()
    merged.merge_vertices()  # facets need shared vertices; the triangles keep their order
    if not len(merged.facets):
        return []
    areas = np.asarray(merged.facets_area)
    keep = np.flatnonzero(areas >= min_area * merged.area)
    order = keep[np.argsort(-areas[keep])]
    return [np.asarray(merged.facets[i]) for i in order]


def _outline(mesh: trimesh.Trimesh, triangles: np.ndarray) -> np.ndarray:
    """The segments (n, 2, 3) of the outline of the facet made of ``triangles``."""
    edges = np.sort(mesh.faces[triangles][:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    unique, counts = np.unique(edges, axis=0, return_counts=True)
    return mesh.vertices[unique[counts == 1]]


def _distance_to_segments(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Distance (n,) from each point (n, 3) to the nearest of ``segments`` (m, 2, 3)."""
    best = np.full(len(points), np.inf)
    a, b = segments[:, 0], segments[:, 1]
    ab = b - a
    length2 = np.maximum((ab * ab).sum(1), 1e-30)
    for start in range(0, len(segments), 256):  # bounded memory for long outlines
        sa, sab, sl = a[start:start + 256], ab[start:start + 256], length2[start:start + 256]
        rel = points[:, None, :] - sa[None]
        t = np.clip((rel * sab[None]).sum(-1) / sl[None], 0.0, 1.0)
        d = np.linalg.norm(rel - t[..., None] * sab[None], axis=-1)
        best = np.minimum(best, d.min(axis=1))
    return best


def plane_errors(
    mesh: MeshLike,
    gt: MeshLike,
    min_area: float = 0.02,
    border: float = 0.02,
    max_distance: float = 0.05,
    n_samples: int = 200_000,
    seed: int = 0,
    cameras: np.ndarray | None = None,
) -> list[PlaneResult]:
    """The error of ``mesh`` on each planar face of ``gt``, largest face first (see the module
    docstring; ``border`` and ``max_distance`` in the ground truth's unit cube). An empty list
    where ``gt`` has no face of ``min_area``; a face no sample counted for has NaN RMS.
    ``cameras``: camera centres (n, 3) in the frame of the meshes, to count each face's
    ``views``."""
    import open3d as o3d

    gt = as_mesh(gt)
    pred, truth = normalize_pair(as_mesh(mesh), gt)
    truth.merge_vertices()  # outlines need shared vertices
    faces = planar_faces(truth, min_area)
    eyes = None
    if cameras is not None:
        centre, scale = unit_cube_transform(gt)
        eyes = (np.asarray(cameras, np.float64).reshape(-1, 3) - centre) * scale + 0.5

    def views(f: np.ndarray) -> int | None:
        if eyes is None:
            return None
        middle = (truth.triangles_center[f] * truth.area_faces[f, None]).sum(0) / \
            truth.area_faces[f].sum()
        ray = eyes - middle
        sine = ray @ truth.face_normals[f[0]] / np.linalg.norm(ray, axis=1)
        return int((sine > np.sin(np.radians(MIN_ELEVATION))).sum())

    if not faces or not len(pred.faces):
        return [PlaneResult(i, float(truth.area_faces[f].sum()),
                            tuple(float(v) for v in truth.face_normals[f[0]]),
                            float("nan"), float("nan"), 0.0, 0, views(f))
                for i, f in enumerate(faces)]
    points = sample_surface(pred, n_samples, seed)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.t.geometry.TriangleMesh(
        o3d.core.Tensor(np.asarray(truth.vertices, np.float32)),
        o3d.core.Tensor(np.asarray(truth.faces, np.int32))))
    closest = scene.compute_closest_points(
        o3d.core.Tensor(np.ascontiguousarray(points, dtype=np.float32)))
    nearest = closest["points"].numpy().astype(np.float64)
    triangle = closest["primitive_ids"].numpy().astype(np.int64)
    gap = np.linalg.norm(points - nearest, axis=1)
    owner = np.full(len(truth.faces), -1, np.int64)
    for i, f in enumerate(faces):
        owner[f] = i
    density = n_samples / pred.area
    results = []
    for i, f in enumerate(faces):
        normal = truth.face_normals[f[0]]
        origin = truth.vertices[truth.faces[f[0], 0]]
        area = float(truth.area_faces[f].sum())
        near = np.flatnonzero((owner[triangle] == i) & (gap <= max_distance))
        inner = near[_distance_to_segments(nearest[near], _outline(truth, f)) >= border]
        # The interior's area, from the face's own samples (an outline may be any polygon).
        probe = sample_surface(truth.submesh([f], append=True), 4000, seed + 1 + i)
        inner_share = float((_distance_to_segments(probe, _outline(truth, f)) >= border).mean())
        signed = (points[inner] - origin) @ normal
        rms = float(np.sqrt(np.mean(signed**2))) if len(inner) else float("nan")
        offset = float(np.median(signed)) if len(inner) else float("nan")
        coverage = len(inner) / (density * area * inner_share) if inner_share > 0 else 0.0
        results.append(PlaneResult(i, area, tuple(float(v) for v in normal), rms, offset,
                                   float(coverage), int(len(inner)), views(f)))
    return results


def plane_rms(results: list[PlaneResult]) -> float:
    """One RMS over the counted samples of all faces that a camera sees (all faces, when no
    cameras were given); NaN when none counted."""
    kept = [r for r in results if r.samples and r.views != 0]
    n = sum(r.samples for r in kept)
    if n == 0:
        return float("nan")
    return float(np.sqrt(sum(r.samples * r.rms**2 for r in kept) / n))
