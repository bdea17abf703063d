"""Textured triangle meshes for the simulator: loading (OBJ/MTL, PLY, OFF, GLB) and normalisation.

A :class:`SceneMesh` flattens whatever trimesh returns (one mesh, or a Scene of parts with
their own materials) into plain arrays that the ray-casting renderer can index by triangle id:
per-corner albedo colours, per-corner UVs and a per-face texture index.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from hybridneus.errors import MeshError


@dataclass
class SceneMesh:
    """A triangle mesh with its appearance, as flat arrays.

    The albedo at a surface point is the barycentric interpolation of ``corner_colors``,
    multiplied by a bilinear texture lookup at the interpolated ``corner_uv`` when the face
    has a texture (``face_texture >= 0``). Colours are sRGB in [0, 1].

    Attributes:
        vertices: (n_vertices, 3) float64 positions.
        faces: (n_faces, 3) int64 vertex indices.
        corner_colors: (n_faces, 3, 3) float32 sRGB albedo at each face corner.
        corner_uv: (n_faces, 3, 2) float32 texture coordinates (origin bottom-left, OBJ/glTF
            convention after trimesh), zeros for untextured faces.
        face_texture: (n_faces,) int32 index into ``textures``, -1 for none.
        textures: list of (height, width, 3) float32 sRGB images.
        source: where the mesh came from (a path or ``builtin:<name>``).
    """

    vertices: np.ndarray
    faces: np.ndarray
    corner_colors: np.ndarray
    corner_uv: np.ndarray
    face_texture: np.ndarray
    textures: list[np.ndarray] = field(default_factory=list)
    source: str = ""

    @property
    def n_faces(self) -> int:
        return int(self.faces.shape[0])

    def transformed(self, scale: float, translation: np.ndarray) -> SceneMesh:
        """Return a copy with ``vertices * scale + translation`` (appearance shared)."""
        return SceneMesh(
            vertices=self.vertices * scale + np.asarray(translation, dtype=np.float64),
            faces=self.faces,
            corner_colors=self.corner_colors,
            corner_uv=self.corner_uv,
            face_texture=self.face_texture,
            textures=self.textures,
            source=self.source,
        )

    def to_trimesh(self):
        """The geometry as a ``trimesh.Trimesh`` (no appearance), e.g. for ``gt_mesh.ply``."""
        import trimesh

        return trimesh.Trimesh(self.vertices, self.faces, process=False)


def concatenate_parts(parts: list[SceneMesh], source: str = "") -> SceneMesh:
    """Merge parts into one :class:`SceneMesh`, renumbering vertices and texture indices."""
    vertices, faces, colors, uvs, face_tex, textures = [], [], [], [], [], []
    offset = 0
    for part in parts:
        vertices.append(part.vertices)
        faces.append(part.faces + offset)
        offset += part.vertices.shape[0]
        colors.append(part.corner_colors)
        uvs.append(part.corner_uv)
        ft = part.face_texture.copy()
        ft[ft >= 0] += len(textures)
        face_tex.append(ft)
        textures.extend(part.textures)
    return SceneMesh(
        vertices=np.concatenate(vertices).astype(np.float64),
        faces=np.concatenate(faces).astype(np.int64),
        corner_colors=np.concatenate(colors).astype(np.float32),
        corner_uv=np.concatenate(uvs).astype(np.float32),
        face_texture=np.concatenate(face_tex).astype(np.int32),
        textures=textures,
        source=source,
    )


def _image_to_float(image) -> np.ndarray:
    arr = np.asarray(image.convert("RGB"), dtype=np.float32) / 255.0
    return np.ascontiguousarray(arr)


def _material_texture_and_color(material) -> tuple[object | None, np.ndarray]:
    """(PIL image or None, sRGB diffuse colour (3,)) of a trimesh Simple/PBR material."""
    image = getattr(material, "image", None)
    if image is None:
        image = getattr(material, "baseColorTexture", None)
    color = getattr(material, "diffuse", None)
    if color is None:
        color = getattr(material, "baseColorFactor", None)
    if color is None:
        color = np.array([200, 200, 200, 255])
    raw = np.asarray(color).reshape(-1)[:3]
    # trimesh stores material colours as uint8 RGBA; floats are taken as [0, 1] already
    color = raw.astype(np.float32) / (255.0 if raw.dtype.kind in "ui" else 1.0)
    return image, np.clip(color, 0.0, 1.0)


def part_from_trimesh(mesh, default_color=(0.8, 0.8, 0.8)) -> SceneMesh:
    """Convert one ``trimesh.Trimesh`` (with texture, face or vertex colours) to a part.

    A textured material uses its image alone (the MTL ``Kd`` that often accompanies a
    ``map_Kd`` is ignored, as Blender's importer does); a material without image or UVs uses
    its diffuse colour; colour visuals use their face or vertex colours.
    """
    faces = np.asarray(mesh.faces, dtype=np.int64)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    n_faces = faces.shape[0]
    colors = np.broadcast_to(np.asarray(default_color, np.float32), (n_faces, 3, 3)).copy()
    uvs = np.zeros((n_faces, 3, 2), np.float32)
    face_tex = np.full(n_faces, -1, np.int32)
    textures: list[np.ndarray] = []
    visual = mesh.visual
    kind = getattr(visual, "kind", None)
    material = getattr(visual, "material", None)
    if material is not None:
        image, color = _material_texture_and_color(material)
        uv = getattr(visual, "uv", None)
        if image is not None and uv is not None and len(uv) == len(vertices):
            textures.append(_image_to_float(image))
            uvs = np.asarray(uv, np.float32)[faces]
            colors[:] = 1.0
            face_tex[:] = 0
        else:
            colors[:] = color
    elif kind == "face":
        fc = np.asarray(visual.face_colors, np.float32)[:, :3] / 255.0
        colors[:] = fc[:, None, :]
    elif kind == "vertex":
        vc = np.asarray(visual.vertex_colors, np.float32)[:, :3] / 255.0
        colors = vc[faces]
    return SceneMesh(vertices, faces, colors, uvs, face_tex, textures)


def load_mesh(path: str | os.PathLike) -> SceneMesh:
    """Load a mesh file (OBJ with MTL and textures, PLY, OFF, GLB/GLTF, STL) as a SceneMesh.

    Multi-material files that trimesh returns as a Scene are flattened part by part (with the
    scene graph's transforms applied), so that every part keeps its own texture.

    Raises:
        MeshError: the file is missing, unreadable, or holds no triangles.
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: no such mesh file")
    try:
        loaded = trimesh.load(path, process=False)
    except Exception as exc:  # trimesh raises many types for malformed files
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise MeshError(f"{path}: cannot read mesh ({msg})") from None
    if isinstance(loaded, trimesh.Scene):
        geoms = [g for g in loaded.dump() if isinstance(g, trimesh.Trimesh)]
    elif isinstance(loaded, trimesh.Trimesh):
        geoms = [loaded]
    else:
        geoms = []
    geoms = [g for g in geoms if len(g.faces) > 0]
    if not geoms:
        raise MeshError(f"{path}: no triangles in the file")
    parts = [part_from_trimesh(g) for g in geoms]
    mesh = concatenate_parts(parts, source=str(path))
    if not np.all(np.isfinite(mesh.vertices)):
        raise MeshError(f"{path}: vertex positions are not all finite")
    return mesh


@dataclass(frozen=True)
class Normalization:
    """World = source * scale + translation (world y is the source's y: assets are y-up).

    Attributes:
        scale: uniform scale factor.
        translation: (3,) translation applied after scaling.
        center: (3,) source-space centre of the bounding sphere (axis-aligned box centre).
        radius: source-space bounding-sphere radius about ``center``.
    """

    scale: float
    translation: tuple[float, float, float]
    center: tuple[float, float, float]
    radius: float

    def to_json(self) -> dict:
        return {
            "scale": self.scale,
            "translation": list(self.translation),
            "source_center": list(self.center),
            "source_radius": self.radius,
            "convention": "world = source * scale + translation; y-up kept (no rotation)",
        }


def normalization_for(mesh: SceneMesh, object_radius: float) -> Normalization:
    """Scale and shift that put the mesh's bounding sphere at the origin with ``object_radius``.

    The sphere is centred on the axis-aligned bounding box centre (not the minimal sphere, so
    the transform is easy to reproduce) with radius the farthest vertex from that centre.
    """
    used = np.unique(mesh.faces)
    verts = mesh.vertices[used]
    center = 0.5 * (verts.min(axis=0) + verts.max(axis=0))
    radius = float(np.linalg.norm(verts - center, axis=1).max())
    if not radius > 0:
        raise MeshError(f"{mesh.source}: mesh is degenerate (zero extent)")
    scale = object_radius / radius
    translation = -center * scale
    return Normalization(
        scale=float(scale),
        translation=tuple(float(v) for v in translation),
        center=tuple(float(v) for v in center),
        radius=radius,
    )
