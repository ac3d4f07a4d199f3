"""Geodesic distances for reward shaping: shortest paths of the robot centre around the obstacles of a
:class:`~ssl_sim.world.World`, on the one free-space graph of ``ssl_sim.scoring`` (the graph every score uses:
obstacles grown by the bumper radius, 16-connected, no corner cutting; within 2.7 % of the Euclidean shortest
path, 8-connected: 8.2 %).

A victim's *goal region* is the free cells within ``goal_radius`` (horizontal, m) of its mouth, the region where
the environment declares it found. World frame, metres.
"""
from __future__ import annotations

import itertools

import numpy as np
from scipy import ndimage

from ssl_sim.physics.scene_gen import ROBOT_RADIUS
from ssl_sim.scoring import FreeSpaceGraph
from ssl_sim.world import World


class GeodesicMap:
    """Shortest-path distances (m) from any point of the room to each victim's goal region.

    ``goal_radius``: horizontal distance (m) from a victim's mouth that counts as reaching it;
    ``res``: grid cell (m); ``inflate``: robot radius (m) by which obstacles are grown. ``graph``: the
    ``scoring.FreeSpaceGraph`` of ``world`` if already built."""

    def __init__(self, world: World, goal_radius: float, res: float = 0.05, inflate: float = ROBOT_RADIUS,
                 graph: FreeSpaceGraph | None = None) -> None:
        if not goal_radius > 0:
            raise ValueError(f"goal_radius: expected > 0 m, got {goal_radius}")
        if not res > 0:
            raise ValueError(f"res: expected > 0 m, got {res}")
        self.world, self.goal_radius = world, float(goal_radius)
        self.graph = graph if graph is not None else FreeSpaceGraph(world, inflate=inflate, res=res)
        self.res = self.graph.res
        self.free, self.centres = self.graph.free, self.graph.centres
        # For points off the free grid (robot touching an obstacle): the nearest free cell.
        _, self._nearest = ndimage.distance_transform_edt(~self.free, return_indices=True)
        self.fields = [self._field(np.asarray(v.position[:2], float)) for v in world.victims]

    def _field(self, goal_xy: np.ndarray) -> np.ndarray:
        """Distance (m) of every grid cell to the goal region of a victim at ``goal_xy`` (inf if cut off)."""
        out = np.full(self.free.shape, np.inf)
        if self.graph.region(goal_xy, self.goal_radius).size:
            out[self.free] = np.maximum(self.graph.field(goal_xy, self.goal_radius), 0.0)
        return out

    def _cell(self, xy) -> tuple[int, int, float]:
        """Grid cell for a world point: the nearest free cell and the extra distance (m) to reach it."""
        x, y = float(xy[0]), float(xy[1])
        nx, ny = self.free.shape
        i = min(max(int(x // self.res), 0), nx - 1)
        j = min(max(int(y // self.res), 0), ny - 1)
        if self.free[i, j]:
            return i, j, 0.0
        fi, fj = self._nearest[0][i, j], self._nearest[1][i, j]
        return int(fi), int(fj), float(np.hypot(*(self.centres[fi, fj] - (x, y))))

    def distance(self, victim: int, xy) -> float:
        """Shortest-path distance (m) from world point ``xy`` to victim ``victim``'s goal region
        (0 inside it, inf when it cannot be reached)."""
        v = np.asarray(self.world.victims[victim].position[:2])
        x, y = float(xy[0]), float(xy[1])
        if np.hypot(x - v[0], y - v[1]) <= self.goal_radius:
            return 0.0
        f = self.fields[victim]
        # Bilinear between the four surrounding cell centres when all are free and reachable
        # (a smooth distance, so a small move gives a small change); else the nearest free cell.
        fx, fy = x / self.res - 0.5, y / self.res - 0.5
        i0, j0 = int(np.floor(fx)), int(np.floor(fy))
        if 0 <= i0 < f.shape[0] - 1 and 0 <= j0 < f.shape[1] - 1:
            q = f[i0:i0 + 2, j0:j0 + 2]
            if np.all(np.isfinite(q)):
                tx, ty = fx - i0, fy - j0
                return float(max(0.0, (q[0, 0] * (1 - tx) + q[1, 0] * tx) * (1 - ty)
                                 + (q[0, 1] * (1 - tx) + q[1, 1] * tx) * ty))
        i, j, extra = self._cell(xy)
        return float(f[i, j] + extra)

    def shortest_tour(self, start_xy, victims: list[int] | None = None) -> float:
        """Length (m) of the shortest path from ``start_xy`` through the goal regions of ``victims``
        (default all) in the best order. With several victims, legs are measured between regions
        (region to region), a lower bound of the exact tour; exact for one victim."""
        ks = list(range(len(self.fields))) if victims is None else list(victims)
        if not ks:
            return 0.0
        first = {k: self.distance(k, start_xy) for k in ks}
        inter = {}
        for a in ks:
            d = np.hypot(*(self.centres - np.asarray(self.world.victims[a].position[:2])).transpose(2, 0, 1))
            region = self.free & (d <= self.goal_radius)
            for b in ks:
                if a != b:
                    inter[a, b] = float(self.fields[b][region].min()) if region.any() else np.inf
        best = np.inf
        for order in itertools.permutations(ks):
            total = first[order[0]] + sum(inter[a, b] for a, b in zip(order[:-1], order[1:]))
            best = min(best, total)
        return float(best)
