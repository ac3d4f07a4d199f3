"""Pooling window detections into whole-recording sources (ssl_core.pooling), with hand-made detections."""
from __future__ import annotations

import numpy as np

from ssl_core.detection import Detection
from ssl_core.grid import angular_distance, azimuth_elevation, direction_from_angles, fibonacci_directions
from ssl_core.pooling import DirectionPool


def _det(u: np.ndarray, power: float, level_db: float = -30.0, z: float = 10.0) -> Detection:
    az, el = azimuth_elevation(u)
    return Detection(float(az), float(el), u, power, level_db, z)


def _scatter(u: np.ndarray, deg: float, rng) -> np.ndarray:
    v = u + np.deg2rad(deg) * rng.standard_normal(3)
    return v / np.linalg.norm(v)


def test_modes_are_the_consistent_directions_strongest_first():
    rng = np.random.default_rng(0)
    grid = fibonacci_directions(20000)  # ~1.4 deg spacing
    u1 = direction_from_angles(np.deg2rad(30), np.deg2rad(10))
    u2 = direction_from_angles(np.deg2rad(-100), np.deg2rad(40))
    u3 = direction_from_angles(np.deg2rad(170), np.deg2rad(-20))
    pool = DirectionPool(grid)
    for k in range(40):
        dets = []
        if k % 2 == 0:
            dets.append(_det(_scatter(u1, 2.0, rng), 0.3))
        if k % 3 == 0:
            dets.append(_det(_scatter(u2, 2.0, rng), 0.2, level_db=-40.0))
        if k == 7:
            dets.append(_det(u3, 0.5))  # a single loud false alarm: not consistent
        pool.add(dets)
    assert pool.windows == 40
    modes = pool.modes(3, np.deg2rad(20), min_windows=2)
    assert len(modes) == 2
    assert np.rad2deg(angular_distance(modes[0].direction, u1)) < 1.5
    assert np.rad2deg(angular_distance(modes[1].direction, u2)) < 1.5
    assert abs(modes[0].power - 0.3) < 1e-9
    # level: the mean over all 40 windows, the 14 without u2 counting as silent
    assert abs(modes[1].level_db - (-40.0 + 10 * np.log10(14 / 40))) < 1e-6
    assert modes[0].significance == 10.0
    # min_windows=1 admits the lone detection, ranked by its density
    assert len(pool.modes(3, np.deg2rad(20), min_windows=1)) == 3


def test_empty_pool_and_constant_state():
    pool = DirectionPool(fibonacci_directions(500))
    assert pool.modes(2, np.deg2rad(20)) == []
    sizes = pool._count.nbytes
    u = direction_from_angles(0.0, 0.0)
    for _ in range(1000):
        pool.add([_det(u, 0.2)])
    assert pool._count.nbytes == sizes  # tallied on the grid: memory does not grow with the recording
    (m,) = pool.modes(1, np.deg2rad(20))
    assert np.rad2deg(angular_distance(m.direction, u)) < 5.0  # the nearest point of a 500-point grid (9 deg apart)
