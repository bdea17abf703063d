"""Procedurally generated textured objects: a benchmark set drawn from a seed.

The shared assets are few, and defaults tuned on them learn them. Each kind below stands for a
part that events see poorly, or a case the assets lack; every seed draws a new object of the
kind (proportions, colours, textures), and :func:`generated_conditions` draws its size and
light, so a run of the set can use shapes no one has tuned on.

- ``box``: an upright box-like device, its faces of one colour each, one face printed;
- ``slab``: a thin flat slab with a large plate of about the background's brightness, lying
  flat, so an equator-heavy camera path sees its faces at grazing angles;
- ``cage``: a light grey body inside a cage of wires 1 to 3 pixels thick;
- ``bowl``: a bowl with a textured inside (a concavity the visual hull cannot see into);
- ``blob``: a rounded, strongly coloured object with a smooth pattern (the easy case);
- ``rods``: a base with rods and a grille of bars 1 to 3 pixels thick;
- ``device``: a composite: an upright box-like body (faces of one colour each, a printed
  screen on its front), a grid of buttons and a flat stand under it;
- ``birdcage``: a composite: a body of one colour on a flat base inside a cage of wires 1 to
  3 pixels thick that stands on the same base.

Single-kind objects did not predict how a fit does on composites (a body, its buttons and
its stand are fitted together, at once), so the set has both.

``hybridneus simulate generated:<kind>:<seed> OUT`` simulates one; the benchmark suite draws
its set with :func:`generated_set`.
"""

from __future__ import annotations

import numpy as np

from hybridneus.errors import MeshError
from hybridneus.simulate.render import Shading
from hybridneus.simulate.scene_mesh import SceneMesh, concatenate_parts, part_from_trimesh

KINDS = ("box", "slab", "cage", "bowl", "blob", "rods", "device", "birdcage")
#: The kinds made of parts that fire few events (flat faces of one colour, faint plates, thin
#: wires and rods): the ones the benchmarks summarise apart.
SCARCE_KINDS = ("box", "slab", "cage", "rods", "device", "birdcage")
PREFIX = "generated:"
#: The renderer's default background (sRGB); "faint" colours are drawn near it.
BACKGROUND = 159 / 255
#: One pixel of the default camera (346x260, 55 degrees, at 1/1.1 from the origin), in units
#: of the normalised object radius 0.4: wires are sized in pixels with it.
PIXEL_PER_RADIUS = 2 * (1 / 1.1) * np.tan(np.deg2rad(27.5)) / 260 / 0.4


def _rng(kind: str, seed: int) -> np.random.Generator:
    return np.random.default_rng([KINDS.index(kind), int(seed)])


def _vivid(rng: np.random.Generator) -> np.ndarray:
    """A saturated colour far from the grey background."""
    hue = rng.random()
    rgb = np.clip(np.abs((hue * 6 + np.array([0, 4, 2])) % 6 - 3) - 1, 0, 1)
    return (0.1 + 0.8 * rgb).astype(np.float32)


def _near_background(rng: np.random.Generator, spread: float = 0.06) -> np.ndarray:
    return np.full(3, BACKGROUND + rng.uniform(-spread, spread), np.float32)


def _texture(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """A random printed pattern: stripes, checks, dots or a smooth wave field."""
    t, s = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size,
                       indexing="ij")
    a, b = _vivid(rng), _vivid(rng) * rng.uniform(0.3, 1.0)
    kind = rng.integers(4)
    if kind == 0:  # stripes at a random angle
        ang, period = rng.uniform(0, np.pi), rng.uniform(0.06, 0.2)
        mask = np.sin(2 * np.pi * (s * np.cos(ang) + t * np.sin(ang)) / period) > 0
    elif kind == 1:  # checks
        n = rng.integers(3, 9)
        mask = (np.floor(s * n) + np.floor(t * n)) % 2 == 0
    elif kind == 2:  # dots
        n = rng.integers(3, 7)
        mask = ((s * n) % 1 - 0.5) ** 2 + ((t * n) % 1 - 0.5) ** 2 < rng.uniform(0.03, 0.15)
    else:  # a smooth wave field
        w = sum(np.sin(2 * np.pi * (rng.uniform(1, 4) * s * np.cos(q) + rng.uniform(1, 4) * t
                                    * np.sin(q)) + rng.uniform(0, 6))
                for q in rng.uniform(0, np.pi, 3))
        mix = (w - w.min()) / (np.ptp(w) + 1e-9)
        return (a * mix[..., None] + b * (1 - mix[..., None])).astype(np.float32)
    return np.where(mask[..., None], a, b).astype(np.float32)


