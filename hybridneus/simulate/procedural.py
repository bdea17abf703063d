"""Built-in procedural scenes that need no files: ``device`` and ``thin``.

- ``device``: a handheld, multimeter-like device standing upright (y up): a rounded box with
  a procedurally drawn texture (screen with digits, coloured bands, grip stripes on the
  sides), four coloured buttons and a dial with a pointer on the front (+z).
- ``thin``: a tripod stand with thin legs, a pole, a vertical ring with a rainbow of vertex
  colours and a small ball on top: thin parts that event-based reconstruction finds hard.

Sizes are arbitrary; :func:`hybridneus.simulate.scene_mesh.normalization_for` rescales them.
"""

from __future__ import annotations

import numpy as np

from hybridneus.errors import MeshError
from hybridneus.simulate.scene_mesh import SceneMesh, concatenate_parts, part_from_trimesh

#: Names accepted by :func:`builtin_scene` (and ``builtin:<name>`` on the CLI).
BUILTIN_SCENES = ("device", "thin")

# (normal, s axis, t axis) of the six box faces; s x t = normal, so grids wind outwards.
_BOX_FACES = (
    ((0, 0, 1), (1, 0, 0), (0, 1, 0)),
    ((0, 0, -1), (-1, 0, 0), (0, 1, 0)),
    ((1, 0, 0), (0, 0, -1), (0, 1, 0)),
    ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
    ((0, 1, 0), (1, 0, 0), (0, 0, -1)),
    ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
)
_CELL = 128  # texture atlas cell size (px): 3 columns x 2 rows, one cell per box face


