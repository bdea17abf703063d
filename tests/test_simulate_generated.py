"""The generated benchmark objects: drawn from a seed, composites made of their parts."""

from __future__ import annotations

import numpy as np
import pytest

from hybridneus.errors import MeshError
from hybridneus.simulate.generated import KINDS, generated_parts, generated_scene, parse_source


@pytest.mark.parametrize("kind", KINDS)
def test_every_kind_is_drawn_from_its_seed(kind):
    a, b = generated_scene(kind, 3), generated_scene(kind, 3)
    assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.faces, b.faces)
    c = generated_scene(kind, 4)
    assert a.vertices.shape != c.vertices.shape or not np.allclose(a.vertices, c.vertices)
    assert parse_source(f"generated:{kind}:3") == (kind, 3)


def test_the_device_stands_on_its_stand_with_buttons_on_its_front():
    for seed in range(4):
        body, screen, *buttons, stand = generated_parts("device", seed)
        lo, hi = body.vertices.min(0), body.vertices.max(0)
        assert len(buttons) >= 4  # a grid of at least 2 x 2
        # the stand lies under the body and reaches beyond it
        assert abs(stand.vertices[:, 1].max() - lo[1]) < 1e-9
        assert (stand.vertices[:, [0, 2]].max(0) > hi[[0, 2]]).all()
        # the screen and every button sit on the front, inside its outline
        for part in [screen, *buttons]:
            v = part.vertices
            assert v[:, 2].min() >= hi[2] - 1e-9 and v[:, 2].max() < hi[2] + 0.05
            assert (v[:, :2].min(0) > lo[:2]).all() and (v[:, :2].max(0) < hi[:2]).all()


def test_the_birdcage_wires_stand_on_the_base_around_the_body():
    for seed in range(4):
        base, body, *wires = generated_parts("birdcage", seed)
        top = base.vertices[:, 1].max()
        assert abs(body.vertices[:, 1].min() - top) < 1e-9  # the body sits on the base
        radius = np.linalg.norm(wires[0].vertices[:, [0, 2]], axis=1).mean()
        assert np.linalg.norm(body.vertices[:, [0, 2]], axis=1).max() < radius
        uprights = [w for w in wires if np.ptp(w.vertices[:, 1]) > 0.5]
        assert len(uprights) >= 6
        assert all(abs(w.vertices[:, 1].min() - top) < 0.01 for w in uprights)


def test_an_unknown_kind_is_refused_in_one_line():
    with pytest.raises(MeshError, match="unknown kind"):
        generated_parts("teapot", 1)
    with pytest.raises(MeshError, match="kind one of"):
        parse_source("generated:teapot:1")