# (normal, s axis, t axis) of the six box faces; s x t = normal, so faces wind outwards.
_FACES = (((0, 0, 1), (1, 0, 0), (0, 1, 0)), ((0, 0, -1), (-1, 0, 0), (0, 1, 0)),
          ((1, 0, 0), (0, 0, -1), (0, 1, 0)), ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
          ((0, 1, 0), (1, 0, 0), (0, 0, -1)), ((0, -1, 0), (1, 0, 0), (0, 0, 1)))


def _box(center, half, looks: list, n: int = 8) -> SceneMesh:
    """A box, each of its faces (+z, -z, +x, -x, +y, -y) a colour (3,) or a texture image."""
    g = np.linspace(0.0, 1.0, n + 1)
    s, t = (a.reshape(-1) for a in np.meshgrid(g, g, indexing="xy"))
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quad = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], -1).reshape(-1, 4)
    tris = np.concatenate([quad[:, [0, 1, 2]], quad[:, [0, 2, 3]]])
    half, center = np.asarray(half, float), np.asarray(center, float)
    parts = []
    for (nrm, sa, ta), look in zip(_FACES, looks, strict=True):
        nrm, sa, ta = (np.asarray(v, float) for v in (nrm, sa, ta))
        p = (center + nrm * np.abs(nrm @ half) + (2 * s - 1)[:, None] * sa * np.abs(sa @ half)
             + (2 * t - 1)[:, None] * ta * np.abs(ta @ half))
        look = np.asarray(look, np.float32)
        textured = look.ndim == 3
        colors = np.ones((len(tris), 3, 3), np.float32) if textured else np.broadcast_to(
            look, (len(tris), 3, 3)).copy()
        uv = np.stack([s, t], -1).astype(np.float32)[tris]
        parts.append(SceneMesh(p, tris, colors, uv if textured else np.zeros_like(uv),
                               np.full(len(tris), 0 if textured else -1, np.int32),
                               [look] if textured else []))
    return concatenate_parts(parts)


def _solid(mesh, color) -> SceneMesh:
    part = part_from_trimesh(mesh)
    part.corner_colors[:] = np.asarray(color, np.float32)
    return part


def _patterned(mesh, rng: np.random.Generator) -> SceneMesh:
    """``mesh`` coloured by a smooth random 3D pattern of two vivid colours."""
    part = part_from_trimesh(mesh)
    a, b = _vivid(rng), _vivid(rng)
    freq = rng.normal(size=(3, 3)) * rng.uniform(3, 8)
    v = np.asarray(mesh.vertices)
    w = np.sin(v @ freq + rng.uniform(0, 6, 3)).sum(axis=1)
    mix = ((w - w.min()) / (np.ptp(w) + 1e-9)).astype(np.float32)[:, None]
    part.corner_colors = (a * mix + b * (1 - mix))[mesh.faces]
    return part


def _wire(a, b, radius: float, color) -> SceneMesh:
    import trimesh

    return _solid(trimesh.creation.cylinder(radius, segment=[a, b], sections=10), color)


def _box_object(rng) -> list[SceneMesh]:
    half = np.array([rng.uniform(0.25, 0.4), 0.5, rng.uniform(0.08, 0.2)])
    looks = [_vivid(rng) * rng.uniform(0.4, 1.0) for _ in range(6)]
    looks[int(rng.integers(2))] = _texture(rng)  # the front or the back is printed
    parts = [_box((0, 0, 0), half, looks)]
    for _ in range(rng.integers(0, 3)):  # a few knobs on the front
        import trimesh

        x, y = rng.uniform(-0.7, 0.7) * half[0], rng.uniform(-0.7, 0.2) * half[1]
        knob = trimesh.creation.cylinder(rng.uniform(0.02, 0.05),
                                         segment=[(x, y, half[2]), (x, y, half[2] + 0.03)])
        parts.append(_solid(knob, _vivid(rng)))
    return parts


def _slab_object(rng) -> list[SceneMesh]:
    size = np.array([0.5, rng.uniform(0.015, 0.03), rng.uniform(0.3, 0.45)])
    base = _vivid(rng) * rng.uniform(0.3, 0.7)
    parts = [_box((0, 0, 0), size, [base] * 6)]
    plate = np.array([size[0] * rng.uniform(0.6, 0.9), 0.004, size[2] * rng.uniform(0.6, 0.9)])
    faint = _near_background(rng)
    parts.append(_box((0, size[1] + plate[1], 0), plate, [faint] * 6))
    return parts