def _rounded_box(half: np.ndarray, radius: float, n: int) -> SceneMesh:
    """A rounded box with one textured atlas cell per face; UVs span each cell."""
    verts, faces, uvs = [], [], []
    g = np.linspace(0.0, 1.0, n + 1)
    s, t = np.meshgrid(g, g, indexing="xy")
    s, t = s.reshape(-1), t.reshape(-1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quad = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    tris = np.concatenate([quad[:, [0, 1, 2]], quad[:, [0, 2, 3]]])
    inner = half - radius
    for fi, (nrm, sa, ta) in enumerate(_BOX_FACES):
        nrm, sa, ta = (np.asarray(a, np.float64) for a in (nrm, sa, ta))
        p = (nrm * np.abs(nrm @ half)
             + (2 * s - 1)[:, None] * sa * np.abs(sa @ half)
             + (2 * t - 1)[:, None] * ta * np.abs(ta @ half))
        q = np.clip(p, -inner, inner)
        d = p - q
        p = q + radius * d / np.linalg.norm(d, axis=1, keepdims=True)
        col, row = fi % 3, fi // 3
        uv = np.stack([(col + s) / 3.0, (row + t) / 2.0], -1)
        faces.append(tris + len(verts) * (n + 1) ** 2)
        verts.append(p)
        uvs.append(uv)
    verts, faces, uvs = np.concatenate(verts), np.concatenate(faces), np.concatenate(uvs)
    tex = _device_texture()
    n_f = faces.shape[0]
    return SceneMesh(verts, faces, np.ones((n_f, 3, 3), np.float32),
                     uvs[faces].astype(np.float32), np.zeros(n_f, np.int32), [tex])


def _device_texture() -> np.ndarray:
    """A 2 x 3 atlas (256 x 384 px) of face images drawn with numpy (rows: t up)."""
    body = np.array([0.95, 0.72, 0.12], np.float32)  # yellow casing
    dark = np.array([0.12, 0.12, 0.14], np.float32)
    atlas = np.zeros((2 * _CELL, 3 * _CELL, 3), np.float32)
    t, s = np.meshgrid((np.arange(_CELL) + 0.5) / _CELL, (np.arange(_CELL) + 0.5) / _CELL,
                       indexing="ij")
    for fi in range(6):
        img = np.broadcast_to(body, (_CELL, _CELL, 3)).copy()
        if fi == 0:  # front: screen with segment "digits", a dark band and a red stripe
            screen = (s > 0.15) & (s < 0.85) & (t > 0.62) & (t < 0.9)
            img[screen] = (0.55, 0.68, 0.55)
            for k in range(4):
                x0 = 0.2 + 0.165 * k
                seg = ((s > x0) & (s < x0 + 0.11) & (t > 0.66) & (t < 0.86)
                       & ~((s > x0 + 0.025) & (s < x0 + 0.085)
                           & (((t > 0.69) & (t < 0.75)) | ((t > 0.78) & (t < 0.83)))))
                img[seg & screen] = (0.08, 0.12, 0.1)
            img[(t > 0.05) & (t < 0.14)] = dark
            img[(t > 0.55) & (t < 0.58)] = (0.8, 0.1, 0.1)
        elif fi in (2, 3):  # sides: grip stripes
            img[(np.floor(t * 12) % 2 == 0) & (t > 0.2) & (t < 0.8)] = dark
        elif fi == 1:  # back: a label
            img[(s > 0.25) & (s < 0.75) & (t > 0.3) & (t < 0.7)] = (0.9, 0.9, 0.92)
            img[(s > 0.3) & (s < 0.7) & (t > 0.45) & (t < 0.5)] = (0.1, 0.2, 0.7)
        else:  # top / bottom
            img[(s > 0.2) & (s < 0.35)] = dark
        col, row = fi % 3, fi // 3
        r0 = (1 - row) * _CELL  # image row 0 is at v = 1
        atlas[r0:r0 + _CELL, col * _CELL:(col + 1) * _CELL] = img[::-1]
    return atlas


def _solid(mesh, color) -> SceneMesh:
    part = part_from_trimesh(mesh)
    part.corner_colors[:] = np.asarray(color, np.float32)
    return part


def device_scene() -> SceneMesh:
    """The ``device`` scene (see module docstring), about 0.6 x 1.0 x 0.3 in size."""
    import trimesh

    half = np.array([0.3, 0.5, 0.1])
    parts = [_rounded_box(half, 0.05, 16)]
    front = half[2]
    for i, color in enumerate([(0.85, 0.1, 0.1), (0.1, 0.7, 0.2), (0.1, 0.25, 0.85),
                               (0.95, 0.95, 0.95)]):
        x = -0.18 + 0.12 * i
        cyl = trimesh.creation.cylinder(0.035, segment=[(x, -0.05, front - 0.01),
                                                         (x, -0.05, front + 0.03)], sections=20)
        parts.append(_solid(cyl, color))
    dial = trimesh.creation.cylinder(
        0.11, segment=[(0, -0.3, front - 0.01), (0, -0.3, front + 0.04)], sections=40)
    parts.append(_solid(dial, (0.2, 0.2, 0.22)))
    pointer = trimesh.creation.box(extents=(0.025, 0.12, 0.02))
    pointer.apply_translation((0.02, -0.26, front + 0.05))
    parts.append(_solid(pointer, (0.95, 0.95, 0.9)))
    # Two probe sockets on top: short cylinders, red and black.
    for x, color in ((-0.12, (0.8, 0.05, 0.05)), (0.12, (0.05, 0.05, 0.05))):
        sock = trimesh.creation.cylinder(0.03, segment=[(x, half[1] - 0.01, 0),
                                                         (x, half[1] + 0.06, 0)], sections=20)
        parts.append(_solid(sock, color))
    return concatenate_parts(parts, source="builtin:device")


def thin_scene() -> SceneMesh:
    """The ``thin`` scene: a tripod with thin legs, a pole, a ring and a ball."""
    import trimesh

    parts = []
    top = np.array([0.0, -0.25, 0.0])
    for k in range(3):
        a = 2 * np.pi * k / 3 + 0.3
        foot = np.array([0.45 * np.cos(a), -0.9, 0.45 * np.sin(a)])
        leg = trimesh.creation.cylinder(0.018, segment=[foot, top], sections=12)
        parts.append(_solid(leg, (0.15, 0.15, 0.17)))
    pole = trimesh.creation.cylinder(0.025, segment=[top, (0, 0.45, 0)], sections=12)
    parts.append(_solid(pole, (0.75, 0.75, 0.78)))
    ring = trimesh.creation.torus(0.28, 0.035, major_sections=64, minor_sections=12)
    # torus lies in the x-y plane around z: stand it on the pole, facing +z
    ring.apply_translation((0, 0.45 + 0.28, 0))
    part = part_from_trimesh(ring)
    ang = np.arctan2(ring.vertices[:, 1] - 0.73, ring.vertices[:, 0])
    hue = (ang / (2 * np.pi)) % 1.0
    rgb = np.clip(np.abs(((hue[:, None] * 6 + np.array([0, 4, 2])) % 6) - 3) - 1, 0, 1)
    part.corner_colors = (0.15 + 0.8 * rgb).astype(np.float32)[ring.faces]
    parts.append(part)
    ball = trimesh.creation.icosphere(subdivisions=3, radius=0.07)
    ball.apply_translation((0, 0.73, 0))
    parts.append(_solid(ball, (0.1, 0.3, 0.9)))
    return concatenate_parts(parts, source="builtin:thin")


def builtin_scene(name: str) -> SceneMesh:
    """Return a built-in scene by name (see :data:`BUILTIN_SCENES`)."""
    builders = {"device": device_scene, "thin": thin_scene}
    if name not in builders:
        raise MeshError(f"builtin:{name}: unknown built-in scene; choose one of "
                        f"{', '.join(BUILTIN_SCENES)}")
    return builders[name]()
