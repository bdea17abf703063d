"""Filling the space no camera saw: caves opened from an unfilmed underside, and what is left."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from hybridneus.meshing import CropVolume, extract_mesh
from hybridneus.meshing.unseen import FilledField, spread_cameras, unseen_space
from hybridneus.model.analytic import SphereField
from hybridneus.model.protocol import Field

BOX = ((-0.7, -0.7, -0.7), (0.7, 0.7, 0.7))
SPHERE_VOLUME = 4 / 3 * np.pi * 0.5**3


class CaveField(SphereField):
    """A ball of radius 0.5 with a vertical shaft of radius 0.08 bored from below up to
    y = 0.2: a cave whose mouth faces straight down."""

    def __init__(self) -> None:
        super().__init__(0.5)

    def _sdf(self, points: torch.Tensor) -> torch.Tensor:
        shaft = torch.maximum(points[:, [0, 2]].norm(dim=1) - 0.08, points[:, 1] - 0.2)
        return torch.maximum(super()._sdf(points), -shaft)


class SlitField(SphereField):
    """A ball of radius 0.5 with a slit 0.05 wide and 0.4 long cut from below up to y = 0.2."""

    def __init__(self) -> None:
        super().__init__(0.5)

    def _sdf(self, points: torch.Tensor) -> torch.Tensor:
        slit = torch.maximum(points[:, 0].abs() - 0.025, points[:, 2].abs() - 0.2)
        slit = torch.maximum(slit, points[:, 1] - 0.2)
        return torch.maximum(super()._sdf(points), -slit)


class FlatBottomField(SphereField):
    """A ball of radius 0.5 cut flat at y = -0.25."""

    def __init__(self) -> None:
        super().__init__(0.5)

    def _sdf(self, points: torch.Tensor) -> torch.Tensor:
        return torch.maximum(super()._sdf(points), -0.25 - points[:, 1])


def ring_cameras(elevations_deg, n_azimuth: int = 12, distance: float = 3.0) -> np.ndarray:
    out = []
    for e in np.deg2rad(elevations_deg):
        for a in np.linspace(0, 2 * np.pi, n_azimuth, endpoint=False):
            direction = [np.cos(e) * np.cos(a), np.sin(e), np.cos(e) * np.sin(a)]
            out.append(distance * np.array(direction))
    return np.array(out)


ABOVE = ring_cameras([0, 15, 40, 70])  # the EventNeRF captures: the equator and above
AROUND = ring_cameras([-90, -70, -40, -15, 0, 15, 40, 70])


def test_a_cave_no_camera_sees_into_is_filled():
    field = CaveField()
    plain = extract_mesh(field, res=96, bounds=BOX, progress=False)
    filled = extract_mesh(field, res=96, bounds=BOX, cameras=ABOVE, progress=False)
    shaft = np.pi * 0.08**2 * (0.2 + np.sqrt(0.5**2 - 0.08**2))
    assert plain.volume == pytest.approx(SPHERE_VOLUME - shaft, rel=0.01)
    assert filled.volume == pytest.approx(SPHERE_VOLUME, rel=0.01)
    assert filled.is_watertight


def test_a_cave_seen_from_below_is_kept():
    unseen = unseen_space(CaveField(), AROUND, BOX, res=64)
    assert unseen.filled == 0
    mesh = extract_mesh(CaveField(), res=96, bounds=BOX, cameras=AROUND, progress=False)
    shaft = np.pi * 0.08**2 * (0.2 + np.sqrt(0.5**2 - 0.08**2))
    assert mesh.volume == pytest.approx(SPHERE_VOLUME - shaft, rel=0.03)


def test_the_open_wedge_below_a_flat_underside_stays_empty():
    # Cameras at and above the equator cannot see just below a flat bottom either, but
    # nothing there is surrounded by matter, so the bottom stays where the field put it.
    field = FlatBottomField()
    unseen = unseen_space(field, ABOVE, BOX, res=64)
    assert unseen.hidden > 0 and unseen.filled == 0
    mesh = extract_mesh(field, res=96, bounds=BOX, cameras=ABOVE, progress=False)
    assert mesh.vertices[:, 1].min() > -0.25 - 0.02


def test_min_thickness_leaves_thin_pockets_and_fills_thick_ones():
    # the slit is about 2 voxels wide at res 64 over the 1.4-wide box, the shaft about 7
    assert unseen_space(SlitField(), ABOVE, BOX, res=64, min_thickness=0).filled > 0
    assert unseen_space(SlitField(), ABOVE, BOX, res=64, min_thickness=4).filled == 0
    cave = unseen_space(CaveField(), ABOVE, BOX, res=64, min_thickness=0)
    thick = unseen_space(CaveField(), ABOVE, BOX, res=64, min_thickness=4)
    assert thick.filled > 0.8 * cave.filled


def test_the_filled_region_is_a_signed_distance_on_its_grid():
    unseen = unseen_space(CaveField(), ABOVE, BOX, res=64)
    assert unseen.filled > 0 and unseen.cameras == len(ABOVE)
    g = unseen.grid
    assert unseen.distance.shape == g.shape and unseen.distance.dtype == np.float32
    # the shaft's axis, halfway up the cave, is inside; the box's corner is far outside
    centre = np.round(g.to_index(np.array([[0.0, -0.1, 0.0]]))[0]).astype(int)
    assert unseen.distance[tuple(centre)] < -0.05
    assert unseen.distance[0, 0, 0] > 0.3


def test_filled_field_is_a_field_that_keeps_colours_and_attributes():
    field = CaveField()
    field.crop = (0.6, -0.6, 0.6)
    wrapped = FilledField(field, unseen_space(field, ABOVE, BOX, res=64))
    assert isinstance(wrapped, Field)
    assert wrapped.crop == (0.6, -0.6, 0.6)
    pts = torch.tensor([[0.0, -0.1, 0.0], [0.0, 0.3, 0.0], [0.0, 0.9, 0.0], [5.0, 5.0, 5.0]])
    d = wrapped.sdf(pts)
    own = field.sdf(pts)
    assert d[0] < 0 < own[0]  # inside the filled cave
    assert d[1] == pytest.approx(float(own[1]))  # matter stays matter
    assert torch.all(d[2:] == own[2:])  # outside the fill's grid: the field's own value
    dirs = torch.nn.functional.normalize(torch.ones(4, 3), dim=1)
    assert torch.equal(wrapped.color(pts, dirs), field.color(pts, dirs))
    value, grad = wrapped.sdf_and_gradient(pts)
    assert torch.allclose(value, d) and grad.shape == (4, 3)


def test_the_examined_box_is_the_crop_when_the_field_has_one():
    field = CaveField()
    crop = CropVolume(0.6, -0.6, 0.6)
    mesh = extract_mesh(field, res=96, crop=crop, cameras=ABOVE, progress=False)
    assert mesh.volume == pytest.approx(SPHERE_VOLUME, rel=0.01)


def test_spread_cameras_keeps_the_rare_directions():
    equator = ring_cameras([0.0], n_azimuth=200)
    pole = np.array([[0.0, 3.0, 0.0]])
    chosen = spread_cameras(np.vstack([equator, pole]), 4)
    assert len(chosen) == 4
    assert any(np.allclose(c, pole[0]) for c in chosen)
    assert len(spread_cameras(pole, 4)) == 1


def test_unseen_space_rejects_bad_cameras():
    with pytest.raises(ValueError, match="cameras"):
        unseen_space(CaveField(), np.zeros((0, 3)), BOX)
    with pytest.raises(ValueError, match="cameras"):
        unseen_space(CaveField(), np.array([[np.nan, 0.0, 3.0]]), BOX)


def test_filled_field_takes_numpy_and_tensors_like_a_trained_field():
    field = CaveField()
    wrapped = FilledField(field, unseen_space(field, ABOVE, BOX, res=64))
    pts = np.array([[0.0, -0.1, 0.0], [0.0, 0.3, 0.0], [5.0, 5.0, 5.0]], dtype=np.float64)
    d = wrapped.sdf(pts)
    assert isinstance(d, np.ndarray) and d.shape == (3,)
    assert np.allclose(d, wrapped.sdf(torch.from_numpy(pts)).numpy())
    assert d[0] < 0  # the filled cave
    value, grad = wrapped.sdf_and_gradient(pts)
    assert isinstance(value, np.ndarray) and isinstance(grad, np.ndarray)
    assert np.allclose(value, d) and grad.shape == (3, 3)
