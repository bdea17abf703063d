"""Mesh clean-up after marching cubes: clip, weld, de-duplicate, repair, drop floaters, decimate.

Order (each step optional, see :class:`PostprocessOptions`):
    1. clip to the crop cylinder (faces with a vertex outside are dropped), then trim the
       crop's cut (faces lying on the cylinder: the cap that closes matter reaching the crop);
    2. merge vertices closer than ``merge_distance``; remove duplicate and zero-area faces;
    3. repair non-manifold edges (by removing faces) and vertices (by splitting);
    4. remove connected components smaller than ``min_component_diameter`` (fraction of the
       whole mesh's bounding-box diagonal; small components within ``component_gap`` of each
       other are judged as one, see :func:`remove_small_components`) and/or with fewer than
       ``min_component_faces`` faces;
    5. ``remove_cavities``: drop closed components that face inwards (the walls of hollows
       inside matter, which no camera can see);
    6. ``keep_largest``: keep only the component with the most faces;
    7. quadric edge-collapse decimation to ``decimate`` faces.
Vertex colours (``mesh.visual.vertex_colors``) survive every step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from hybridneus.meshing.volume import CropVolume


@dataclass
class PostprocessOptions:
    """Which clean-up steps :func:`postprocess_mesh` runs (defaults: all cleaning, no decimation).

    Attributes:
        enabled: run post-processing at all.
        merge_distance: weld vertices closer than this (world units); None = 1e-5 x diagonal.
        remove_duplicate_faces: drop repeated and zero-area faces.
        repair_non_manifold: remove faces on non-manifold edges, split non-manifold vertices.
        min_component_diameter: drop components whose bounding-box diagonal is below this
            fraction of the whole mesh's diagonal (0.05 = 5%); None or 0 disables.
        component_gap: small components (those below ``min_component_diameter``) closer than
            this fraction of the whole mesh's diagonal to each other are judged together, by
            the diagonal of their joint bounding box; None or 0 judges each alone.
        min_component_faces: drop components with fewer faces; None or 0 disables.
        remove_cavities: drop closed components with negative signed volume: the inner
            walls of hollows enclosed by matter (see :func:`remove_cavities`).
        keep_largest: keep only the connected component with the most faces.
        decimate: target face count for quadric decimation; None disables.
        clip: crop cylinder to clip the mesh to; None disables.
        clip_margin: grow the cylinder by this much (world units) before clipping, so that
            surfaces lying on it survive marching-cubes jitter; None = 0 here and half a
            voxel in :func:`~hybridneus.meshing.extract.extract_mesh`.
        trim_crop: with ``clip``, also drop the cap that the crop puts on matter reaching
            it: faces within ``trim_tolerance`` of the cylinder and facing along its normal
            (see :func:`trim_crop_cut`). Off by default, since it leaves the mesh open.
        trim_tolerance: world units; None = ``clip_margin`` here and one voxel in
            :func:`~hybridneus.meshing.extract.extract_mesh` (a vertex on the cut can sit up to
            a voxel from the cylinder where the field's own SDF is shallow).
    """

    enabled: bool = True
    merge_distance: float | None = None
    remove_duplicate_faces: bool = True
    repair_non_manifold: bool = True
    min_component_diameter: float | None = 0.05
    component_gap: float | None = 0.01
    min_component_faces: int | None = None
    remove_cavities: bool = True
    keep_largest: bool = False
    decimate: int | None = None
    clip: CropVolume | None = None
    clip_margin: float | None = None
    trim_crop: bool = False
    trim_tolerance: float | None = None


def _vertex_colors(mesh: trimesh.Trimesh) -> np.ndarray | None:
    """The mesh's uint8 RGBA vertex colours (n_vertices, 4), or None when it has none."""
    if mesh.visual.kind != "vertex":
        return None
    colors = np.asarray(mesh.visual.vertex_colors)
    return colors if colors.shape[0] == mesh.vertices.shape[0] else None


def _rebuild(
    vertices: np.ndarray, faces: np.ndarray, colors: np.ndarray | None
) -> trimesh.Trimesh:
    """A trimesh without trimesh's own processing, keeping colours and dropping stray vertices."""
    used = np.zeros(vertices.shape[0], dtype=bool)
    used[faces.reshape(-1)] = True
    remap = np.cumsum(used) - 1
    kwargs = {}
    if colors is not None:
        kwargs["vertex_colors"] = colors[used]
    return trimesh.Trimesh(vertices[used], remap[faces], process=False, **kwargs)


def _to_meshset(mesh: trimesh.Trimesh, colors: np.ndarray | None):  # -> pymeshlab.MeshSet
    """A pymeshlab MeshSet holding ``mesh`` (float64 vertices, int32 faces, float colours)."""
    import pymeshlab

    kwargs = {}
    if colors is not None:
        kwargs["v_color_matrix"] = colors.astype(np.float64) / 255.0
    ms = pymeshlab.MeshSet()
    ms.add_mesh(
        pymeshlab.Mesh(
            vertex_matrix=np.asarray(mesh.vertices, dtype=np.float64),
            face_matrix=np.asarray(mesh.faces, dtype=np.int32),
            **kwargs,
        )
    )
    return ms


def _from_meshset(ms, with_colors: bool) -> trimesh.Trimesh:
    """The current mesh of a pymeshlab MeshSet as a trimesh (uint8 colours if asked)."""
    out = ms.current_mesh()
    colors = None
    if with_colors:
        colors = np.clip(np.round(out.vertex_color_matrix() * 255.0), 0, 255).astype(np.uint8)
    return _rebuild(out.vertex_matrix(), out.face_matrix().astype(np.int64), colors)


def clip_mesh(mesh: trimesh.Trimesh, crop: CropVolume, margin: float = 0.0) -> trimesh.Trimesh:
    """Drop faces with any vertex outside ``crop`` grown by ``margin``; keep colours."""
    inside = crop.contains(np.asarray(mesh.vertices), margin=margin + 1e-9)
    keep = inside[mesh.faces].all(axis=1)
    return _rebuild(np.asarray(mesh.vertices), np.asarray(mesh.faces)[keep], _vertex_colors(mesh))


def trim_crop_cut(
    mesh: trimesh.Trimesh, crop: CropVolume, tolerance: float, min_cos: float = 0.9
) -> trimesh.Trimesh:
    """Drop the faces that lie on the crop's surface and face the way it does.

    Where matter reaches the crop, the cropped SDF ``max(sdf, crop_sdf)`` closes it with a
    cap on the cylinder; no view supervised that cap (the crop is a user's box, and density
    outside it is zero), so it is a cut, not a reconstructed surface. A face is part of the
    cap when its three vertices lie within ``tolerance`` of the cylinder and its normal is
    within ``arccos(min_cos)`` of the cylinder's outward normal (so a surface that crosses
    the crop at an angle keeps its faces up to the rim). The mesh is left open there;
    colours are kept.
    """
    vertices, faces = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    if faces.shape[0] == 0:
        return mesh
    near = crop.boundary_distance(vertices)[faces].max(axis=1) <= tolerance
    along = (np.asarray(mesh.face_normals) * crop.boundary_normal(
        vertices[faces].mean(axis=1))).sum(axis=1) >= min_cos
    keep = ~(near & along)
    return _rebuild(vertices, faces[keep], _vertex_colors(mesh))


def face_components(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Connected-component label (n_faces,) of each face (faces sharing a vertex are joined)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if faces.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    rows = np.concatenate([faces[:, 0], faces[:, 1]])
    cols = np.concatenate([faces[:, 1], faces[:, 2]])
    graph = coo_matrix((np.ones(rows.size, dtype=np.int8), (rows, cols)), (n_vertices,) * 2)
    _, labels = connected_components(graph, directed=False)
    return labels[faces[:, 0]]


def remove_cavities(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Drop the closed components whose faces point inwards (negative signed volume).

    Marching cubes orients faces from matter (SDF < 0) towards free space, so a closed
    component encloses matter when its signed volume is positive and encloses a hollow in
    matter when it is negative. No camera sees into a closed hollow; a trained field can
    still leave one where the data say nothing (an event-poor, uniformly coloured interior),
    and its wall then counts as surface. Open components (cut by a clip or trim) are kept,
    since their volume has no sign. Colours are kept.
    """
    faces = np.asarray(mesh.faces)
    if faces.shape[0] == 0:
        return mesh
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    labels = face_components(faces, vertices.shape[0])
    tri = vertices[faces]
    volume = np.bincount(
        labels, weights=np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])) / 6.0
    )
    edge_index = np.asarray(mesh.edges_unique_inverse)  # trimesh's hashed edge ids
    open_edge = np.bincount(edge_index)[edge_index] != 2
    is_open = np.bincount(labels[np.asarray(mesh.edges_face)[open_edge]], minlength=volume.size)
    cavity = (volume < 0) & (is_open == 0)
    if not cavity.any():
        return mesh
    return _rebuild(vertices, faces[~cavity[labels]], _vertex_colors(mesh))


def remove_small_components(
    mesh: trimesh.Trimesh, min_diameter: float, gap: float = 0.0
) -> trimesh.Trimesh:
    """Drop the connected components whose bounding-box diagonal is below ``min_diameter``.

    A thin part that the field holds all along (a wire, a rod one or two voxels wide) often
    comes out of marching cubes as a chain of short pieces, each far below any sensible
    floater size, with gaps of a voxel or two between them; a floater is a lump alone in free
    space. So the small components are first joined wherever two of them come closer than
    ``gap`` (world units, vertex to vertex), and a group is kept when its joint bounding box
    reaches ``min_diameter``. Only small components join each other: lying next to the main
    body does not save a lump. ``gap`` = 0 judges each component alone. Colours are kept.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    faces = np.asarray(mesh.faces)
    if faces.shape[0] == 0:
        return mesh
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    face_label = face_components(faces, vertices.shape[0])
    n = int(face_label.max()) + 1
    vertex_label = np.full(vertices.shape[0], -1, dtype=np.int64)
    vertex_label[faces.reshape(-1)] = np.repeat(face_label, 3)
    used = vertex_label >= 0
    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    np.minimum.at(lo, vertex_label[used], vertices[used])
    np.maximum.at(hi, vertex_label[used], vertices[used])
    small = np.linalg.norm(hi - lo, axis=1) < min_diameter
    if not small.any():
        return mesh
    group = np.arange(n)
    if gap > 0:
        members = np.flatnonzero(used & small[np.maximum(vertex_label, 0)])
        pairs = cKDTree(vertices[members]).query_pairs(gap, output_type="ndarray")
        a, b = vertex_label[members[pairs[:, 0]]], vertex_label[members[pairs[:, 1]]]
        link = a != b
        graph = coo_matrix((np.ones(int(link.sum()), dtype=np.int8), (a[link], b[link])), (n, n))
        _, group = connected_components(graph, directed=False)
        n_groups = int(group.max()) + 1
        glo = np.full((n_groups, 3), np.inf)
        ghi = np.full((n_groups, 3), -np.inf)
        np.minimum.at(glo, group, lo)
        np.maximum.at(ghi, group, hi)
        lo, hi = glo[group], ghi[group]
    drop = small & (np.linalg.norm(hi - lo, axis=1) < min_diameter)
    if not drop.any():
        return mesh
    return _rebuild(vertices, faces[~drop[face_label]], _vertex_colors(mesh))


def keep_largest_component(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Only the connected component with the most faces (colours kept)."""
    faces = np.asarray(mesh.faces)
    if faces.shape[0] == 0:
        return mesh
    labels = face_components(faces, mesh.vertices.shape[0])
    largest = np.bincount(labels).argmax()
    return _rebuild(np.asarray(mesh.vertices), faces[labels == largest], _vertex_colors(mesh))


def postprocess_mesh(
    mesh: trimesh.Trimesh, options: PostprocessOptions | None = None
) -> trimesh.Trimesh:
    """Clean ``mesh`` as described in the module docstring; returns a new mesh.

    Args:
        mesh: triangle mesh in world coordinates, with optional vertex colours.
        options: which steps to run; default :class:`PostprocessOptions()`.
    """
    import pymeshlab

    options = options or PostprocessOptions()
    if not options.enabled or len(mesh.faces) == 0:
        return mesh
    if options.clip is not None:
        mesh = clip_mesh(mesh, options.clip, options.clip_margin or 0.0)
        if options.trim_crop:
            tolerance = options.trim_tolerance
            mesh = trim_crop_cut(mesh, options.clip, tolerance if tolerance is not None
                                 else options.clip_margin or 0.0)
        if len(mesh.faces) == 0:
            return mesh

    colors = _vertex_colors(mesh)
    ms = _to_meshset(mesh, colors)
    diag = float(np.linalg.norm(np.ptp(np.asarray(mesh.vertices), axis=0)))
    merge = options.merge_distance if options.merge_distance is not None else 1e-5 * diag
    if merge > 0:
        ms.meshing_merge_close_vertices(threshold=pymeshlab.PureValue(merge))
    if options.remove_duplicate_faces:
        ms.meshing_remove_duplicate_faces()
        ms.meshing_remove_null_faces()
    if options.repair_non_manifold:
        ms.meshing_repair_non_manifold_edges(method="Remove Faces")
        ms.meshing_repair_non_manifold_vertices()
    if options.min_component_faces:
        ms.meshing_remove_connected_component_by_face_number(
            mincomponentsize=int(options.min_component_faces)
        )
    ms.meshing_remove_unreferenced_vertices()
    result = _from_meshset(ms, colors is not None)
    if options.min_component_diameter:
        result = remove_small_components(
            result, options.min_component_diameter * diag, (options.component_gap or 0.0) * diag
        )
    if options.remove_cavities:
        result = remove_cavities(result)
    if options.keep_largest:
        result = keep_largest_component(result)
    if options.decimate and len(result.faces) > options.decimate:
        result = decimate_mesh(result, options.decimate)
    return result


def decimate_mesh(mesh: trimesh.Trimesh, target_faces: int) -> trimesh.Trimesh:
    """Quadric edge-collapse decimation (pymeshlab) to about ``target_faces`` faces."""
    colors = _vertex_colors(mesh)
    ms = _to_meshset(mesh, colors)
    ms.meshing_decimation_quadric_edge_collapse(
        targetfacenum=int(target_faces), preservenormal=True, optimalplacement=True, autoclean=True
    )
    ms.meshing_remove_unreferenced_vertices()
    return _from_meshset(ms, colors is not None)
