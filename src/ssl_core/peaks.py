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


def local_maxima(power: np.ndarray, neighbours: np.ndarray, top: int | None = None) -> np.ndarray:
    """Indices of points whose power is >= all their neighbours', strongest first (at most ``top``)."""
    peak = power[neighbours[:, 0]]
    for k in range(1, neighbours.shape[1]):  # a few columns: cheaper than one 2-D gather + reduce
        np.maximum(peak, power[neighbours[:, k]], out=peak)
    idx = np.flatnonzero(power >= peak)
    if top is not None and idx.size > top:
        idx = idx[np.argpartition(power[idx], -top)[-top:]]
    return idx[np.argsort(power[idx])[::-1]]
