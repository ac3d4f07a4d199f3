"""Peak picking on a spherical SRP map: neighbourhoods and local maxima."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def neighbour_table(directions: np.ndarray, radius: float) -> np.ndarray:
    """For each unit vector, the indices of those within ``radius`` (rad), padded with its own index.

    Shape (n, k_max); every row contains its own index.
    """
    chord = 2.0 * np.sin(radius / 2.0)
    lists = cKDTree(directions).query_ball_point(directions, chord)
    k = max(len(v) for v in lists)
    table = np.repeat(np.arange(len(lists))[:, None], k, axis=1)
    for i, v in enumerate(lists):  # init-time only
        table[i, : len(v)] = v
    return table


def local_maxima(power: np.ndarray, neighbours: np.ndarray) -> np.ndarray:
    """Indices of points whose power is >= all their neighbours', strongest first."""
    is_max = power >= power[neighbours].max(axis=1)
    idx = np.flatnonzero(is_max)
    return idx[np.argsort(power[idx])[::-1]]