def _wire_cage(rng, radius: float, bottom: float, top: float, lowest_ring: float,
               px: float) -> list[SceneMesh]:
    """Upright wires on a circle of ``radius`` from ``bottom`` to ``top`` and rings from
    ``lowest_ring`` to ``top``, each 1 to 3 pixels (``px``) thick, all of one dark colour."""
    import trimesh

    parts = []
    color = _vivid(rng) * rng.uniform(0.2, 0.6)
    n = int(rng.integers(6, 12))
    for k in range(n):
        a = 2 * np.pi * k / n
        thick = rng.uniform(1.0, 3.0) * px / 2
        x, z = radius * np.cos(a), radius * np.sin(a)
        parts.append(_wire((x, bottom, z), (x, top, z), thick, color))
    for y in np.linspace(lowest_ring, top, int(rng.integers(2, 4))):
        ring = trimesh.creation.torus(radius, rng.uniform(1.0, 3.0) * px / 2,
                                      major_sections=96, minor_sections=8)
        ring.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, (1, 0, 0)))
        ring.apply_translation((0, y, 0))
        parts.append(_solid(ring, color))
    return parts


def _cage_object(rng) -> list[SceneMesh]:
    import trimesh

    body = trimesh.creation.icosphere(subdivisions=3, radius=rng.uniform(0.18, 0.28))
    parts = [_solid(body, _near_background(rng, 0.03) + 0.15)]  # light grey
    radius, height = 0.4, 0.5
    extent = np.hypot(radius, height)  # the cage decides the object's bounding sphere
    return parts + _wire_cage(rng, radius, -height, height, -height, PIXEL_PER_RADIUS * extent)


def _bowl_object(rng) -> list[SceneMesh]:
    import trimesh

    r, depth, wall = rng.uniform(0.35, 0.5), rng.uniform(0.2, 0.4), rng.uniform(0.02, 0.05)
    heights = np.linspace(0, 1, 24)
    outer = np.stack([r * np.sqrt(np.clip(heights, 1e-3, 1)), depth * heights - depth / 2], -1)
    inner = np.stack([np.maximum(outer[:, 0] - wall, 1e-3), outer[:, 1] + wall], -1)[::-1]
    profile = np.concatenate([outer, inner[inner[:, 1] <= depth / 2]])
    bowl = trimesh.creation.revolve(profile, sections=64)
    bowl.apply_transform(trimesh.transformations.rotation_matrix(-np.pi / 2, (1, 0, 0)))
    return [_patterned(bowl, rng)]


def _blob_object(rng) -> list[SceneMesh]:
    import trimesh

    blob = trimesh.creation.icosphere(subdivisions=4, radius=0.4)
    v = blob.vertices
    bumps = sum(rng.uniform(0.02, 0.08) * np.sin(v @ rng.normal(size=3) * rng.uniform(2, 5))
                for _ in range(4))
    blob.vertices = v * (1 + bumps)[:, None] * np.array([1, rng.uniform(0.7, 1.3), 1])
    return [_patterned(blob, rng)]


def _rods_object(rng) -> list[SceneMesh]:
    half = np.array([0.45, 0.05, 0.3])
    parts = [_box((0, -0.45, 0), half, [_vivid(rng) * 0.5] * 6)]
    extent = 0.65
    px = PIXEL_PER_RADIUS * extent
    color = _vivid(rng)
    for _ in range(int(rng.integers(3, 6))):  # free-standing rods
        x, z = rng.uniform(-0.35, 0.35), rng.uniform(-0.2, 0.2)
        top = (x + rng.uniform(-0.1, 0.1), rng.uniform(0.1, 0.5), z)
        parts.append(_wire((x, -0.4, z), top, rng.uniform(1.0, 3.0) * px / 2, color))
    bars, grille = int(rng.integers(5, 10)), _vivid(rng) * 0.6
    for k in range(bars):  # a grille: a frame of parallel bars
        x = -0.3 + 0.6 * k / (bars - 1)
        parts.append(_wire((x, -0.4, -0.25), (x, 0.2, -0.25), rng.uniform(1.0, 3.0) * px / 2,
                           grille))
    parts.append(_wire((-0.3, 0.2, -0.25), (0.3, 0.2, -0.25), 1.5 * px, grille))
    return parts


