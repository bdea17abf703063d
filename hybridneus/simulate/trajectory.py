"""Camera trajectories on a sphere around the origin, and look-at poses (OpenCV axes).

World frame: y is up. A viewing direction is given by its polar angle from +y and its
azimuth ``phi`` measured in the x-z plane, so that the unit position is
``(sin(theta) cos(phi), cos(theta), sin(theta) sin(phi))``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Trajectory:
    """Camera centres on a sphere, with the azimuth that fixes each camera's roll.

    Attributes:
        kind: ``seiffert``, ``even`` or ``circle``.
        directions: (n_views, 3) float64 unit vectors from the origin to the camera.
        azimuth: (n_views,) float64 radians; the camera's x axis is
            ``(sin(phi), 0, -cos(phi))``, which is well defined at the poles too.
        params: the parameters that produced it (written to scene.json).
    """

    kind: str
    directions: np.ndarray
    azimuth: np.ndarray
    params: dict

    @property
    def n_views(self) -> int:
        return int(self.directions.shape[0])


def _directions(polar: np.ndarray, azimuth: np.ndarray) -> np.ndarray:
    s = np.sin(polar)
    return np.stack([s * np.cos(azimuth), np.cos(polar), s * np.sin(azimuth)], axis=-1)


def seiffert_spiral(
    n_views: int, revolutions: float = 8.0, k: float = 1.0, azimuth_offset_deg: float = 0.0
) -> Trajectory:
    """Seiffert's spherical spiral traversed at constant speed, from the north pole (+y).

    The curve is ``(sn(s,k) cos(k s + phi0), cn(s,k), sn(s,k) sin(k s + phi0))`` with the
    Jacobi elliptic functions of modulus ``k``; ``s`` is arc length, sampled uniformly on
    ``[0, 2 pi revolutions / k]``. With the default ``k = 1`` (sn = tanh, cn = sech) the
    camera leaves the pole, reaches the equator within about one turn and then circles just
    above it: with 8 revolutions and 999 views it moves 2.886 degrees per view, as in the
    EventNeRF synthetic data. ``k < 1`` winds across the equator towards the south pole
    (which it reaches at ``s = 2 K(k)``).

    Args:
        n_views: number of camera positions.
        revolutions: turns of azimuth over the whole sequence.
        k: elliptic modulus in (0, 1].
        azimuth_offset_deg: azimuth of the first view.

    Returns:
        The :class:`Trajectory`.
    """
    from scipy.special import ellipj

    if not 0.0 < k <= 1.0:
        raise ValueError(f"Seiffert modulus k must be in (0, 1], got {k}")
    s = np.linspace(0.0, 2.0 * np.pi * revolutions / k, n_views)
    sn, cn, _, _ = ellipj(s, k * k)
    phi = k * s + np.deg2rad(azimuth_offset_deg)
    dirs = np.stack([sn * np.cos(phi), cn, sn * np.sin(phi)], axis=-1)
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    params = {"revolutions": revolutions, "k": k, "azimuth_offset_deg": azimuth_offset_deg,
              "start": "north pole (+y)", "speed": "constant (arc length)"}
    return Trajectory("seiffert", dirs, phi, params)


def even_spiral(
    n_views: int,
    revolutions: float = 8.0,
    elevation_start_deg: float = 90.0,
    elevation_end_deg: float = 0.0,
    azimuth_offset_deg: float = 0.0,
) -> Trajectory:
    """An evenly wound spiral: azimuth and elevation both change linearly with the view index.

    Every turn lowers the elevation by the same amount, so views cover the band between the
    two elevations evenly (unlike Seiffert's spiral, which bunches them at the equator).
    """
    u = np.linspace(0.0, 1.0, n_views)
    elev = np.deg2rad(elevation_start_deg + (elevation_end_deg - elevation_start_deg) * u)
    phi = 2.0 * np.pi * revolutions * u + np.deg2rad(azimuth_offset_deg)
    params = {"revolutions": revolutions, "elevation_start_deg": elevation_start_deg,
              "elevation_end_deg": elevation_end_deg, "azimuth_offset_deg": azimuth_offset_deg}
    return Trajectory("even", _directions(np.pi / 2 - elev, phi), phi, params)


def circle(
    n_views: int,
    elevation_deg: float = 30.0,
    revolutions: float = 1.0,
    azimuth_offset_deg: float = 0.0,
) -> Trajectory:
    """Views on a circle of constant elevation; the last view stops one step short of a full
    turn when ``revolutions == 1``, so that the sequence can wrap around."""
    phi = np.deg2rad(azimuth_offset_deg) + 2.0 * np.pi * revolutions * np.arange(n_views) / n_views
    polar = np.full(n_views, np.pi / 2 - np.deg2rad(elevation_deg))
    params = {"elevation_deg": elevation_deg, "revolutions": revolutions,
              "azimuth_offset_deg": azimuth_offset_deg}
    return Trajectory("circle", _directions(polar, phi), phi, params)


def look_at_origin(directions: np.ndarray, azimuth: np.ndarray, radius: float) -> np.ndarray:
    """Camera-to-world poses of cameras at ``radius * directions`` looking at the origin.

    OpenCV axes: x right, y down, z forward. The x axis is horizontal,
    ``(sin(phi), 0, -cos(phi))``, i.e. ``normalize(forward x world_up)`` away from the
    poles, so world +y appears up in the image (image y down).

    Args:
        directions: (n_views, 3) unit vectors from the origin to the cameras.
        azimuth: (n_views,) radians.
        radius: distance of every camera from the origin.

    Returns:
        (n_views, 4, 4) float64 camera-to-world matrices.
    """
    forward = -np.asarray(directions, dtype=np.float64)
    right = np.stack([np.sin(azimuth), np.zeros_like(azimuth), -np.cos(azimuth)], axis=-1)
    # Remove any component along forward (exactly zero analytically) before completing.
    right -= (right * forward).sum(-1, keepdims=True) * forward
    right /= np.linalg.norm(right, axis=-1, keepdims=True)
    down = np.cross(forward, right)
    c2w = np.zeros((forward.shape[0], 4, 4))
    c2w[:, :3, 0] = right
    c2w[:, :3, 1] = down
    c2w[:, :3, 2] = forward
    c2w[:, :3, 3] = -forward * radius
    c2w[:, 3, 3] = 1.0
    return c2w


def make_trajectory(kind: str, n_views: int, **params) -> Trajectory:
    """Build a trajectory by name: ``seiffert``, ``even`` or ``circle``."""
    builders = {"seiffert": seiffert_spiral, "even": even_spiral, "circle": circle}
    if kind not in builders:
        raise ValueError(f"unknown trajectory {kind!r}; choose one of {sorted(builders)}")
    return builders[kind](n_views, **params)
