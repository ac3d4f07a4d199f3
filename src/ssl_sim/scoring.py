"""The one definition of a rescue's score: finds, false finds, "reached" and SPL, on one free-space graph.

Every score (``runner``'s results.json, the sweep, ``benchmarks/bench_rescue.py``, the gym env's evaluation)
goes through this module; the robot's planner keeps its own graph for planning only. Rationale and sources:
``docs/design/scoring.md``. World frame, metres, seconds, horizontal distances.

* **Free-space graph** (:class:`FreeSpaceGraph`): cells of ``res`` (5 cm) where the robot centre can stand
  (blocking obstacles and walls grown by the bumper radius, ``scene_gen.free_space_grid``), 16-connected (axis,
  diagonal and knight moves, each weighted by its Euclidean length), **no corner cutting**: a move is an edge
  only if every cell its straight segment crosses is free.
* **Find** (:class:`Judge`): a declaration is a find when its *reported* position (the behaviour's estimate)
  lies within :data:`FIND_REPORT_RADIUS_M` (0.5 m) of a victim not yet found **and** the robot base is then
  within :data:`FIND_BASE_RADIUS_M` (1.5 m) of her, at or before the time limit; the credited victim is the
  nearest such one to the report. A **false find** is a declaration whose report is more than 0.5 m from every
  unfound victim (late ones included). A report within 0.5 m of an unfound victim from a base more than 1.5 m
  from her is neither ("too_far"); one after the limit is "late". **Reached** (the former success criterion,
  reported, not scored): a declaration, in time, with the base within :data:`REACHED_RADIUS_M` (0.75 m) of a
  victim not reached before.
* **SPL** (:func:`victim_spl`): per victim, found x l / max(p, l) with l the shortest path on the graph from
  where its leg starts (the start, or the base at the previous find) to within 1.5 m of her, p the path the base
  drove in that leg; victims taken in the order found; 0 if not found; l = p = 0 counts 1. A run's SPL is the
  mean over its victims.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from ssl_sim.physics.scene_gen import ROBOT_RADIUS, free_space_grid

__all__ = ["FIND_REPORT_RADIUS_M", "FIND_BASE_RADIUS_M", "REACHED_RADIUS_M", "FreeSpaceGraph", "Judge",
           "Judgement", "victim_spl", "leg_spls", "run_spl", "SCORING"]

#: A report within this horizontal distance of an unfound victim names her (m).
FIND_REPORT_RADIUS_M = 0.5
#: ... if the robot base is then within this distance of her (a camera or thermal sensor can confirm) (m).
FIND_BASE_RADIUS_M = 1.5
#: The former success criterion, kept as the reported column "reached": base within this distance (m).
REACHED_RADIUS_M = 0.75

#: The definitions, as written into every result.
SCORING = {"find_report_radius_m": FIND_REPORT_RADIUS_M, "find_base_radius_m": FIND_BASE_RADIUS_M,
           "reached_radius_m": REACHED_RADIUS_M,
           "graph": "free floor at 0.05 m, obstacles grown by the robot radius, 16-connected, no corner cutting",
           "spl": "per victim found x shortest / max(path, shortest), legs in the order found, to within "
                  "find_base_radius_m; run = mean over victims"}

# (di, dj) moves and the cells (besides both ends) that the straight segment between the cell centres crosses.
_MOVES: tuple[tuple[tuple[int, int], tuple[tuple[int, int], ...]], ...] = (
    ((1, 0), ()), ((0, 1), ()),
    ((1, 1), ((1, 0), (0, 1))), ((1, -1), ((1, 0), (0, -1))),
    ((2, 1), ((1, 0), (1, 1))), ((1, 2), ((0, 1), (1, 1))),
    ((2, -1), ((1, 0), (1, -1))), ((1, -2), ((0, -1), (1, -1))),
)


def _shifted(a: np.ndarray, di: int, dj: int) -> np.ndarray:
    """``out[i, j] = a[i + di, j + dj]`` (False outside)."""
    out = np.zeros_like(a)
    nx, ny = a.shape
    out[max(0, -di):min(nx, nx - di), max(0, -dj):min(ny, ny - dj)] = \
        a[max(0, di):min(nx, nx + di), max(0, dj):min(ny, ny + dj)]
    return out


class FreeSpaceGraph:
    """Shortest paths (m) of the robot centre on the free floor of ``world`` (see the module docstring).

    ``inflate``: robot radius (m) by which blocking obstacles and walls grow; ``res``: cell size (m)."""

    def __init__(self, world, inflate: float = ROBOT_RADIUS, res: float = 0.05) -> None:
        if not res > 0:
            raise ValueError(f"res: expected a cell size > 0 m, got {res}")
        free, centres = free_space_grid(world, inflate=inflate, res=res)
        self._build(free, centres, res)

    @classmethod
    def from_grid(cls, free: np.ndarray, res: float) -> "FreeSpaceGraph":
        """A graph over a given ``free`` (nx, ny) bool grid whose cell (i, j) is centred at ((i+.5) res, (j+.5) res)."""
        free = np.asarray(free, bool)
        if free.ndim != 2:
            raise ValueError(f"free: expected a 2-D bool grid, got shape {free.shape}")
        i, j = np.meshgrid(np.arange(free.shape[0]), np.arange(free.shape[1]), indexing="ij")
        g = cls.__new__(cls)
        g._build(free, np.stack([(i + 0.5) * res, (j + 0.5) * res], axis=-1), float(res))
        return g

    def _build(self, free: np.ndarray, centres: np.ndarray, res: float) -> None:
        self.res = float(res)
        self.free = free
        self.centres = centres                       # (nx, ny, 2)
        index = np.full(free.shape, -1, np.int64)
        index[free] = np.arange(int(free.sum()))
        self.index = index                           # grid cell -> node (-1: not free)
        self.cells = centres[free]                   # node -> centre (n, 2)
        rows, cols, w = [], [], []
        for (di, dj), via in _MOVES:
            ok = free & _shifted(free, di, dj)
            for vi, vj in via:
                ok &= _shifted(free, vi, vj)
            a, b = np.nonzero(ok)
            rows.append(index[a, b])
            cols.append(index[a + di, b + dj])
            w.append(np.full(a.size, self.res * math.hypot(di, dj)))
        n = len(self.cells)
        self._edges = (np.concatenate(rows), np.concatenate(cols), np.concatenate(w))
        self.graph = coo_matrix((self._edges[2], (self._edges[0], self._edges[1])), shape=(n, n)).tocsr()
        self._fields: dict[tuple[float, float, float], np.ndarray] = {}

    # -- distances ---------------------------------------------------------------------
    def region(self, goal_xy, radius: float) -> np.ndarray:
        """Nodes whose centres lie within ``radius`` (m) of ``goal_xy``."""
        g = np.asarray(goal_xy, float)[:2]
        return np.flatnonzero(np.hypot(*(self.cells - g).T) <= radius)

    def field(self, goal_xy, radius: float = FIND_BASE_RADIUS_M) -> np.ndarray:
        """Shortest path (m) from every node's centre to within ``radius`` of ``goal_xy`` (inf: cut off).

        A path on the graph ends at a cell centre inside the goal disc, up to a knight move past its edge; it is
        credited the part inside (radius - the centre's distance from the goal): a virtual source joined to
        every goal cell by ``2.5 res - that slack`` (>= 0 for the cells a path enters by), the 2.5 res taken
        off again. Nodes inside the disc read <= 0. A goal region holding no node (a victim deep in rubble):
        the path to the node nearest her plus the rest of the way in a straight line."""
        g = np.asarray(goal_xy, float)[:2]
        key = (round(float(g[0]), 9), round(float(g[1]), 9), float(radius))
        f = self._fields.get(key)
        if f is None:
            n = len(self.cells)
            if not n:
                f = np.zeros(0)
            else:
                goal = self.region(g, radius)
                if goal.size:
                    k = 2.5 * self.res
                    w = np.maximum(k - (radius - np.hypot(*(self.cells[goal] - g).T)), 1e-9)
                else:
                    d = np.hypot(*(self.cells - g).T)
                    goal = np.array([int(np.argmin(d))])
                    k, w = 0.0, np.array([max(0.0, float(d[goal[0]]) - radius)]) + 1e-9
                r, c, ww = self._edges
                aug = coo_matrix((np.concatenate([ww, w]), (np.concatenate([r, np.full(goal.size, n)]),
                                                             np.concatenate([c, goal]))), shape=(n + 1, n + 1))
                f = dijkstra(aug.tocsr(), directed=False, indices=n)[:n] - k - 1e-9
            self._fields[key] = f
        return f

    def nearest_node(self, xy) -> tuple[int, float]:
        """The node whose centre is nearest ``xy`` and the straight distance (m) to it (-1, inf: no free floor)."""
        if not len(self.cells):
            return -1, math.inf
        d = np.hypot(*(self.cells - np.asarray(xy, float)[:2]).T)
        k = int(np.argmin(d))
        return k, float(d[k])

    def shortest_path(self, start_xy, goal_xy, radius: float = FIND_BASE_RADIUS_M) -> float:
        """Shortest path (m) of the robot centre from ``start_xy`` to within ``radius`` of ``goal_xy``: 0 if already
        there, else straight to the best free cell centre within 0.75 cells of it (its own cell, or the four
        around a corner it sits on; off the free floor: the nearest free cell) and on along the graph; inf if
        cut off."""
        s, g = np.asarray(start_xy, float)[:2], np.asarray(goal_xy, float)[:2]
        if math.hypot(*(s - g)) <= radius:
            return 0.0
        if not len(self.cells):
            return math.inf
        d = np.hypot(*(self.cells - s).T)
        near = np.flatnonzero(d <= 0.75 * self.res)
        if not near.size:
            near = np.array([int(np.argmin(d))])
        return max(0.0, float(np.min(d[near] + self.field(g, radius)[near])))

    def reachable_area(self, start_xy, goal_xy, radius: float = FIND_BASE_RADIUS_M) -> float:
        """Floor (m^2) where the robot centre can stand within ``radius`` of ``goal_xy``, reachable from
        ``start_xy``: 0 means no behaviour can be credited with a victim there."""
        k, _ = self.nearest_node(start_xy)
        if k < 0:
            return 0.0
        reach = np.isfinite(dijkstra(self.graph, directed=False, indices=k))
        return float(np.count_nonzero(reach[self.region(goal_xy, radius)])) * self.res ** 2


# ----------------------------------------------------------------------------- finds
@dataclass(frozen=True)
class Judgement:
    """How one declaration scores. ``kind``: "find" | "false_find" | "too_far" (report names an unfound victim,
    base too far to confirm) | "late" (report names an unfound victim after the time limit). ``victim``: the
    credited victim (find) or the one nearest the report; distances (m) to her."""

    time_s: float
    kind: str
    victim: int | None
    reported_xy: tuple[float, float]
    base_xy: tuple[float, float]
    report_error_m: float
    base_distance_m: float
    reached: int | None = None       # victim first reached by this declaration (base within REACHED_RADIUS_M)
    late: bool = False


@dataclass
class Judge:
    """Classifies a run's declarations in time order (see the module docstring); ``victims_xy`` (n, 2+) truth."""

    victims_xy: Sequence[Sequence[float]]
    time_limit_s: float
    judgements: list[Judgement] = field(default_factory=list)
    found: dict[int, Judgement] = field(default_factory=dict)
    reached: dict[int, Judgement] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self._v = np.asarray([p[:2] for p in self.victims_xy], float).reshape(-1, 2)

    @property
    def n_victims(self) -> int:
        return len(self._v)

    def declare(self, time_s: float, reported_xy, base_xy) -> Judgement:
        """Score one declaration: ``reported_xy`` the behaviour's estimate, ``base_xy`` the true base position."""
        rep = np.asarray(reported_xy, float)[:2]
        base = np.asarray(base_xy, float)[:2]
        late = time_s > self.time_limit_s + 1e-9
        d_rep = np.hypot(*(self._v - rep).T) if len(self._v) else np.zeros(0)
        d_base = np.hypot(*(self._v - base).T) if len(self._v) else np.zeros(0)
        if not np.all(np.isfinite(rep)):
            d_rep = np.full(len(self._v), np.inf)
        unfound = np.array([k not in self.found for k in range(len(self._v))], bool)
        named = np.flatnonzero(unfound & (d_rep <= FIND_REPORT_RADIUS_M))
        reached = None
        if not late:
            near = [k for k in np.flatnonzero(d_base <= REACHED_RADIUS_M) if k not in self.reached]
            if near:
                reached = int(min(near, key=lambda k: d_base[k]))
        if not named.size:
            kind = "false_find"
            k = int(np.argmin(d_rep)) if len(self._v) and np.isfinite(d_rep).any() else (
                int(np.argmin(d_base)) if len(self._v) else None)
        elif late:
            kind, k = "late", int(named[np.argmin(d_rep[named])])
        else:
            ok = named[d_base[named] <= FIND_BASE_RADIUS_M]
            if ok.size:
                kind, k = "find", int(ok[np.argmin(d_rep[ok])])
            else:
                kind, k = "too_far", int(named[np.argmin(d_rep[named])])
        j = Judgement(float(time_s), kind, k, (float(rep[0]), float(rep[1])), (float(base[0]), float(base[1])),
                      float(d_rep[k]) if k is not None else math.nan,
                      float(d_base[k]) if k is not None else math.nan, reached, late)
        self.judgements.append(j)
        if kind == "find":
            self.found[k] = j
        if reached is not None:
            self.reached[reached] = j
        return j

    @property
    def false_finds(self) -> list[Judgement]:
        return [j for j in self.judgements if j.kind == "false_find"]


# ----------------------------------------------------------------------------- SPL
def victim_spl(shortest_m: float, path_m: float) -> float:
    """found x l / max(p, l) for one found victim's leg (l, p in m); l = p = 0 counts 1, an unreachable goal 0."""
    if not math.isfinite(shortest_m):
        return 0.0
    if shortest_m <= 0.0 and path_m <= 0.0:
        return 1.0
    return shortest_m / max(path_m, shortest_m)


@dataclass(frozen=True)
class Leg:
    """The leg that ended at a find: ``victim``, where it started, the path driven (m), the shortest (m), SPL."""

    victim: int
    start_xy: tuple[float, float]
    path_m: float
    shortest_m: float
    spl: float


def leg_spls(graph: FreeSpaceGraph, victims_xy, start_xy, finds: Sequence[tuple[int, Sequence[float], float]]
             ) -> list[Leg]:
    """Legs of a run: ``finds`` are ``(victim, base_xy at the find, cumulative base path (m) at the find)``,
    in the order found."""
    legs = []
    prev_xy, prev_path = (float(start_xy[0]), float(start_xy[1])), 0.0
    for k, base_xy, path in finds:
        p = float(path) - prev_path
        v = victims_xy[k]
        l = graph.shortest_path(prev_xy, v, FIND_BASE_RADIUS_M)
        legs.append(Leg(int(k), prev_xy, p, l, victim_spl(l, p)))
        prev_xy, prev_path = (float(base_xy[0]), float(base_xy[1])), float(path)
    return legs


def run_spl(n_victims: int, legs: Sequence[Leg]) -> float:
    """A run's SPL: the mean over its ``n_victims`` victims of their leg SPL (0 for victims not found)."""
    if n_victims <= 0:
        return 0.0
    return float(sum(leg.spl for leg in legs)) / n_victims
