"""``extract_mesh``: a field's zero level as a clean, optionally coloured, triangle mesh.

The narrow-band marching cubes is :mod:`hybridneus.meshing.narrowband`; the unseen pockets it
can fill first are :mod:`hybridneus.meshing.unseen`; the clean-up is
:mod:`hybridneus.meshing.postprocess`; the colours :mod:`hybridneus.meshing.color`.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import trimesh

from hybridneus.meshing.narrowband import ExtractionStats, extract_sdf_mesh
from hybridneus.meshing.postprocess import PostprocessOptions
from hybridneus.meshing.volume import DEFAULT_BOUNDS, Bounds, CropVolume
from hybridneus.model.protocol import Field


def _examined_box(field_: Field, bounds: Bounds | None, crop: CropVolume | None) -> Bounds:
    """Where to look for unseen space: the crop's padded box (the given one, else the
    field's own), else ``bounds``, else the default volume."""
    crop = crop if crop is not None else CropVolume.of_field(field_)
    if crop is not None:
        return crop.padded_bounds()
    return bounds if bounds is not None else DEFAULT_BOUNDS


def extract_mesh(
    field_: Field,
    res: int = 300,
    bounds: Bounds | None = None,
    crop: CropVolume | None = None,
    clip: bool = True,
    color: bool = False,
    chunk: int = 2**18,
    narrow_band: bool = True,
    postprocess: PostprocessOptions | None = None,
    progress: bool = True,
    stats: ExtractionStats | None = None,
    color_normals: str = "mesh",
    cameras: np.ndarray | None = None,
    fill_radius: float = 0.1,
    fill_thickness: float = 4.0,
) -> trimesh.Trimesh:
    """Extract the zero level of ``field_`` as a triangle mesh in world coordinates.

    With ``cameras``, the pockets of empty space that no camera sees are first filled
    (:mod:`~hybridneus.meshing.unseen`). Then marching cubes on a grid with ``res`` points
    along the longest side of the volume
    (narrow-band evaluation, bounded memory; see :func:`extract_sdf_mesh`), then clean-up
    (:func:`~hybridneus.meshing.postprocess.postprocess_mesh`), then, with ``color``, vertex
    colours from the colour head (:func:`~hybridneus.meshing.color.vertex_colors`).

    Args:
        field_: any :class:`~hybridneus.model.protocol.Field` (e.g. a trained run, or
            :class:`~hybridneus.model.analytic.SphereField`).
        res: grid points along the longest side of the volume.
        bounds: world box ((x0, y0, z0), (x1, y1, z1)); default the crop's box, else
            [-1, 1]^3. Give ``DEFAULT_BOUNDS`` to mesh the whole volume of a cropped field.
        crop: crop cylinder; its (padded) box is meshed when ``bounds`` is not given.
            Default (with no ``bounds`` either): the field's own crop (a trained field's,
            :meth:`CropVolume.of_field`), so that ``res`` points span the object's region as
            in ``hybridneus mesh`` rather than the whole cube, whose voxels are two to three
            times larger and lose parts a few pixels thin.
        clip: clip the mesh to ``crop`` (when ``postprocess.clip`` is None).
        color: attach uint8 vertex colours.
        chunk: points per field query.
        narrow_band: evaluate the fine grid only near the surface.
        postprocess: clean-up options; ``PostprocessOptions(enabled=False)`` for the raw mesh.
        progress: progress bar on stderr.
        stats: if given, filled with counts and timings.
        color_normals: view direction for colours: ``"mesh"`` (-vertex normal, forward
            queries only) or ``"gradient"`` (-SDF gradient at each grid corner, slower).
        cameras: centres (n_views, 3) of the training cameras; when given, empty space that
            they cannot see and that matter nearly surrounds is filled before meshing
            (:func:`~hybridneus.meshing.unseen.unseen_space`, examined over the crop's box,
            or ``bounds``). None meshes the field as it is.
        fill_radius: the closing radius of that fill, as a fraction of the examined box's
            longest side.
        fill_thickness: parts of the fill thinner than this many voxels of its 128-point
            grid are left empty (:func:`~hybridneus.meshing.unseen.unseen_space`).

    Returns:
        ``trimesh.Trimesh`` with outward normals; ``visual.vertex_colors`` set when ``color``.

    Example:
        >>> from hybridneus.model.analytic import SphereField
        >>> mesh = extract_mesh(SphereField(0.5), res=64, progress=False)
        >>> bool(abs(mesh.vertices.max() - 0.5) < 0.01)
        True
    """

    from hybridneus.meshing.color import to_uint8, vertex_colors
    from hybridneus.meshing.postprocess import postprocess_mesh

    if color_normals not in ("mesh", "gradient"):
        raise ValueError(f"color_normals {color_normals!r}: expected 'mesh' or 'gradient'")
    if bounds is None and crop is None:
        crop = CropVolume.of_field(field_)
    options = postprocess if postprocess is not None else PostprocessOptions()
    if clip and crop is not None and options.clip is None and options.enabled:
        options = dataclasses.replace(options, clip=crop)
    source, unseen_s, filled = field_, 0.0, 0
    if cameras is not None:
        from hybridneus.meshing.unseen import FilledField, unseen_space

        t0 = time.perf_counter()
        unseen = unseen_space(field_, cameras, _examined_box(field_, bounds, crop),
                              close_radius=fill_radius, min_thickness=fill_thickness,
                              chunk=chunk)
        unseen_s, filled = time.perf_counter() - t0, unseen.filled
        if unseen.filled:
            source = FilledField(field_, unseen)
    mesh, grid, run_stats = extract_sdf_mesh(
        source, res, bounds, crop, chunk=chunk, narrow_band=narrow_band, progress=progress
    )
    run_stats.filled_voxels = filled
    if cameras is not None:
        run_stats.times["unseen"] = unseen_s
    if options.clip is not None and options.clip_margin is None:
        options = dataclasses.replace(options, clip_margin=0.5 * grid.voxel)
    if options.clip is not None and options.trim_tolerance is None:
        options = dataclasses.replace(options, trim_tolerance=grid.voxel)
    t0 = time.perf_counter()
    mesh = postprocess_mesh(mesh, options)
    run_stats.times["postprocess"] = time.perf_counter() - t0
    if color and len(mesh.vertices):
        t0 = time.perf_counter()
        normals = np.asarray(mesh.vertex_normals) if color_normals == "mesh" else None
        rgb = vertex_colors(
            field_, np.asarray(mesh.vertices), grid, normals, chunk=min(chunk, 2**16)
        )
        mesh = trimesh.Trimesh(
            mesh.vertices, mesh.faces, vertex_colors=to_uint8(rgb), process=False
        )
        run_stats.times["color"] = time.perf_counter() - t0
    if stats is not None:
        stats.__dict__.update(run_stats.__dict__)
    return mesh
