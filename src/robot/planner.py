"""Where to drive: a path on the learned occupancy grid to a source's goal, and exploration goals.

Frames: world/odometry frame (x, y in m). Inputs are the ``SoundMap``'s sources and the ``OccupancyGrid``.

* **goal for a source** (``goal_of``): its estimate, or while its range is open a probe across its bearing
  (which source is worth going to is ``robot.options``'s choice).
* **path** (``plan``): Dijkstra (``scipy.sparse.csgraph``) on the grid's free cells (unknown counts as
  free: obstacles are known only where touched or seen by the range sensors), 16-connected, within
  ``search_margin_m`` of the search area when there is one, to the nearest cell within ``stop_radius`` of the
  goal; then shortened to line-of-sight waypoints.
* **exploration** (``explore_goal``): ``explore_headings`` points ``explore_distance_m`` away; the reachable one
  where a listen would hear most of the floor not yet listened to (``robot.coverage``: a mapped machine's
  masking counted there), preferring directions away from found victims (their calls mask fainter ones); or,
  when that is better once path lengths are counted against both, the best such unvisited reachable cell near
  covered floor (frontier: the way out of a covered pocket of rubble).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Sequence

import numpy as np
from scipy import ndimage, sparse
from scipy.sparse.csgraph import dijkstra

from robot.config_values import need
from robot.coverage import ListeningCoverage
from robot.occupancy import OccupancyGrid
from robot.sound_map import MapSource

__all__ = ["PlannerConfig", "Planner", "Plan", "grid_graph", "path_start"]

#: Neighbour offsets for a 16-connected grid (king + knight moves): path lengths within ~3 % of the
#: Euclidean geodesic instead of ~8 % with 8 neighbours.
OFFSETS_16 = ((1, 0), (0, 1), (1, 1), (1, -1), (2, 1), (1, 2), (2, -1), (1, -2))
#: The same offsets in the row-major order of the cells they lead to (the node order of ``grid_graph``).
_OFFSETS_IN_NODE_ORDER = tuple(sorted(OFFSETS_16))


def _outside(xy, area) -> float:
    """Horizontal distance (m) of ``xy`` outside the rectangle ``area`` (0 inside, or without an area)."""
    if area is None:
        return 0.0
    dx = max(area[0] - xy[0], 0.0, xy[0] - area[2])
    dy = max(area[1] - xy[1], 0.0, xy[1] - area[3])
    return math.hypot(dx, dy)


def grid_graph(free: np.ndarray, res: float) -> tuple[sparse.csr_matrix, np.ndarray]:
    """Undirected graph of the ``free`` cells (16-connected, edge = centre distance in m):
    ``(graph, index)`` where ``index[i, j]`` is the node of cell (i, j) or -1.

    Nodes number the free cells in row-major order; each node's row holds its neighbours after it (the other
    half of the edges is the transpose's), in node order: the canonical CSR matrix (sorted, no duplicates) that
    ``coo_matrix(...).tocsr()`` of the same edges gives, built directly (half the time on a 200 x 200 grid)."""
    nx, ny = free.shape
    n = int(free.sum())
    idx = np.full(free.shape, -1, dtype=np.int64)
    idx[free] = np.arange(n)
    pad = np.full((nx + 2, ny + 4), -1, dtype=np.int64)   # room for offsets of up to 2 rows down, 2 columns across
    pad[:nx, 2:ny + 2] = idx
    nb = np.stack([pad[di:di + nx, 2 + dj:2 + dj + ny][free] for di, dj in _OFFSETS_IN_NODE_ORDER], axis=1)
    ok = nb >= 0
    itype = np.int32 if max(n, int(ok.sum())) < 2 ** 31 else np.int64
    indptr = np.zeros(n + 1, dtype=itype)
    np.cumsum(ok.sum(axis=1), out=indptr[1:])
    w = np.broadcast_to(np.array([res * math.hypot(di, dj) for di, dj in _OFFSETS_IN_NODE_ORDER]), nb.shape)
    g = sparse.csr_matrix((w[ok], nb[ok].astype(itype), indptr), shape=(n, n))
    return g, idx


@dataclass(frozen=True)
class PlannerConfig:
    distance_scale_m: float = 3.0      # path length that halves an exploration goal's worth (frontier vs ring)
    keep_factor: float = 1.5           # the current choice's value is multiplied by this (hysteresis: robot.options)
    probe_sigma_m: float = 1.0         # more uncertain than this: drive probe_distance_m along its bearing
    probe_distance_m: float = 1.5      # how far a probe drives along an unranged source's bearing
    probe_angle_deg: float = 30.0      # ... that far off the bearing (a baseline for triangulation)
    stop_radius_m: float = 0.35        # plan to within this of a source's estimate
    explore_distance_m: float = 1.2    # exploration candidates lie this far from the robot
    explore_headings: int = 16         # ... in this many directions
    # A frontier goal is unvisited floor at most this far from floor the robot has covered (Yamauchi's frontier:
    # known floor meets unknown). Touch maps walls only where met, so a cell deep in the unknown may lie beyond one.
    frontier_reach_m: float = 0.6
    # Paths stay within this of the search area (the coverage's ``area``, a floor plan's room): beyond it lies
    # floor the rescuer did not ask to search, in the simulator the far side of the room's walls, which the
    # grid shows as free until a range ray or a touch finds the wall. Searching it cost most of the planner's
    # time (Dijkstra on the whole 20 m window for a 5 m room) and offered paths through the walls.
    search_margin_m: float = 1.0

    #: Fields that no longer exist (robot.config_values.field_values): ignored with a warning.
    RETIRED: ClassVar[dict[str, str]] = {name: "no decision reads it: targets are valued by robot.options" for name in (
        "recency_s", "sigma_scale_m", "stale_s", "max_sigma_m", "min_listens", "min_unknown_listens",
        "unreachable_retry_s", "machine_image_radius_m", "image_bearing_deg", "area_margin_m")}

    def __post_init__(self) -> None:
        need(self, self.distance_scale_m > 0, "distance_scale_m", "> 0 m")
        need(self, self.keep_factor >= 1, "keep_factor", ">= 1")
        need(self, self.probe_sigma_m > 0 and self.probe_distance_m > 0, "probe_sigma_m", "> 0 m (and probe_distance_m)")
        need(self, self.stop_radius_m >= 0, "stop_radius_m", ">= 0 m")
        need(self, self.explore_distance_m > 0, "explore_distance_m", "> 0 m")
        need(self, self.explore_headings >= 4, "explore_headings", "an integer >= 4")
        need(self, self.frontier_reach_m > 0, "frontier_reach_m", "> 0 m")
        need(self, self.search_margin_m >= 0, "search_margin_m", ">= 0 m")


def path_start(start, waypoints, length: float) -> tuple[list[np.ndarray], float]:
    """The first ``length`` m of the polyline from ``start`` (x, y) through ``waypoints`` (k, 2), world m: the
    end points of its legs (waypoints closer than 1 mm to the previous point skipped) and the length they cover."""
    here = np.array(start, float)
    legs, left = [], float(length)
    for wp in np.asarray(waypoints, float):
        d = float(np.hypot(*(wp - here)))
        if d < 1e-3:
            continue
        take = min(d, left)
        legs.append(here + (wp - here) * (take / d))
        left, here = left - take, legs[-1]
        if left <= 1e-3:
            break
    return legs, float(length) - left


@dataclass(frozen=True)
class Plan:
    """A path from the robot to a goal: ``waypoints`` (k, 2) world m (the first is the next one to drive to,
    the last the goal cell), ``length`` m along the grid path."""

    waypoints: np.ndarray
    length: float


class _Graph:
    """A grid graph kept between plans: the free cells it was built from, the node numbering, the nodes' cells
    (filled on first use) and the last Dijkstra search on it."""

    def __init__(self, key: tuple, free: np.ndarray, g: sparse.csr_matrix, idx: np.ndarray) -> None:
        self.key, self.free, self.g, self.idx = key, free, g, idx
        self.cells: np.ndarray | None = None
        self.search: tuple[np.ndarray, np.ndarray, np.ndarray, int] | None = None


class Planner:
    def __init__(self, config: PlannerConfig = PlannerConfig()) -> None:
        self.config = config
        self._graph: _Graph | None = None
        self._frontier: np.ndarray | None = None    # the frontier cell being explored toward (world x, y)
        self._near: tuple[tuple, np.ndarray] | None = None   # the cells near the search area, per grid window

    # -- paths ----------------------------------------------------------------------------
    def distances(self, grid: OccupancyGrid, start_xy, area=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """Dijkstra from the robot: ``(dist per node, predecessors, index grid, start node)`` (read only: the
        arrays are kept and handed out again while the grid's free cells and the start cell stay the same).
        ``area`` (x_min, y_min, x_max, y_max, world m): the search area; the cells farther than
        ``search_margin_m`` outside it are left out while the robot is within that margin."""
        free = ~grid.blocked
        s = grid.cell(start_xy)
        if not grid.inside(s):
            raise ValueError(f"start_xy: {tuple(start_xy)} is outside the occupancy grid")
        if area is not None:
            near = self._near_area(grid, area)
            if near[s]:
                free &= near
        if not free[s]:   # touching an obstacle: the robot is where it is, so its own cell is free
            free[s] = True
        graph = self._graph_of(free, grid)
        start = int(graph.idx[s])
        if graph.search is None or graph.search[3] != start:
            dist, pred = dijkstra(graph.g, directed=False, indices=start, return_predecessors=True)
            for a in (dist, pred):
                a.flags.writeable = False
            graph.search = (dist, pred, graph.idx, start)
        return graph.search

    def _near_area(self, grid: OccupancyGrid, area) -> np.ndarray:
        """Cells whose centre lies within ``search_margin_m`` of the rectangle ``area`` (kept per grid window)."""
        key = (tuple(area), grid.resolution, tuple(grid.centre((0, 0))), grid.n)
        if self._near is None or self._near[0] != key:
            m = self.config.search_margin_m
            x = grid.centre(np.stack([np.arange(grid.n), np.zeros(grid.n, int)], axis=1))[:, 0]
            y = grid.centre(np.stack([np.zeros(grid.n, int), np.arange(grid.n)], axis=1))[:, 1]
            ok_x = (x >= area[0] - m) & (x <= area[2] + m)
            ok_y = (y >= area[1] - m) & (y <= area[3] + m)
            self._near = (key, np.outer(ok_x, ok_y))
        return self._near[1]

    def _graph_of(self, free: np.ndarray, grid: OccupancyGrid) -> _Graph:
        """The graph of ``free`` on ``grid``'s cells, rebuilt only when a cell's state, the grid's extent or its
        resolution changed: the robot replans every cycle, mostly on the same free cells (building the graph of
        a 200 x 200 grid took as long as the Dijkstra search on it)."""
        g = self._graph
        key = (grid.resolution, tuple(grid.origin), free.shape)
        if g is None or g.key != key or not np.array_equal(g.free, free):
            graph, idx = grid_graph(free, grid.resolution)
            for a in (free, idx):
                a.flags.writeable = False
            g = self._graph = _Graph(key, free, graph, idx)
        return g

    def plan(self, grid: OccupancyGrid, start_xy, goal_xy, stop_radius: float | None = None,
             _search=None) -> Plan | None:
        """Shortest path to within ``stop_radius`` (default ``stop_radius_m``) of ``goal_xy``; None if none."""
        r = self.config.stop_radius_m if stop_radius is None else stop_radius
        search = _search if _search is not None else self.distances(grid, start_xy)
        node = self._goal_node(grid, search, goal_xy, r)
        return None if node is None else self._path(grid, search, start_xy, node)

    @staticmethod
    def _goal_node(grid: OccupancyGrid, search, goal_xy, r: float) -> int | None:
        """The reachable node within ``r`` (at least 0.75 cell) of ``goal_xy`` that is shortest to reach *and*
        then to the goal (on the line toward it, not the near rim), or None. Only the cells of the goal's box
        are looked at, in row-major (= node) order, so ties go to the same node as over the whole grid."""
        dist, _, idx, _ = search
        goal = np.asarray(goal_xy, float)[:2]
        rr = max(r, grid.resolution * 0.75)
        lo, hi = grid.cell(goal - rr), grid.cell(goal + rr)
        i0, j0 = max(lo[0] - 1, 0), max(lo[1] - 1, 0)
        sub = idx[i0:max(hi[0] + 2, 0), j0:max(hi[1] + 2, 0)]
        cells = np.argwhere(sub >= 0)
        if not cells.size:
            return None
        nodes = sub[sub >= 0]
        cells += (i0, j0)
        to_goal = np.hypot(*(grid.centre(cells) - goal).T)
        reach = (to_goal <= rr) & np.isfinite(dist[nodes])
        if not np.any(reach):
            return None
        return int(nodes[reach][int(np.argmin(dist[nodes[reach]] + to_goal[reach]))])

    def _path(self, grid: OccupancyGrid, search, start_xy, node: int) -> Plan:
        """The search's path from the robot to ``node``, shortened to line-of-sight waypoints."""
        dist, pred, idx, start = search
        chain = [node]
        while chain[-1] != start and pred[chain[-1]] >= 0:
            chain.append(int(pred[chain[-1]]))
        cell_of = self._cells_of(idx)[np.asarray(chain[::-1])]
        path = grid.centre(cell_of)
        path[0] = np.asarray(start_xy, float)[:2]
        return Plan(self._shortcut(grid, path), float(dist[node]))

    def _cells_of(self, idx: np.ndarray) -> np.ndarray:
        """The cells (k, 2) of the graph's nodes in node order (``grid_graph`` numbers the free cells in
        row-major order), kept with the graph."""
        g = self._graph
        if g is not None and g.idx is idx and g.cells is not None:
            return g.cells
        cells = np.argwhere(idx >= 0)
        if g is not None and g.idx is idx:
            g.cells = cells
        return cells

    @staticmethod
    def _shortcut(grid: OccupancyGrid, path: np.ndarray) -> np.ndarray:
        """Line-of-sight waypoints along a grid path (the first point, the robot, dropped): from each waypoint
        the farthest later point in clear sight (the next point when none beyond it is)."""
        blocked = grid.blocked
        out = []
        i = 0
        while i < len(path) - 1:
            j = len(path) - 1
            if j > i + 1 and not Planner._clear(grid, blocked, path[i], path[j:j + 1])[0]:
                # The straight line to the end is blocked (checked first: the common case is a clear one).
                ok = np.flatnonzero(Planner._clear(grid, blocked, path[i], path[i + 2:j]))
                j = i + 2 + int(ok[-1]) if ok.size else i + 1
            out.append(path[j])
            i = j
        return np.array(out).reshape(-1, 2) if out else path[-1:].copy()

    @staticmethod
    def _clear(grid: OccupancyGrid, blocked: np.ndarray, a, ends: np.ndarray) -> np.ndarray:
        """Per point of ``ends`` (k, 2): is the segment from ``a`` free of blocked cells? Each segment is
        sampled every half cell (all segments in one pass)."""
        if not len(ends):
            return np.zeros(0, bool)
        ns = [max(2, int(math.ceil(np.linalg.norm(b - a) / (0.5 * grid.resolution)))) for b in ends]
        t = np.concatenate([np.linspace(0, 1, n) for n in ns])
        seg = np.repeat(np.arange(len(ends)), ns)
        pts = a + t[:, None] * (ends[seg] - a)
        ij = np.floor((pts - grid.origin) / grid.resolution).astype(int)
        ok = (ij >= 0).all(1) & (ij < grid.n).all(1)
        hit = np.zeros(len(pts), bool)
        hit[ok] = blocked[ij[ok, 0], ij[ok, 1]]
        return ~np.logical_or.reduceat(hit, np.concatenate([[0], np.cumsum(ns)[:-1]]))

    # -- targets --------------------------------------------------------------------------
    def goal_of(self, s: MapSource, pose) -> np.ndarray:
        """Where to drive for a source: its estimate, or, while its range is unknown (1-sigma over
        ``probe_sigma_m``: heard from one place, near the horizon), ``probe_distance_m`` toward it but
        ``probe_angle_deg`` off its bearing (closer, and across the bearing so that the next ones triangulate)."""
        cfg = self.config
        xy = np.asarray(pose[:2], float)
        v = s.position[:2] - xy
        d = float(np.hypot(*v))
        if s.horizontal_sigma_m <= cfg.probe_sigma_m or d < 1e-9:
            return s.position[:2].copy()
        # 30 deg off the bearing: closer, and across it, so that the next bearings cross this one.
        a = math.atan2(v[1], v[0]) + math.radians(cfg.probe_angle_deg)
        step = min(d, cfg.probe_distance_m)
        return xy + step * np.array([math.cos(a), math.sin(a)])

    def explore_goal(self, grid: OccupancyGrid, pose, coverage: ListeningCoverage, avoid: Sequence[np.ndarray] = (),
                     machines: Sequence[np.ndarray] = (), gain: np.ndarray | None = None) -> tuple[Plan | None, str]:
        """A reachable point ``explore_distance_m`` away where a listen would hear most of the floor not yet
        listened to (``coverage``; ``machines``, the mapped interferers' world x, y, mask the goals near them),
        away from the points ``avoid`` (found victims), or the best frontier goal (module docstring)."""
        cfg = self.config
        x, y = float(pose[0]), float(pose[1])
        search = self.distances(grid, (x, y), coverage.config.area)
        best = None
        gain = coverage.gain(machines) if gain is None else gain   # the caller's, if it has it (one FFT a cycle)
        occupied = grid.occupied
        r = int(round(1.0 / grid.resolution))   # judge a direction by the floor within 1 m of its goal
        for k in range(cfg.explore_headings):
            a = 2 * math.pi * k / cfg.explore_headings
            goal = np.array([x + cfg.explore_distance_m * math.cos(a), y + cfg.explore_distance_m * math.sin(a)])
            ij = grid.cell(goal)
            if not grid.inside(ij) or grid.blocked[ij]:
                continue
            box = (slice(max(0, ij[0] - r), ij[0] + r + 1), slice(max(0, ij[1] - r), ij[1] + r + 1))
            # Floor not yet listened to draws; known obstacles there (walls met before) push away.
            score = float(gain[ij]) - 3.0 * float(occupied[box].mean())
            score += float(self._away(goal[None], (x, y), avoid)[0])
            node = self._goal_node(grid, search, goal, 0.2)   # the path is built for the best goal only
            if node is None or search[0][node] > 2.0 * cfg.explore_distance_m:
                continue
            if best is None or score > best[0]:
                best = (score, node, math.degrees(a))
        if best is not None:
            best = (best[0], self._path(grid, search, (x, y), best[1]), best[2])
        far, far_why = self._frontier_goal(grid, (x, y), gain, coverage.in_area if coverage.config.area else None,
                                           avoid, search)
        # The ring's best against the best unvisited cell anywhere, each worth its score over (1 + path length /
        # distance_scale_m) as a target is: in a pocket of rubble whose floor is covered the ring offers only
        # visited floor (measured, dense_pump: the robot circled its start for 100-250 s), the way out leads on.
        # A ring goal worth nothing (heard floor, learned obstacles) is no goal: with no frontier either, the
        # behaviour's clearing recovery must look again (else the robot steps to and fro between two such goals
        # inside a ring of misplaced contacts: 80 s of it was measured beside a loud pump).
        if best is not None and best[0] > 0 and (far is None or self._worth(best[0], best[1].length) >= far[1]):
            self._frontier = None
            return best[1], f"toward unheard floor at {best[2]:.0f} deg (world), {best[0]:.2f} unheard/away score"
        if far is None:
            return None, far_why
        return far[0], far_why

    def _away(self, goals: np.ndarray, xy, avoid: Sequence[np.ndarray]) -> np.ndarray:
        """Bonus of ``goals`` (..., 2) for leading away from found victims: their calls mask fainter sources.
        0.5 per ``explore_distance_m`` farther than the robot is, within -0.5..0.5. (A machine's masking is in
        the listening coverage's gain.)"""
        cfg = self.config
        out = np.zeros(goals.shape[:-1])
        for p in avoid:
            d = np.hypot(goals[..., 0] - p[0], goals[..., 1] - p[1]) - math.hypot(xy[0] - p[0], xy[1] - p[1])
            out += 0.5 * np.clip(d / cfg.explore_distance_m, -1, 1)
        return out

    def _worth(self, score, length):
        return np.maximum(score, 0.0) / (1.0 + length / self.config.distance_scale_m)

    def _frontier_goal(self, grid: OccupancyGrid, xy, gain: np.ndarray, area: np.ndarray | None,
                       avoid: Sequence[np.ndarray], search) -> tuple[tuple[Plan, float] | None, str]:
        """The best unvisited reachable cell anywhere (frontier exploration, Yamauchi 1997) at least
        ``explore_distance_m`` along the path, scored as the ring's goals, worth that score (if positive) over
        (1 + path length / ``distance_scale_m``): ``((plan, worth), why)`` or ``(None, why)``."""
        cfg = self.config
        dist, _, idx, _ = search
        reach = idx >= 0
        reach[reach] = np.isfinite(dist[idx[reach]])
        length = np.full(idx.shape, np.inf)
        length[reach] = dist[idx[reach]]
        size = 2 * int(round(1.0 / grid.resolution)) + 1   # the floor within 1 m, as in explore_goal
        unvisited = (grid.visited == 0) & ~grid.blocked
        score = gain - 3.0 * ndimage.uniform_filter(grid.occupied.astype(float), size, mode="constant")
        centres = grid.origin + (np.indices(idx.shape).transpose(1, 2, 0) + 0.5) * grid.resolution
        score += self._away(centres, xy, avoid)
        if area is None:
            area = ndimage.distance_transform_edt(grid.visited == 0) * grid.resolution <= cfg.frontier_reach_m
        ok = reach & unvisited & area & (length >= cfg.explore_distance_m)
        utility = np.where(ok, self._worth(score, np.where(ok, length, 0.0)), -np.inf)
        ij = np.unravel_index(int(np.argmax(utility)), utility.shape)
        # The frontier goal chosen before, while still unvisited, reachable and not reached, counts keep_factor
        # times (as the current target does): without it the robot turned back and forth between frontiers as
        # each step changed their path lengths (100 s between two of them was measured in dense rubble).
        kept = self._frontier
        self._frontier = None
        if kept is not None:
            k = grid.cell(kept)
            if grid.inside(k) and reach[k] and unvisited[k] and length[k] > 0.3:
                worth = float(self._worth(score[k], length[k])) * cfg.keep_factor
                if worth > 0 and not worth < utility[ij]:
                    ij = k
                    utility[k] = worth
        if not utility[ij] > 0:
            return None, "no reachable unexplored direction or floor on the learned grid"
        goal = grid.centre(ij)
        plan = self.plan(grid, xy, goal, stop_radius=0.2, _search=search)
        if plan is None:   # cannot happen for a reachable cell; kept for a clear answer
            return None, "no reachable unexplored direction or floor on the learned grid"
        self._frontier = goal
        return (plan, float(utility[ij])), (f"toward the unvisited floor at ({goal[0]:.2f}, {goal[1]:.2f}) (frontier),"
                                            f" {plan.length:.2f} m of path, {score[ij]:.2f} unheard/away score")
