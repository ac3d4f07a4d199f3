"""Spherical search grids of directions around the array (array frame).

Directions are unit vectors; azimuth is CCW from +x, elevation up from the
x-y plane. A grid may carry a finite ``radius`` (m): then its points are
``radius * direction`` and delays are computed in the near field, as in the
paper's constant-radius 3D grid; ``radius=None`` means far field.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_GOLDEN_ANGLE = np.pi * (3.0 - np.sqrt(5.0))


def fibonacci_directions(n: int) -> np.ndarray:
    """``n`` near-uniform unit vectors on the sphere (Fibonacci lattice), shape (n, 3)."""
    if n < 1:
        raise ValueError(f"number of grid directions must be >= 1, got {n}")
    k = np.arange(n, dtype=float)
    z = 1.0 - (2.0 * k + 1.0) / n
    r = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
    phi = k * _GOLDEN_ANGLE
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def n_points_for_spacing(spacing: float) -> int:
    """Points a full-sphere Fibonacci grid needs so that neighbours are at most ``spacing`` (rad) apart.

    Each point gets an area of ``spacing**2`` of the unit sphere; on the Fibonacci
    lattice this gives nearest-neighbour distances of about 0.93-0.97 ``spacing``.
    """
    if not 0 < spacing < np.pi / 2:
        raise ValueError(f"grid spacing must be in (0, 90) degrees, got {np.rad2deg(spacing):.3g} degrees")
    return max(4, int(np.ceil(4.0 * np.pi / (spacing * spacing))))


def azimuth_elevation(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Azimuth (rad, CCW from +x, in (-pi, pi]) and elevation (rad) of unit vectors ``(..., 3)``."""
    d = np.asarray(directions, dtype=float)
    az = np.arctan2(d[..., 1], d[..., 0])
    el = np.arcsin(np.clip(d[..., 2] / np.linalg.norm(d, axis=-1), -1.0, 1.0))
    return az, el


def direction_from_angles(azimuth, elevation) -> np.ndarray:
    """Unit vector(s) ``(..., 3)`` from azimuth and elevation (rad)."""
    az, el = np.asarray(azimuth, float), np.asarray(elevation, float)
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


def angular_distance(a, b) -> np.ndarray:
    """Great-circle angle (rad) between unit vectors ``a`` and ``b`` (broadcasting over ``...``)."""
    dot = np.sum(np.asarray(a, float) * np.asarray(b, float), axis=-1)
    return np.arccos(np.clip(dot, -1.0, 1.0))


@dataclass(frozen=True)
class SphericalGrid:
    """Grid directions (unit vectors, array frame), nominal spacing (rad) and optional radius (m)."""

    directions: np.ndarray
    spacing: float
    radius: float | None = None

    @property
    def n_points(self) -> int:
        return int(self.directions.shape[0])

    @property
    def azimuth(self) -> np.ndarray:
        return azimuth_elevation(self.directions)[0]

    @property
    def elevation(self) -> np.ndarray:
        return azimuth_elevation(self.directions)[1]

    @property
    def points(self) -> np.ndarray | None:
        """Grid points (m, array frame) when the grid has a finite radius, else None."""
        return None if self.radius is None else self.directions * self.radius


def make_grid(
    spacing: float,
    el_min: float = -np.pi / 2,
    el_max: float = np.pi / 2,
    radius: float | None = None,
) -> SphericalGrid:
    """A Fibonacci grid with nearest-neighbour spacing ``spacing`` (rad), limited to ``[el_min, el_max]`` (rad)."""
    if not -np.pi / 2 <= el_min < el_max <= np.pi / 2:
        raise ValueError(
            f"elevation limits must satisfy -90 <= el_min < el_max <= 90 degrees, "
            f"got el_min={np.rad2deg(el_min):.3g}, el_max={np.rad2deg(el_max):.3g}"
        )
    if radius is not None and not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"grid radius must be a positive number of metres or None (far field), got {radius}")
    dirs = fibonacci_directions(n_points_for_spacing(spacing))
    el = np.arcsin(np.clip(dirs[:, 2], -1.0, 1.0))
    keep = (el >= el_min - 1e-12) & (el <= el_max + 1e-12)
    if not np.any(keep):
        raise ValueError("elevation limits leave no grid points; widen el_min/el_max or refine the grid")
    return SphericalGrid(dirs[keep], float(spacing), radius)
