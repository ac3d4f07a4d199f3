"""Where the robot has listened: per floor cell, the probability that a caller there would still be unheard.

Frame: the occupancy grid's cells (world/odometry frame, x, y in m). Search theory (Koopman): each listen is a
look with a detection probability that falls with the distance to the cell and with a machine's masking at the
listening spot; a caller at a cell stays unheard after the looks so far with probability
prod(1 - p_detect). Exploration then goes where a listen would detect most of what is still unheard
(``gain``), not where the robot has not *driven*: the robot hears 1.5 m around it but covers a 0.3 m swath.

Detection model, measured in dense_pump (``tools/audibility_map.py``: the robot placed on a 0.5 m grid
of the reachable floor, six standing 1 s listens per point, a caller detected within 15 deg in a listen where
she sounds): the mid-room caller within 1.5 m was detected in 27 of 54 listens with the pump more than 2.5 m
away, in 2 of 16 with it closer, and from farther than 1.5 m in 12 of 210 (counted as none here).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np
from scipy import signal

from robot.config_values import need
from robot.occupancy import BlockStore

__all__ = ["CoverageConfig", "ListeningCoverage"]


@dataclass(frozen=True)
class CoverageConfig:
    hearing_radius_m: float = 1.5      # a caller this close is detected with detect_probability per listen
    detect_probability: float = 0.5    # 27 of 54 listens (module docstring)
    masked_within_m: float = 2.5       # ... unless a mapped machine is this close to the listening robot:
    masked_probability: float = 0.12   # 2 of 16 listens
    shadow_depth_m: float = 1.0        # floor behind a bumper contact taken as searched (``shadow``)
    # The area to search, (x_min, y_min, x_max, y_max) in m, odometry frame: a room's floor from a plan, as an
    # operator gives it. Touch maps walls only where met, so without it the floor beyond a wall looks unheard.
    # None: unbounded (exploration then keeps to floor near where the robot has been: planner.frontier_reach_m).
    area: tuple[float, float, float, float] | None = None

    def __post_init__(self) -> None:
        need(self, self.hearing_radius_m > 0, "hearing_radius_m", "> 0 m")
        need(self, 0 < self.detect_probability < 1, "detect_probability", "in (0, 1)")
        need(self, self.masked_within_m >= 0, "masked_within_m", ">= 0 m")
        need(self, self.shadow_depth_m >= 0, "shadow_depth_m", ">= 0 m")
        if self.area is not None:
            ok = len(self.area) == 4 and all(math.isfinite(v) for v in self.area)
            need(self, ok and self.area[0] < self.area[2] and self.area[1] < self.area[3], "area",
                 "(x_min, y_min, x_max, y_max) in m with x_min < x_max and y_min < y_max, or None")
        need(self, 0 <= self.masked_probability <= self.detect_probability, "masked_probability",
             "in [0, detect_probability]")


class ListeningCoverage:
    """``unheard`` (n, n): probability that a caller in each cell is still undetected, on the grid of
    ``origin`` (world x, y of cell (0, 0)'s corner, m), ``n`` cells a side of ``resolution`` m."""

    def __init__(self, origin, n: int, resolution: float, config: CoverageConfig = CoverageConfig(),
                 memory_budget_mb: float = 64.0) -> None:
        self.config = config
        self._anchor = np.asarray(origin, float)[:2]
        self.origin = self._anchor.copy()
        self.offset = (0, 0)   # cells from the first window's corner (``move_to``: the occupancy grid's window)
        self.resolution = float(resolution)
        self.n = int(n)
        self._place((0, 0))
        self.unheard = self._fresh(self._centres)
        # The map beyond the window (as robot.occupancy's): floor never listened to is unheard in the area.
        self.store = BlockStore({"unheard": (np.float64, self._fresh_cells)}, memory_budget_mb * 1e6, "coverage")
        r = int(math.ceil(config.hearing_radius_m / resolution))
        ii, jj = np.mgrid[-r:r + 1, -r:r + 1]
        self._kernel = (np.hypot(ii, jj) * resolution <= config.hearing_radius_m).astype(float)
        self._kernel /= self._kernel.sum()

    def _place(self, offset: tuple[int, int]) -> None:
        self.offset = offset = (int(offset[0]), int(offset[1]))
        self.origin = self._anchor + np.asarray(offset, float) * self.resolution
        n = self.n
        # world m; counted from the first window's corner as the occupancy grid's cells (the same wherever it stands)
        self._centres = self._anchor + (np.indices((n, n)).transpose(1, 2, 0) + offset + 0.5) * self.resolution
        self.in_area = self._in_area(self._centres)   # cells inside the search area (all without one)

    def _in_area(self, c: np.ndarray) -> np.ndarray:
        if self.config.area is None:
            return np.ones(c.shape[:-1], bool)
        x0, y0, x1, y1 = self.config.area
        return (c[..., 0] >= x0) & (c[..., 0] <= x1) & (c[..., 1] >= y0) & (c[..., 1] <= y1)

    def _fresh(self, centres: np.ndarray) -> np.ndarray:
        """Unheard probability of cells never listened to: 1 in the search area, 0 outside (nothing to find)."""
        out = np.ones(centres.shape[:-1])
        out[~self._in_area(centres)] = 0.0
        return out

    def _fresh_cells(self, i: np.ndarray, j: np.ndarray) -> np.ndarray:
        return self._fresh(self._anchor + (np.stack([i, j], -1) + 0.5) * self.resolution)

    def move_to(self, offset: tuple[int, int]) -> None:
        """Put the window's cell (0, 0) at ``offset`` cells from the first window's (the occupancy grid's
        ``offset`` after it moved): the cells left are stored, those entered come back from the store."""
        offset = (int(offset[0]), int(offset[1]))
        if offset == self.offset:
            return
        self.store.save(self.offset, {"unheard": self.unheard})
        self.unheard = self.store.load(offset, (self.n, self.n))["unheard"]
        self._place(offset)

    def detect_probability(self, xy, machines: Sequence[np.ndarray] = ()) -> float:
        """Detection probability per listen, at ``xy`` (world m), of a caller within the hearing radius."""
        cfg = self.config
        masked = any(math.hypot(xy[0] - m[0], xy[1] - m[1]) < cfg.masked_within_m for m in machines)
        return cfg.masked_probability if masked else cfg.detect_probability

    def listened(self, xy, machines: Sequence[np.ndarray] = ()) -> None:
        """A listen at ``xy`` (world m) with ``machines`` (world x, y of mapped interferers) running."""
        p = self.detect_probability(xy, machines)
        c = self._centres
        near = np.hypot(c[..., 0] - xy[0], c[..., 1] - xy[1]) <= self.config.hearing_radius_m
        self.unheard[near] *= 1.0 - p

    def shadow(self, contact_xy, heading: float, width: float) -> None:
        """A bumper contact at ``contact_xy`` while moving along ``heading`` (rad, world): the ``width`` m wide
        strip behind it, ``shadow_depth_m`` deep, is taken as searched. The robot learns walls only by touch, so
        without a search area the floor beyond a wall looks unheard forever and draws exploration along the wall
        (a goal 0.4 m beyond a wall kept the robot driving at it for 100 s; the shadow alone did not end that, the
        search area did). Behind a block the strip is floor the robot hears from its other sides."""
        u = np.array([math.cos(heading), math.sin(heading)])
        rel = self._centres - np.asarray(contact_xy, float)[:2]
        along = rel @ u
        across = rel @ np.array([-u[1], u[0]])
        self.unheard[(along >= 0) & (along <= self.config.shadow_depth_m) & (np.abs(across) <= 0.5 * width)] = 0.0

    def gain(self, machines: Sequence[np.ndarray] = ()) -> np.ndarray:
        """(n, n): for a listen at each cell, the mean still-unheard probability within the hearing radius
        times that listen's detection probability relative to an unmasked one (0..1; 1 = all unheard, no
        machine near)."""
        cfg = self.config
        # Beyond the window's edge (at least occupancy.edge_margin_m from the robot) counts as heard: no goal is
        # near it.
        g = signal.fftconvolve(self.unheard, self._kernel, mode="same")
        if machines:
            c = self._centres
            d = np.min([np.hypot(c[..., 0] - m[0], c[..., 1] - m[1]) for m in machines], axis=0)
            g = np.where(d < cfg.masked_within_m, g * (cfg.masked_probability / cfg.detect_probability), g)
        return g