def _device_object(rng) -> list[SceneMesh]:
    import trimesh

    half = np.array([rng.uniform(0.22, 0.35), rng.uniform(0.4, 0.5), rng.uniform(0.06, 0.14)])
    looks = [_vivid(rng) * rng.uniform(0.4, 1.0) for _ in range(6)]
    parts = [_box((0, 0, 0), half, looks)]
    # a printed screen on the upper front, standing out by a hair so that it is a face
    screen = np.array([half[0] * rng.uniform(0.6, 0.85), half[1] * rng.uniform(0.2, 0.35),
                       0.004])
    top = half[1] - screen[1] - half[1] * rng.uniform(0.08, 0.15)
    parts.append(_box((0, top, half[2] + screen[2]), screen,
                      [_texture(rng)] + [looks[0]] * 5))
    rows, cols = int(rng.integers(2, 4)), int(rng.integers(2, 4))
    size = min(half[0] / cols, half[1] * 0.8 / rows) * rng.uniform(0.2, 0.35)
    button = _vivid(rng) * rng.uniform(0.5, 1.0)
    for r in range(rows):  # a grid of buttons below the screen
        for c in range(cols):
            x = (2 * (c + 0.5) / cols - 1) * half[0] * 0.7
            y = -half[1] * 0.8 + (r + 0.5) / rows * (top - screen[1] + half[1] * 0.7)
            if rng.random() < 0.5:
                knob = trimesh.creation.cylinder(size, segment=[(x, y, half[2]),
                                                               (x, y, half[2] + 0.02)])
                parts.append(_solid(knob, button))
            else:
                parts.append(_box((x, y, half[2] + 0.01), (size, size * 0.7, 0.01),
                                  [button] * 6))
    stand = np.array([half[0] * rng.uniform(1.1, 1.4), rng.uniform(0.02, 0.04),
                      half[2] * rng.uniform(2.0, 3.0)])
    parts.append(_box((0, -half[1] - stand[1], 0), stand, [_vivid(rng) * 0.5] * 6))
    return parts


def _birdcage_object(rng) -> list[SceneMesh]:
    radius, height = rng.uniform(0.3, 0.4), rng.uniform(0.35, 0.5)
    base = np.array([radius * 1.15, rng.uniform(0.03, 0.05), radius * 1.15])
    floor = -height
    parts = [_box((0, floor - base[1], 0), base, [_vivid(rng) * rng.uniform(0.3, 0.6)] * 6)]
    body_half = np.array([rng.uniform(0.1, 0.18), rng.uniform(0.12, 0.25),
                          rng.uniform(0.1, 0.18)])
    light = _near_background(rng, 0.03) + 0.15
    parts.append(_box((0, floor + body_half[1], 0), body_half, [light] * 6))
    extent = np.hypot(radius * 1.15 * np.sqrt(2), height)
    return parts + _wire_cage(rng, radius, floor, height, floor + 0.3 * height,
                              PIXEL_PER_RADIUS * extent)


_BUILDERS = {"box": _box_object, "slab": _slab_object, "cage": _cage_object,
             "bowl": _bowl_object, "blob": _blob_object, "rods": _rods_object,
             "device": _device_object, "birdcage": _birdcage_object}


def generated_parts(kind: str, seed: int) -> list[SceneMesh]:
    """The parts of :func:`generated_scene`'s object, in the order its builder makes them
    (the slab's body before its plate; the cage's body, then its wires, then its rings), in
    the builder's own units (before the simulator normalises the object).

    Raises:
        MeshError: unknown kind.
    """
    if kind not in _BUILDERS:
        raise MeshError(f"{PREFIX}{kind}: unknown kind; choose one of {', '.join(KINDS)}")
    return _BUILDERS[kind](_rng(kind, seed))


def generated_scene(kind: str, seed: int) -> SceneMesh:
    """The object of ``kind`` drawn by ``seed`` (any size: the simulator normalises it).

    Raises:
        MeshError: unknown kind.
    """
    return concatenate_parts(generated_parts(kind, seed), source=f"{PREFIX}{kind}:{seed}")


def generated_conditions(kind: str, seed: int) -> tuple[float, Shading]:
    """The object radius (0.25 to 0.45, of the cameras' 0.91) and the light the benchmark
    simulates the object of ``kind`` and ``seed`` with."""
    rng = np.random.default_rng([KINDS.index(kind), int(seed), 1])
    radius = float(rng.uniform(0.25, 0.45))
    light = rng.normal(size=3)
    light[1] = abs(light[1]) + 0.3  # from above, mostly
    ambient = float(rng.uniform(0.2, 0.45))
    shading = Shading(light_dir=tuple(float(v) for v in light), ambient=ambient,
                      diffuse=1.0 - ambient, headlight=bool(rng.random() < 0.2))
    return radius, shading


def generated_set(n: int, seed: int) -> list[tuple[str, int]]:
    """``n`` (kind, seed) pairs: the kinds in turn, each object's seed drawn from ``seed``."""
    rng = np.random.default_rng(seed)
    return [(KINDS[i % len(KINDS)], int(rng.integers(0, 2**31))) for i in range(n)]


def parse_source(text: str) -> tuple[str, int]:
    """``generated:<kind>:<seed>`` -> (kind, seed).

    Raises:
        MeshError: malformed text or unknown kind.
    """
    body = text[len(PREFIX):] if text.startswith(PREFIX) else text
    kind, _, seed = body.partition(":")
    if kind not in KINDS or not seed.lstrip("-").isdigit():
        raise MeshError(f"{text}: expected {PREFIX}<kind>:<seed>, kind one of "
                        f"{', '.join(KINDS)}")
    return kind, int(seed)
