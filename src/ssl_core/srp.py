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

    def __init__(self, tdoa: np.ndarray, fs: float, upsample: int, max_lag: int, interpolate: bool = True,
                 by_point: bool = False):
        """``by_point``: store the table point-major, (points, pairs), for tables read a few columns at a time
        (the fine grid's refinement caps): a point's pairs then share a few cache lines instead of one each,
        and the same values come out in the same memory order as column picks of the pair-major table, so
        ``power`` gives the same numbers to the bit."""
        pos = tdoa * (fs * upsample) + max_lag
        if pos.min() < 0 or pos.max() > 2 * max_lag:
            raise ValueError("TDOA table exceeds the GCC lag window; max_lag is too small for this geometry")
        i0 = np.minimum(np.floor(pos).astype(np.intp), 2 * max_lag - 1)
        frac = (pos - i0).astype(np.float32)
        del pos
        n_pairs = tdoa.shape[0]
        index = (i0 + (np.arange(n_pairs)[:, None] * (2 * max_lag + 1))).astype(np.intp)
        del i0
        self.n_pairs = n_pairs
        self.interpolate = interpolate
        if not interpolate:  # nearest lag: half the gathers, for max-pooled coarse searches
            index = index + (frac >= 0.5)
        self.by_point = by_point
        if by_point:
            self._index_t, self._frac_t = np.ascontiguousarray(index.T), np.ascontiguousarray(frac.T)
        else:
            self._index, self._frac = index, frac

    @property
    def index(self) -> np.ndarray:
        """Flat GCC index (pairs, points) of each point's lower lag (nearest lag without interpolation)."""
        return np.ascontiguousarray(self._index_t.T) if self.by_point else self._index

    @property
    def frac(self) -> np.ndarray:
        """Interpolation weight (pairs, points) of the upper lag, float32."""
        return np.ascontiguousarray(self._frac_t.T) if self.by_point else self._frac

    def power(self, gcc: np.ndarray, columns: np.ndarray | None = None) -> np.ndarray:
        """Mean over pairs of the interpolated GCC at each grid point (or at ``columns`` only)."""
        flat = gcc.reshape(-1)
        if columns is None:
            idx, w = self.index, self.frac
        elif self.by_point:   # (pairs, k) views of (k, pairs) rows: the layout column picks of (pairs, points) give
            idx, w = self._index_t[columns].T, self._frac_t[columns].T
        else:
            idx, w = self._index[:, columns], self._frac[:, columns]
        if not self.interpolate:
            return flat[idx].sum(axis=0) / self.n_pairs
        lo = flat[idx]
        hi = flat[idx + 1]
        return ((lo + w * (hi - lo)).sum(axis=0)) / self.n_pairs
