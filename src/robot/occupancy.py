"""Occupancy grid learned by touch and by range sensors: bump contacts, stalls and wheel slip mark obstacles,
range returns mark obstacles ahead of the robot, driving and clear rays mark free floor.

Frame: the odometry/world frame (x, y in m). The grid is ``size_m`` square, centred on ``origin`` (the start
pose by default), at ``resolution_m``; cells hold log-odds of "an obstacle (for the robot's body) is here",
0 = unknown. A robot without range sensors learns obstacles only where it touches them, so:

* a **contact** (bumper, stall, slip) at the robot's pose while moving along ``heading`` marks a short
  obstacle face: the cells ``contact_width_m`` wide across the heading, just beyond the bumper
  (``robot_radius_m``) -- the bumper is a ring, so the contact is somewhere on its front arc; a bumper press
  makes an obstacle at once, a stall only when repeated (wheels stall on debris they could cross);
* ``forget`` (clearing recovery) drops the obstacles that a single contact made when they close every way;
* the robot's **footprint** along its path is free (log-odds lowered; the footprint is where it was, so
  nothing blocking is there at the robot's height);
* ``visited`` counts footprint coverage (for exploration);
* **range rays** (``mark_rays``, from ``robot.ranging``) keep their own layer of log-odds: a return raises its
  cell, the cells the ray crossed are lowered (the usual inverse sensor model of a beam, Thrun et al.,
  *Probabilistic Robotics* ch. 9). A separate layer because the rays pass 0.075 m above the floor and the bumper
  reaches down to 0.045 m: a clear ray over low rubble must not erase the contact that found it. A cell is an
  obstacle when either layer says so.

``blocked`` is the configuration space for the robot centre: occupied cells grown by ``robot_radius_m``.

**A map that grows**: the arrays are a ``size_m`` square *window* of an unbounded map. When the robot comes within
``edge_margin_m`` of the window's edge, ``follow`` moves the window to centre it again: the cells it leaves go to
a store of ``STORE_BLOCK`` x ``STORE_BLOCK`` cell blocks (only blocks holding anything learned), the cells it
enters come back from the store (unknown where never seen). Everything that reads the grid (planner, coverage)
works on the window, so the CPU per cycle does not grow with the map; the store grows with the floor the
window has passed over and is bounded by ``memory_budget_mb`` (``MapMemoryError`` names the figures when reached).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from robot.config_values import need

__all__ = ["OccupancyConfig", "OccupancyGrid", "MapMemoryError", "WINDOW_BYTES_PER_CELL", "STORE_BLOCK",
           "BlockStore"]

#: Working memory per cell of the window while the behaviour plans on it (bytes): the grid's layers, the
#: listening coverage, the planner's graph (16 neighbours, sparse matrix build) and Dijkstra search, the frontier
#: score fields. Measured with tracemalloc: a replan and an exploration goal on a 200 x 200 window peaked at 454
#: bytes a cell above the 45 of the layers held; rounded up.
WINDOW_BYTES_PER_CELL = 600
#: Cells a side of a stored block of the map beyond the window.
STORE_BLOCK = 64


class MapMemoryError(RuntimeError):
    """The map outgrew its configured memory budget (the message gives the figures and the field to raise)."""


class BlockStore:
    """Layers of a map beyond its window, in ``STORE_BLOCK``-cell square blocks keyed by block index (cells
    counted from a fixed anchor), each block one array per layer; only blocks that differ from the layers'
    defaults are kept. ``defaults``: name -> (dtype, default value per cell: a scalar, or a function of the
    blocks' cell indices (i, j) arrays giving the value)."""

    def __init__(self, defaults: dict, budget_bytes: float, what: str) -> None:
        self.defaults = defaults
        self.blocks: dict[tuple[int, int], dict[str, np.ndarray]] = {}
        self.budget_bytes = float(budget_bytes)
        self.what = what
        self.block_bytes = STORE_BLOCK ** 2 * sum(np.dtype(t).itemsize for t, _ in defaults.values())

    @property
    def nbytes(self) -> int:
        return len(self.blocks) * self.block_bytes

    def _default(self, name: str, bi: int, bj: int) -> np.ndarray:
        dtype, value = self.defaults[name]
        if callable(value):
            i, j = np.meshgrid(np.arange(STORE_BLOCK) + bi * STORE_BLOCK, np.arange(STORE_BLOCK) + bj * STORE_BLOCK,
                               indexing="ij")
            return np.asarray(value(i, j), dtype)
        return np.full((STORE_BLOCK, STORE_BLOCK), value, dtype)

    def _spans(self, i0: int, n: int) -> list[tuple[int, int, int]]:
        """(block index, first cell in it, last cell + 1) of the cells i0 .. i0 + n - 1."""
        out = []
        b = i0 // STORE_BLOCK
        while b * STORE_BLOCK < i0 + n:
            a, e = max(i0, b * STORE_BLOCK), min(i0 + n, (b + 1) * STORE_BLOCK)
            out.append((b, a, e))
            b += 1
        return out

    def save(self, offset: tuple[int, int], layers: dict[str, np.ndarray]) -> None:
        """Keep ``layers`` (each (n, n), cell (0, 0) at cell ``offset`` from the anchor)."""
        oi, oj = offset
        n_i, n_j = next(iter(layers.values())).shape
        for bi, a, e in self._spans(oi, n_i):
            for bj, c, f in self._spans(oj, n_j):
                blk = self.blocks.get((bi, bj))
                new = blk is None
                if new:
                    blk = {k: self._default(k, bi, bj) for k in self.defaults}
                for k, arr in layers.items():
                    blk[k][a - bi * STORE_BLOCK:e - bi * STORE_BLOCK, c - bj * STORE_BLOCK:f - bj * STORE_BLOCK] = \
                        arr[a - oi:e - oi, c - oj:f - oj]
                if new:
                    if all(np.array_equal(blk[k], self._default(k, bi, bj)) for k in self.defaults):
                        continue   # nothing learned there
                    if self.nbytes + self.block_bytes > self.budget_bytes:
                        raise MapMemoryError(
                            f"{self.what}: the map beyond the window would grow past {len(self.blocks) + 1} blocks "
                            f"of {STORE_BLOCK} x {STORE_BLOCK} cells ({(self.nbytes + self.block_bytes) / 1e6:.1f} MB "
                            f"stored) over its memory budget ({self.budget_bytes / 1e6:.1f} MB); raise "
                            "memory_budget_mb or use a coarser resolution_m")
                    self.blocks[(bi, bj)] = blk

    def load(self, offset: tuple[int, int], shape: tuple[int, int]) -> dict[str, np.ndarray]:
        """The layers of the window of ``shape`` cells at cell ``offset`` (defaults where nothing is stored)."""
        oi, oj = offset
        out = {}
        for k, (dtype, value) in self.defaults.items():
            if callable(value):
                i, j = np.meshgrid(np.arange(shape[0]) + oi, np.arange(shape[1]) + oj, indexing="ij")
                out[k] = np.asarray(value(i, j), dtype)
            else:
                out[k] = np.full(shape, value, dtype)
        for bi, a, e in self._spans(oi, shape[0]):
            for bj, c, f in self._spans(oj, shape[1]):
                blk = self.blocks.get((bi, bj))
                if blk is None:
                    continue
                for k in self.defaults:
                    out[k][a - oi:e - oi, c - oj:f - oj] = \
                        blk[k][a - bi * STORE_BLOCK:e - bi * STORE_BLOCK, c - bj * STORE_BLOCK:f - bj * STORE_BLOCK]
        return out


@dataclass(frozen=True)
class OccupancyConfig:
    resolution_m: float = 0.1        # cell size (the bumper ring is 0.32 m across: 3 cells)
    size_m: float = 20.0             # grid side (shipped rooms are <= 7 m; the start may be in a corner)
    robot_radius_m: float = 0.16     # bumper radius (ssl_sim robot model; the real chassis matches)
    contact_width_m: float = 0.3     # width of the obstacle face marked by one contact (~ the bumper's front arc)
    hit_log_odds: float = 2.0        # per bumper contact (one makes a cell occupied: p = 0.88)
    stall_log_odds: float = 0.6      # per stall or gyro-detected slip: most are no obstacle (measured, MuJoCo truth:
    #                                  dense_pump seeds 0-3, 10 of 13 stalls 0.24-0.46 m from any obstacle, wheels
    #                                  on debris; 66 bumper presses in 7 runs of 4 scenarios all within 0.2 m): two
    #                                  at one place make an obstacle (the robot does not retry one forever)
    free_log_odds: float = -0.4      # per footprint pass (five passes outweigh one contact)
    occupied_log_odds: float = 1.0   # a cell at or above this is an obstacle
    max_log_odds: float = 6.0        # clamp of a cell's log-odds (a confirmed cell can still be cleared)
    range_hit_log_odds: float = 0.7   # per ray return: two returns make an obstacle (one alone may be the floor
    #                                   seen by a tilted robot on rubble)
    range_sure_m: float = 0.35        # a return this close is an obstacle at once: the floor seen by a tilted ray
    #                                   is >= 0.075 m / sin(tilt) away, 0.35 m at a 12 deg tilt
    range_free_log_odds: float = -0.35  # per ray crossing a cell
    range_max_log_odds: float = 3.5   # clamp: ten crossings clear a confirmed return again (odometry drifts)
    # The window moves (module docstring) when the robot is this close to its edge: the hearing radius (1.5 m)
    # plus the robot's, so a listen's floor lies on the window (at most a quarter of size_m: a small window moves
    # when the robot leaves its middle half). The shipped rooms (<= 7 m) never move the default window.
    edge_margin_m: float = 2.0
    memory_budget_mb: float = 256.0   # the window's working memory plus the stored map beyond it (100 x 100 m
    #                                   at 0.1 m: 16 MB window + 20 MB of occupancy store)

    def __post_init__(self) -> None:
        need(self, self.resolution_m > 0 and math.isfinite(self.resolution_m), "resolution_m", "> 0 m")
        need(self, math.isfinite(self.size_m) and self.size_m >= 10 * self.resolution_m, "size_m",
             f">= 10 cells ({10 * self.resolution_m} m)")
        need(self, self.memory_budget_mb > 0 and math.isfinite(self.memory_budget_mb), "memory_budget_mb", "> 0 MB")
        need(self, 0 <= self.edge_margin_m < math.inf, "edge_margin_m", ">= 0 m")
        cells = math.ceil(self.size_m / self.resolution_m) ** 2
        need_mb = cells * WINDOW_BYTES_PER_CELL / 1e6
        if need_mb > self.memory_budget_mb:
            raise ValueError(
                f"OccupancyConfig.resolution_m={self.resolution_m!r}, size_m={self.size_m!r}: the map window of "
                f"{cells:.3g} cells needs about {_mb(need_mb)} to plan on ({WINDOW_BYTES_PER_CELL} bytes a cell), "
                f"more than memory_budget_mb={self.memory_budget_mb:g}; use a coarser resolution_m or a smaller "
                "size_m (the map grows beyond the window as the robot moves), or raise memory_budget_mb")
        need(self, self.robot_radius_m > 0, "robot_radius_m", "> 0 m")
        need(self, self.contact_width_m > 0, "contact_width_m", "> 0 m")
        need(self, self.hit_log_odds > 0, "hit_log_odds", "> 0")
        need(self, 0 < self.stall_log_odds <= self.hit_log_odds, "stall_log_odds", "in (0, hit_log_odds]")
        need(self, self.free_log_odds < 0, "free_log_odds", "< 0")
        need(self, 0 < self.occupied_log_odds <= self.max_log_odds, "occupied_log_odds", "in (0, max_log_odds]")
        need(self, self.range_hit_log_odds > 0, "range_hit_log_odds", "> 0")
        need(self, self.range_free_log_odds < 0, "range_free_log_odds", "< 0")
        need(self, self.range_sure_m >= 0, "range_sure_m", ">= 0 m")
        need(self, self.range_max_log_odds >= self.occupied_log_odds, "range_max_log_odds", ">= occupied_log_odds")


def _mb(mb: float) -> str:
    return f"{mb / 1e6:.3g} TB" if mb >= 1e6 else f"{mb / 1e3:.3g} GB" if mb >= 1e3 else f"{mb:.3g} MB"


class OccupancyGrid:
    """See the module docstring. ``origin``: (x, y) of the first window's centre in the world frame (m), or
    ``corner``: its cell (0, 0)'s corner;
    ``self.origin`` is the world (x, y) of the current window's cell (0, 0) corner."""

    def __init__(self, config: OccupancyConfig = OccupancyConfig(), origin=(0.0, 0.0), corner=None) -> None:
        self.config = config
        self.n = int(math.ceil(config.size_m / config.resolution_m))
        # the first window's corner (``corner``: given instead of the centre, e.g. to share another grid's cells)
        self._anchor = np.asarray(origin, float)[:2] - 0.5 * self.n * config.resolution_m if corner is None \
            else np.asarray(corner, float)[:2].copy()
        self.offset = (0, 0)   # cells from the first window's corner to this one's
        self.origin = self._anchor.copy()  # corner of cell (0, 0)
        self.log_odds = np.zeros((self.n, self.n))          # touch: contacts, stalls, footprints
        self.range_log_odds = np.zeros((self.n, self.n))    # range rays (and footprints)
        self.visited = np.zeros((self.n, self.n), dtype=np.int32)
        self.contacts: list[tuple[float, float, str]] = []   # (x, y, why): where contacts were marked
        self._blocked: np.ndarray | None = None
        # The budget left after the window is shared with the listening coverage's store by bytes per cell: 20
        # here (two float64 layers and an int32), 8 there (one float64).
        beyond = config.memory_budget_mb * 1e6 - self.n ** 2 * WINDOW_BYTES_PER_CELL
        self.coverage_store_mb = beyond * 8 / 28 / 1e6
        self.store = BlockStore({"log_odds": (np.float64, 0.0), "range_log_odds": (np.float64, 0.0),
                                 "visited": (np.int32, 0)}, beyond * 20 / 28, "occupancy")

    # -- the window -------------------------------------------------------------------------
    @property
    def anchor(self) -> np.ndarray:
        """World (x, y) of the first window's cell (0, 0) corner, m: map cells are counted from it."""
        return self._anchor.copy()

    def needs_move(self, xy) -> bool:
        """Is ``xy`` (world m) within ``edge_margin_m`` of the window's edge (or beyond it)?"""
        m = min(self.config.edge_margin_m, 0.25 * self.n * self.resolution)
        lo = self.origin + m
        hi = self.origin + self.n * self.resolution - m
        p = np.asarray(xy, float)[:2]
        return bool(np.any(p < lo) or np.any(p > hi))

    def window_offset_for(self, xy) -> tuple[int, int]:
        """The window offset (cells from the first window) that centres the window on ``xy``."""
        c = np.floor((np.asarray(xy, float)[:2] - self._anchor) / self.resolution).astype(int) - self.n // 2
        return int(c[0]), int(c[1])

    def follow(self, xy) -> bool:
        """Move the window to centre it on ``xy`` (world m) if ``xy`` is within ``edge_margin_m`` of its edge;
        returns whether it moved. Raises ``MapMemoryError`` when the store would pass the memory budget."""
        if not self.needs_move(xy):
            return False
        self.move_to(self.window_offset_for(xy))
        return True

    def move_to(self, offset: tuple[int, int]) -> None:
        """Put the window's cell (0, 0) at ``offset`` cells from the first window's."""
        offset = (int(offset[0]), int(offset[1]))
        if offset == self.offset:
            return
        self.store.save(self.offset, {"log_odds": self.log_odds, "range_log_odds": self.range_log_odds,
                                      "visited": self.visited})
        layers = self.store.load(offset, (self.n, self.n))
        self.log_odds, self.range_log_odds, self.visited = layers["log_odds"], layers["range_log_odds"], \
            layers["visited"]
        self.offset = offset
        self.origin = self._anchor + np.asarray(offset, float) * self.resolution
        self._blocked = None

    @property
    def memory_bytes(self) -> int:
        """The window's working memory (``WINDOW_BYTES_PER_CELL`` a cell) plus the store's blocks."""
        return self.n ** 2 * WINDOW_BYTES_PER_CELL + self.store.nbytes

    # -- coordinates ----------------------------------------------------------------------
    @property
    def resolution(self) -> float:
        return self.config.resolution_m

    def cell(self, xy) -> tuple[int, int]:
        """Cell index of a world point (may be outside the grid)."""
        ij = np.floor((np.asarray(xy, float)[:2] - self._anchor) / self.resolution).astype(int) - self.offset
        return int(ij[0]), int(ij[1])

    # Cells are counted from the first window's corner (``_anchor``) and shifted by the window's ``offset``, so a
    # point falls in the same map cell, and a cell has the same centre, wherever the window stands.
    def centre(self, ij) -> np.ndarray:
        return self._anchor + (np.asarray(ij, float) + self.offset + 0.5) * self.resolution

    def inside(self, ij) -> bool:
        return 0 <= ij[0] < self.n and 0 <= ij[1] < self.n

    def _disc(self, xy, radius: float) -> tuple[np.ndarray, np.ndarray]:
        r = int(math.ceil(radius / self.resolution)) + 1
        ci, cj = self.cell(xy)
        ii, jj = np.meshgrid(np.arange(ci - r, ci + r + 1), np.arange(cj - r, cj + r + 1), indexing="ij")
        c = self._anchor + (np.stack([ii, jj], -1) + self.offset + 0.5) * self.resolution
        ok = np.hypot(c[..., 0] - xy[0], c[..., 1] - xy[1]) <= radius
        ok &= (ii >= 0) & (ii < self.n) & (jj >= 0) & (jj < self.n)
        return ii[ok], jj[ok]

    # -- learning -------------------------------------------------------------------------
    def mark_free(self, xy) -> None:
        """The robot stood here: its footprint is free floor (and visited)."""
        cfg = self.config
        ii, jj = self._disc(xy, cfg.robot_radius_m * 0.75)
        self.log_odds[ii, jj] = np.maximum(self.log_odds[ii, jj] + cfg.free_log_odds, -cfg.max_log_odds)
        self.range_log_odds[ii, jj] = np.maximum(self.range_log_odds[ii, jj] + cfg.free_log_odds,
                                                 -cfg.range_max_log_odds)
        self.visited[ii, jj] += 1
        self._blocked = None

    def mark_path(self, a, b) -> None:
        """Footprints every half cell along the straight drive from ``a`` to ``b`` (world m)."""
        a, b = np.asarray(a, float)[:2], np.asarray(b, float)[:2]
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / (0.5 * self.resolution))))
        for t in np.linspace(0.0, 1.0, n + 1):
            self.mark_free(a + t * (b - a))

    def mark_contact(self, pose, heading: float, why: str = "bump") -> np.ndarray:
        """A contact while moving along ``heading`` (rad, world frame) at ``pose`` (x, y[, yaw]):
        marks the obstacle face ahead; returns its centre (world m). ``why``: "stall" and "slip" (the wheels
        made no progress) weigh ``stall_log_odds``, anything else (a bumper press) ``hit_log_odds``."""
        cfg = self.config
        hit = cfg.stall_log_odds if why in ("stall", "slip") else cfg.hit_log_odds
        x, y = float(pose[0]), float(pose[1])
        u = np.array([math.cos(heading), math.sin(heading)])
        n = np.array([-u[1], u[0]])
        centre = np.array([x, y]) + u * (cfg.robot_radius_m + 0.5 * self.resolution)
        k = max(1, int(math.ceil(cfg.contact_width_m / (0.5 * self.resolution))))
        cells = {self.cell(centre + s * n) for s in np.linspace(-0.5, 0.5, k + 1) * cfg.contact_width_m}
        for ij in cells:
            if self.inside(ij):
                self.log_odds[ij] = min(self.log_odds[ij] + hit, cfg.max_log_odds)
        self.contacts.append((float(centre[0]), float(centre[1]), why))
        self._blocked = None
        return centre

    def mark_rays(self, starts, ends, hit) -> None:
        """Range rays (world m, ``robot.ranging.ray_ends``): each lowers the range layer in the cells it crossed
        from ``starts`` to ``ends`` and, where ``hit``, raises the cell of its end (the surface it saw); a return
        within ``range_sure_m`` makes its cell an obstacle at once."""
        cfg = self.config
        starts, ends = np.asarray(starts, float).reshape(-1, 2), np.asarray(ends, float).reshape(-1, 2)
        hit = np.asarray(hit, bool).reshape(-1)
        if not len(starts):
            return
        n = int(math.ceil(float(np.max(np.linalg.norm(ends - starts, axis=1))) / (0.5 * self.resolution))) + 1
        t = np.linspace(0.0, 1.0, n + 1)[None, :, None]
        ij = np.floor((starts[:, None] + t * (ends - starts)[:, None] - self._anchor) / self.resolution).astype(int) \
            - self.offset
        end_ij = ij[:, -1]
        ok = ((ij >= 0) & (ij < self.n)).all(axis=-1)
        # a ray's own end cell is not crossed when it saw a surface there
        ok &= ~(hit[:, None] & (ij == end_ij[:, None]).all(axis=-1))
        free = np.unique(ij[ok, 0] * self.n + ij[ok, 1])
        inside = ((end_ij >= 0) & (end_ij < self.n)).all(axis=-1)
        near = np.linalg.norm(ends - starts, axis=1) <= cfg.range_sure_m
        hit_idx = np.unique(end_ij[hit & inside, 0] * self.n + end_ij[hit & inside, 1])
        sure_idx = np.unique(end_ij[hit & inside & near, 0] * self.n + end_ij[hit & inside & near, 1])
        free = np.setdiff1d(free, hit_idx, assume_unique=True)
        lo = self.range_log_odds.reshape(-1)           # a view: updates land in the grid
        lo[free] = np.maximum(lo[free] + cfg.range_free_log_odds, -cfg.range_max_log_odds)
        lo[hit_idx] = np.minimum(lo[hit_idx] + cfg.range_hit_log_odds, cfg.range_max_log_odds)
        lo[sure_idx] = np.maximum(lo[sure_idx], cfg.occupied_log_odds)
        self._blocked = None

    def forget(self) -> int:
        """Clearing recovery (as ROS navigation's costmap reset when no plan exists): take one contact's worth of
        evidence (``hit_log_odds``) off every obstacle cell, so that cells marked by a single contact become
        unknown again and cells confirmed by repeated contacts stay. Touch is an unsure sensor in rubble: a
        contact is placed by drifting odometry (measured 0.1-0.3 m after 100 s of bumping in dense_pump) and
        a stall can be a wheel on debris, not an obstacle; a ring of such marks closes the robot in for good.
        Range returns are kept: rays clear their own mistakes as the robot moves. Returns how many cells stopped
        being obstacles."""
        cfg = self.config
        before = self.occupied
        pos = self.log_odds > 0
        self.log_odds[pos] = np.maximum(self.log_odds[pos] - cfg.hit_log_odds, 0.0)
        self._blocked = None
        return int(np.count_nonzero(before & ~self.occupied))

    # -- reading --------------------------------------------------------------------------
    @property
    def occupied(self) -> np.ndarray:
        occ = self.config.occupied_log_odds
        return (self.log_odds >= occ) | (self.range_log_odds >= occ)

    @property
    def blocked(self) -> np.ndarray:
        """Cells where the robot centre cannot be: occupied cells grown by the robot radius."""
        if self._blocked is None:
            occ = self.occupied
            if occ.any():
                # An obstacle may fill its cell up to the edge: grow by half a cell more than the radius.
                reach = self.config.robot_radius_m + 0.5 * self.resolution
                self._blocked = ndimage.distance_transform_edt(~occ) * self.resolution < reach
            else:
                self._blocked = np.zeros_like(occ)
        return self._blocked

    def obstacle_points(self) -> np.ndarray:
        """World (x, y) of the occupied cells' centres, (k, 2)."""
        return self.centre(np.argwhere(self.occupied))
