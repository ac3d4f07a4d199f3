"""SRP-PHAT: steered response power over a spherical grid (array frame).

The delay table holds, for every microphone pair (i, j) and grid point, the
TDOA ``t_i - t_j`` (s) that a source there would produce. The SRP of a grid
point is the mean over pairs of the GCC-PHAT at that pair's TDOA, read from an
upsampled GCC by linear interpolation (one gather for all pairs and points).
"""
from __future__ import annotations

import numpy as np

from ssl_core.geometry import ArrayGeometry
from ssl_core.grid import SphericalGrid

SOUND_SPEED = 343.0  # m/s, dry air at 20 degrees C


def tdoa_table(geometry: ArrayGeometry, grid: SphericalGrid, sound_speed: float = SOUND_SPEED) -> np.ndarray:
    """TDOAs ``t_i - t_j`` (s) for every pair (rows, ``geometry.pairs`` order) and grid point (columns).

    Far field (``grid.radius is None``): ``t_m = -(m . u) / c``. Near field: ``t_m = |r u - m| / c``.
    """
    mics = geometry.positions
    pairs = geometry.pairs
    if grid.radius is None:
        arrival = -(grid.directions @ mics.T) / sound_speed  # (G, M)
    else:
        pts = grid.directions * grid.radius
        arrival = np.linalg.norm(pts[:, None, :] - mics[None, :, :], axis=-1) / sound_speed
    return (arrival[:, pairs[:, 0]] - arrival[:, pairs[:, 1]]).T


class SteeringTable:
    """Precomputed interpolation indices and weights of one grid into the lag-domain GCC.

    ``gcc`` rows are pairs, columns lags ``-max_lag..max_lag`` in steps of
    ``1 / (fs * upsample)``.
    """

    def __init__(self, tdoa: np.ndarray, fs: float, upsample: int, max_lag: int, interpolate: bool = True):
        pos = tdoa * (fs * upsample) + max_lag
        if pos.min() < 0 or pos.max() > 2 * max_lag:
            raise ValueError("TDOA table exceeds the GCC lag window; max_lag is too small for this geometry")
        i0 = np.minimum(np.floor(pos).astype(np.intp), 2 * max_lag - 1)
        self.frac = (pos - i0).astype(np.float32)
        n_pairs = tdoa.shape[0]
        self.index = (i0 + (np.arange(n_pairs)[:, None] * (2 * max_lag + 1))).astype(np.intp)
        self.n_pairs = n_pairs
        self.interpolate = interpolate
        if not interpolate:  # nearest lag: half the gathers, for max-pooled coarse searches
            self.index = self.index + (self.frac >= 0.5)

    def power(self, gcc: np.ndarray, columns: np.ndarray | None = None) -> np.ndarray:
        """Mean over pairs of the interpolated GCC at each grid point (or at ``columns`` only)."""
        flat = gcc.reshape(-1)
        idx, w = (self.index, self.frac) if columns is None else (self.index[:, columns], self.frac[:, columns])
        if not self.interpolate:
            return flat[idx].sum(axis=0) / self.n_pairs
        lo = flat[idx]
        hi = flat[idx + 1]
        return ((lo + w * (hi - lo)).sum(axis=0)) / self.n_pairs
