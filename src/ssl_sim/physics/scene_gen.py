"""Seeded generator of rubble scenes, output as a ``ssl_sim.world.World``.

The World is the single description of the scene: ``world_mjcf.world_spec`` turns it
into the MuJoCo scene and the acoustic simulator reads the same boxes. All numbers
are rounded to 1 mm (0.1 mrad for yaw) so a scene survives a TOML round trip exactly.

What a scene holds (world frame, metres, floor z = 0):
- full-height partitions across the room with doorways (compartments the robot enters through them),
- pillars (full height) and broken interior wall segments,
- big debris the robot must go around: concrete slabs lying flat and blocks, some
  stacked on others, and "voids" (a slab resting on two blocks) a victim can lie under,
- small debris the robot can drive over (``climbable``, top <= ``debris_height[1]``),
- victims on top of rubble, beside it, or partly under it (in a void),
- the robot start pose on free, flat floor from which every victim is reachable
  (checked on an occupancy grid inflated by the robot radius).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import ndimage

from ssl_sim.physics.robot_model import RobotModelConfig
from ssl_sim.world import Box, Room, VictimSite, World

Range = tuple[float, float]

#: Robot footprint radius used for free-space checks (bumper radius, m) and the height
#: below which an obstacle blocks it (top of the cube array, m).
ROBOT_RADIUS = RobotModelConfig().bumper_radius
ROBOT_HEIGHT = RobotModelConfig().array_height + RobotModelConfig().cube_edge / 2


@dataclass(frozen=True)
class RubbleConfig:
    """Parameters of the generator (m, fractions of the floor area)."""

    room_size: tuple[float, float, float] = (6.0, 5.0, 3.0)
    # The damaged room's surfaces (pyroomacoustics database names): brick walls with a share of their area
    # open (blown-out windows, doorways), a floor covered in loose debris, a plasterboard ceiling. The 15 %
    # open is our assumption; with it the light-rubble room's Eyring RT60 is 0.67 s at 1 kHz (3.6 s closed).
    wall_material: str = "brickwork"
    floor_material: str = "rubble"
    ceiling_material: str = "plasterboard"
    wall_open_fraction: float = 0.15
    block_coverage: float = 0.10          # floor fraction under big debris footprints (slabs, blocks, voids)
    debris_coverage: float = 0.03         # floor fraction under small climbable debris
    block_size: tuple[Range, Range, Range] = ((0.15, 0.5), (0.15, 0.45), (0.12, 0.45))
    slab_size: tuple[Range, Range, Range] = ((0.5, 1.3), (0.4, 0.9), (0.08, 0.18))
    debris_size: tuple[Range, Range] = ((0.06, 0.3), (0.05, 0.2))   # footprint length, width
    debris_height: Range = (0.005, 0.02)  # climbable: top at most 2 cm
    n_partitions: int = 0                  # full-height walls across the room (parallel), each with a doorway
    doorway_width: Range = (0.8, 1.2)
    n_walls: int = 0                       # broken interior wall segments
    wall_length: Range = (0.8, 2.2)
    wall_height: Range = (0.4, 1.6)
    n_pillars: int = 0
    n_voids: int = 0                       # slab resting on two blocks, open space beneath
    stack_fraction: float = 0.25           # share of blocks stacked on other debris
    n_victims: int = 1
    victim_modes: tuple[str, ...] = ("on", "beside", "under")
    start_clearance: float = 0.25          # m of free floor around the robot's bumper at the start
    victim_reach: float = 0.8              # m: the robot must be able to get this close to each victim
    grid: float = 0.05                     # m, occupancy grid for the reachability check
    max_attempts: int = 40

    @property
    def room(self) -> Room:
        return Room(size=self.room_size, wall_material=self.wall_material, floor_material=self.floor_material,
                    ceiling_material=self.ceiling_material, wall_open_fraction=self.wall_open_fraction)

    def __post_init__(self) -> None:
        _ = self.room  # validates the room fields
        for name in ("block_coverage", "debris_coverage", "stack_fraction"):
            v = getattr(self, name)
            if not 0.0 <= v < 0.6:
                raise ValueError(f"rubble.{name}: expected a fraction in [0, 0.6), got {v}")
        for name in ("n_partitions", "n_walls", "n_pillars", "n_voids", "n_victims"):
            if getattr(self, name) < 0:
                raise ValueError(f"rubble.{name}: expected >= 0, got {getattr(self, name)}")
        lo, hi = self.debris_height
        if not 0 < lo <= hi <= 0.03:
            raise ValueError(f"rubble.debris_height: expected 0 < low <= high <= 0.03 m, got {self.debris_height}")
        bad = set(self.victim_modes) - {"on", "beside", "under"}
        if bad or not self.victim_modes:
            raise ValueError("rubble.victim_modes: expected some of ('on', 'beside', 'under'), "
                             f"got {self.victim_modes}")
        lo, hi = self.doorway_width
        if not 2 * ROBOT_RADIUS + 0.2 <= lo <= hi:
            raise ValueError(f"rubble.doorway_width: expected {2 * ROBOT_RADIUS + 0.2:.2f} m <= low <= high "
                             f"(the robot must pass), got {self.doorway_width}")
        if min(self.room_size[:2]) < 2 * (ROBOT_RADIUS + self.start_clearance) + 0.2:
            raise ValueError(f"rubble.room_size: room too small for the robot, got {self.room_size}")


#: Generator presets behind the named scenes.
PRESETS: dict[str, RubbleConfig] = {
    "light_rubble": RubbleConfig(room_size=(6.0, 5.0, 3.0), block_coverage=0.06, debris_coverage=0.03,
                                 n_pillars=1, n_walls=0, n_voids=0, n_victims=1, victim_modes=("beside", "on")),
    "dense_collapsed_room": RubbleConfig(room_size=(7.0, 6.0, 2.8), block_coverage=0.2, debris_coverage=0.06,
                                         n_pillars=2, n_walls=2, n_voids=2, n_victims=3, stack_fraction=0.35),
}


def _r(x) -> float:
    return float(np.round(x, 3))


def _rot2(yaw: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    return np.array([[c, -s], [s, c]])


def _uniform(rng: np.random.Generator, rng_range: Range) -> float:
    return float(rng.uniform(*rng_range))


class _Builder:
    def __init__(self, cfg: RubbleConfig, rng: np.random.Generator) -> None:
        self.cfg, self.rng = cfg, rng
        self.L = np.asarray(cfg.room_size, float)
        self.boxes: list[Box] = []
        self._fp_n = 0   # number of boxes the footprint arrays below describe (boxes are only ever appended)
        self._fp_xy = np.zeros((0, 2))
        self._fp_r = np.zeros(0)

    # -- placement helpers ---------------------------------------------------------------
    def box(self, xy, bottom: float, size, yaw, material, kind, climbable=False) -> Box:
        """Add a box of ``size`` standing on height ``bottom`` (m). Sizes are rounded to 1 mm and
        centres to 0.1 mm, so the bottom stays exactly at ``bottom`` after rounding."""
        size = tuple(max(_r(s), 0.001) for s in size)
        center = (round(float(xy[0]), 4), round(float(xy[1]), 4), round(bottom + size[2] / 2, 4))
        b = Box(center=center, size=size, yaw=float(np.round(yaw, 4)), material=material, kind=kind,
                climbable=climbable)
        self.boxes.append(b)
        return b

    def xy_inside(self, half_extent: float, margin: float = 0.05) -> np.ndarray:
        lo = half_extent + margin
        return self.rng.uniform([lo, lo], self.L[:2] - lo)

    def footprint_radius(self, size) -> float:
        return float(np.hypot(size[0], size[1]) / 2)

    def overlaps(self, xy, size, yaw: float, clearance: float = 0.0, kinds=None) -> bool:
        """Whether the footprint rectangle (``size`` x, y at ``xy``, turned by ``yaw``) grown by
        ``clearance`` overlaps the footprint of any box of the given kinds (separating axes)."""
        ha = np.asarray(size[:2], float) / 2 + clearance
        ra = _rot2(yaw)
        if self._fp_n != len(self.boxes):
            new = self.boxes[self._fp_n:]
            self._fp_xy = np.concatenate([self._fp_xy, np.array([b.center[:2] for b in new], float).reshape(-1, 2)])
            self._fp_r = np.concatenate([self._fp_r, [np.hypot(b.size[0], b.size[1]) / 2 for b in new]])
            self._fp_n = len(self.boxes)
        # Footprints whose bounding circles lie apart (1 um slack) cannot overlap: only the others get the
        # exact separating-axis test (the same decisions, a fraction of the work in crowded rooms).
        near = np.hypot(*(self._fp_xy - np.asarray(xy, float)).T) <= self._fp_r + float(np.hypot(*ha)) + 1e-6
        for k in np.flatnonzero(near):
            b = self.boxes[k]
            if kinds is not None and b.kind not in kinds:
                continue
            hb = np.asarray(b.size[:2]) / 2
            rb = _rot2(b.yaw)
            t = np.asarray(b.center[:2]) - np.asarray(xy, float)
            separated = False
            for axis in (*ra.T, *rb.T):
                if abs(t @ axis) > np.abs(ra.T @ axis) @ ha + np.abs(rb.T @ axis) @ hb:
                    separated = True
                    break
            if not separated:
                return True
        return False

    def floor_coverage(self, climbable: bool) -> float:
        area = sum(b.size[0] * b.size[1] for b in self.boxes
                   if b.climbable == climbable and b.center[2] - b.size[2] / 2 < 1e-6 and b.kind != "wall"
                   and b.kind != "pillar")
        return area / (self.L[0] * self.L[1])

    # -- scene elements --------------------------------------------------------------------
    def _place(self, size, yaw: float, clearance: float, margin: float) -> np.ndarray | None:
        """A random free spot (no overlap with anything placed so far) for a footprint, or None."""
        for _ in range(60):
            xy = self.xy_inside(self.footprint_radius(size), margin=margin)
            if not self.overlaps(xy, size, yaw, clearance):
                return xy
        return None

    def partitions(self) -> bool:
        """Full-height walls across the room, parallel to its shorter side, each with one doorway
        (``doorway_width``, anywhere along it, also at an end); compartments at least 1.6 m deep."""
        n = self.cfg.n_partitions
        if n == 0:
            return True
        axis = 0 if self.L[0] >= self.L[1] else 1       # the walls stand at x = const when the room is long in x
        length, span = self.L[1 - axis], self.L[axis]
        thick = 0.12
        min_depth = 1.6
        if span < (n + 1) * min_depth + n * thick:
            return False
        # positions along the long axis: every compartment min_depth deep plus a random share of the spare depth
        slack = span - (n + 1) * min_depth - n * thick
        cuts = np.sort(self.rng.uniform(0.0, slack, n))
        pos = [min_depth * (k + 1) + thick * k + thick / 2 + cuts[k] for k in range(n)]
        for p in pos:
            door = _uniform(self.rng, self.cfg.doorway_width)
            d0 = float(self.rng.uniform(0.0, length - door))
            for a, b in ((0.0, d0), (d0 + door, length)):
                if b - a < 0.05:
                    continue                             # the doorway reaches this end wall
                mid = (a + b) / 2
                xy = (p, mid) if axis == 0 else (mid, p)
                size = (thick, b - a, self.L[2]) if axis == 0 else (b - a, thick, self.L[2])
                self.box(xy, 0.0, size, 0.0, "brickwork", "wall")
        return True

    def pillars(self) -> bool:
        for _ in range(self.cfg.n_pillars):
            s = _uniform(self.rng, (0.25, 0.4))
            xy = self._place((s, s), 0.0, clearance=0.5, margin=0.5)
            if xy is None:
                return False
            self.box(xy, 0.0, (s, s, self.L[2]), 0.0, "unpainted_concrete", "pillar")
        return True

    def walls(self) -> bool:
        """Broken interior walls: roughly axis-aligned, partial height."""
        for _ in range(self.cfg.n_walls):
            length = _uniform(self.rng, self.cfg.wall_length)
            height = _uniform(self.rng, self.cfg.wall_height)
            thick = _uniform(self.rng, (0.1, 0.2))
            yaw = float(self.rng.choice([0.0, np.pi / 2]) + self.rng.normal(0, 0.08))
            xy = self._place((length, thick), yaw, clearance=0.45, margin=0.35)
            if xy is None:
                return False
            self.box(xy, 0.0, (length, thick, height), yaw, "brickwork", "wall")
        return True

    def voids(self) -> bool:
        """A slab bridging two blocks: free space under it (height ``h``) where a victim can lie."""
        for _ in range(self.cfg.n_voids):
            span = _uniform(self.rng, (0.9, 1.3))
            depth = _uniform(self.rng, (0.6, 0.9))
            h = _uniform(self.rng, (0.3, 0.45))
            t = _uniform(self.rng, (0.08, 0.14))
            yaw = float(self.rng.uniform(-np.pi, np.pi))
            xy = self._place((span, depth), yaw, clearance=0.4, margin=0.3)
            if xy is None:
                return False
            ex = _rot2(yaw)[:, 0]
            leg = 0.2
            for side in (-1, 1):
                self.box(xy + side * ex * (span / 2 - leg / 2), 0.0, (leg, depth, h), yaw, "rough_concrete", "block")
            self.box(xy, _r(h), (span, depth, t), yaw, "rough_concrete", "slab")
        return True

    def slabs_and_blocks(self) -> None:
        cfg, rng = self.cfg, self.rng
        for _ in range(400):
            if self.floor_coverage(False) >= cfg.block_coverage:
                break
            if rng.random() < 0.35:
                size = [_uniform(rng, r) for r in cfg.slab_size]
                kind = "slab"
            else:
                size = [_uniform(rng, r) for r in cfg.block_size]
                kind = "block"
            yaw = float(rng.uniform(-np.pi, np.pi))
            material = "rough_concrete" if kind == "slab" else str(rng.choice(["rough_concrete", "brickwork"]))
            supports = [b for b in self.boxes if b.kind in ("slab", "block") and b.center[2] + b.size[2] / 2 < 0.9]
            if kind == "block" and supports and rng.random() < cfg.stack_fraction:
                sup = supports[int(rng.integers(len(supports)))]
                hx, hy = np.asarray(sup.size[:2]) / 2 - min(size[:2]) / 2
                if hx > 0 and hy > 0:
                    local = rng.uniform([-hx, -hy], [hx, hy])
                    xy = np.asarray(sup.center[:2]) + sup.rotation[:2, :2] @ local
                    top = sup.center[2] + sup.size[2] / 2
                    self.box(xy, top, size, yaw, material, kind)
                    continue
            xy = self.xy_inside(self.footprint_radius(size))
            if self.overlaps(xy, size, yaw, 0.05, kinds=("pillar", "wall")):
                continue
            self.box(xy, 0.0, size, yaw, material, kind)

    def debris(self) -> None:
        cfg, rng = self.cfg, self.rng
        for _ in range(2000):
            if self.floor_coverage(True) >= cfg.debris_coverage:
                break
            size = [_uniform(rng, cfg.debris_size[0]), _uniform(rng, cfg.debris_size[1]),
                    _uniform(rng, cfg.debris_height)]
            xy = self.xy_inside(self.footprint_radius(size))
            yaw = float(rng.uniform(-np.pi, np.pi))
            # Small debris lies on the floor, not inside or under big debris.
            if self.overlaps(xy, size, yaw, 0.02, kinds=("pillar", "wall", "slab", "block")):
                continue
            material = str(rng.choice(["rough_concrete", "brickwork", "wood_16mm"]))
            self.box(xy, 0.0, size, yaw, material, "debris", climbable=True)

    # -- victims -------------------------------------------------------------------------------
    def victim(self, world_boxes: list[Box]) -> VictimSite | None:
        """A victim on, beside or under rubble (mode drawn from ``victim_modes``); None if the draw failed."""
        rng, cfg = self.rng, self.cfg
        mode = str(rng.choice(list(cfg.victim_modes)))
        big = [b for b in world_boxes if b.kind in ("slab", "block") and not b.climbable]
        if mode == "under":
            roofs = [b for b in big if b.kind == "slab" and b.center[2] - b.size[2] / 2 > 0.2]
            if not roofs:
                mode = "beside"
            else:
                roof = roofs[int(rng.integers(len(roofs)))]
                # Lying in the void with the head near an open side: half covered.
                gap = roof.center[2] - roof.size[2] / 2
                along = rng.uniform(-0.15, 0.15)
                local = np.array([along, rng.choice([-1, 1]) * roof.size[1] / 2 * rng.uniform(0.5, 0.9)])
                xy = np.asarray(roof.center[:2]) + roof.rotation[:2, :2] @ local
                z = min(0.15, gap - 0.05)
                return VictimSite((_r(xy[0]), _r(xy[1]), _r(z)), buried=float(np.round(rng.uniform(0.4, 0.8), 2)))
        if mode == "on" and big:
            tops = [b for b in big if b.center[2] + b.size[2] / 2 < 1.0 and min(b.size[:2]) > 0.25]
            if tops:
                b = tops[int(rng.integers(len(tops)))]
                local = rng.uniform(-0.3, 0.3, 2) * (np.asarray(b.size[:2]) / 2)
                xy = np.asarray(b.center[:2]) + b.rotation[:2, :2] @ local
                z = b.center[2] + b.size[2] / 2 + 0.12
                if any(o.contains([xy[0], xy[1], o.center[2]]) and o.center[2] - o.size[2] / 2 > z - 0.15
                       for o in world_boxes if not o.climbable):
                    return None  # something lies on top of this block: not in the open
                return VictimSite((_r(xy[0]), _r(xy[1]), _r(z)), buried=0.0)
        # beside: on the floor next to a piece of rubble (or anywhere if there is none), not under any
        if big:
            b = big[int(rng.integers(len(big)))]
            ang = rng.uniform(-np.pi, np.pi)
            d = self.footprint_radius(b.size) + rng.uniform(0.12, 0.3)
            xy = np.asarray(b.center[:2]) + d * np.array([np.cos(ang), np.sin(ang)])
        else:
            xy = self.xy_inside(0.3)
        z = rng.uniform(0.12, 0.25)
        if any(o.contains([xy[0], xy[1], o.center[2]]) for o in world_boxes if not o.climbable):
            return None
        return VictimSite((_r(xy[0]), _r(xy[1]), _r(z)), buried=float(np.round(rng.uniform(0.0, 0.2), 2)))


def blocking_obstacles(world: World) -> list[Box]:
    """Obstacles the robot cannot drive over or under (not climbable, bottom below its top)."""
    return [b for b in world.obstacles if not b.climbable and b.center[2] - b.size[2] / 2 < ROBOT_HEIGHT]


def free_space_grid(world: World, inflate: float = ROBOT_RADIUS, res: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """Cells where the robot centre can be: ``(free (nx, ny) bool, cell centres (nx, ny, 2))``.

    Blocking obstacles and the room walls grown by ``inflate`` (m) are not free."""
    Lx, Ly, _ = world.room.size
    xs = np.arange(res / 2, Lx, res)
    ys = np.arange(res / 2, Ly, res)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    occ = np.zeros(X.shape, bool)
    for b in blocking_obstacles(world):
        # only the cells around the box's plan-view bounding box (2 cells of slack) can be inside it
        c = b.corners()
        i0, j0 = (np.floor(c[:, :2].min(0) / res).astype(int) - 2).clip(0)
        i1, j1 = np.ceil(c[:, :2].max(0) / res).astype(int) + 3
        sx, sy = X[i0:i1, j0:j1], Y[i0:i1, j0:j1]
        pts = np.stack([sx, sy, np.full_like(sx, b.center[2])], axis=-1)
        occ[i0:i1, j0:j1] |= b.contains(pts)
    free = ndimage.distance_transform_edt(~occ) * res > inflate
    free &= (X > inflate) & (X < Lx - inflate) & (Y > inflate) & (Y < Ly - inflate)
    return free, np.stack([X, Y], axis=-1)


def reachable_victims(world: World, reach: float = 0.8, res: float = 0.05) -> np.ndarray:
    """For each victim: can the robot drive from its start to within ``reach`` m (horizontal) of it?"""
    free, centres = free_space_grid(world, res=res)
    labels, _ = ndimage.label(free)
    x0, y0, _ = world.robot_start
    i, j = int(x0 // res), int(y0 // res)
    if not (0 <= i < free.shape[0] and 0 <= j < free.shape[1]) or not free[i, j]:
        return np.zeros(len(world.victims), bool)
    mine = labels == labels[i, j]
    out = []
    for v in world.victims:
        d = np.hypot(centres[..., 0] - v.position[0], centres[..., 1] - v.position[1])
        out.append(bool(np.any(mine & (d <= reach))))
    return np.asarray(out, bool)


def _start_pose(builder: _Builder, world: World) -> tuple[float, float, float] | None:
    """Random start on free flat floor: no blocking obstacle within bumper + clearance, no debris under it."""
    cfg, rng = builder.cfg, builder.rng
    free, centres = free_space_grid(world, inflate=ROBOT_RADIUS + cfg.start_clearance, res=cfg.grid)
    debris = [b for b in world.obstacles if b.climbable]
    cand = centres[free]
    if debris and len(cand):
        keep = np.ones(len(cand), bool)
        for b in debris:
            keep &= np.hypot(*(cand - np.asarray(b.center[:2])).T) > ROBOT_RADIUS + builder.footprint_radius(b.size)
        cand = cand[keep]
    if not len(cand):
        return None
    x, y = cand[int(rng.integers(len(cand)))]
    return (_r(x), _r(y), float(np.round(rng.uniform(-np.pi, np.pi), 4)))


def generate_world(cfg: RubbleConfig = RubbleConfig(), seed: int = 0, name: str | None = None) -> World:
    """A random rubble scene; the same ``(cfg, seed)`` always gives the same World."""
    if not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed: expected a non-negative integer, got {seed!r}")
    rng = np.random.default_rng(int(seed))
    room = cfg.room
    for _ in range(cfg.max_attempts):
        b = _Builder(cfg, rng)
        if not (b.partitions() and b.pillars() and b.walls() and b.voids()):
            continue
        b.slabs_and_blocks()
        b.debris()
        victims = []
        for _ in range(cfg.n_victims):
            for _ in range(20):
                v = b.victim(b.boxes)
                if v is None:
                    continue
                p = np.asarray(v.position)
                world_try = World(room=room, obstacles=tuple(b.boxes))
                apart = all(np.linalg.norm(p[:2] - np.asarray(u.position[:2])) > 0.5 for u in victims)
                if (apart and room.contains(p, margin=0.1)
                        and world_try.inside_obstacle(p, margin=0.03, include_climbable=True) is None):
                    victims.append(v)
                    break
        world = World(room=room, obstacles=tuple(b.boxes), victims=tuple(victims),
                      name=name or f"rubble_{seed}", seed=int(seed))
        start = _start_pose(b, world)
        if start is None or len(victims) < cfg.n_victims:
            continue
        world = replace(world, robot_start=start)
        if np.all(reachable_victims(world, cfg.victim_reach, cfg.grid)):
            return world
    raise RuntimeError(f"generate_world: no valid scene after {cfg.max_attempts} attempts with seed {seed}; "
                       "lower block_coverage / counts or enlarge room_size")


#: Named scenes: generator preset and seed (``empty_lab`` is built by hand).
NAMED_SEEDS = {"light_rubble": 11, "dense_collapsed_room": 7}


def empty_lab() -> World:
    """The paper's lab set-up: an empty room, the robot in the middle facing +x, one talker
    1.5 m away at -4 degrees azimuth with the mouth at 0.3 m."""
    room = Room(size=(7.0, 6.0, 3.0), wall_material="brickwork", floor_material="concrete_floor",
                ceiling_material="plasterboard")
    start = (3.0, 3.0, 0.0)
    az = np.deg2rad(-4.0)
    victim = VictimSite((_r(start[0] + 1.5 * np.cos(az)), _r(start[1] + 1.5 * np.sin(az)), 0.3), buried=0.0)
    return World(room=room, victims=(victim,), robot_start=start, name="empty_lab")


def named_scene(name: str) -> World:
    """Build a named scene from its recipe (the shipped TOML files are these, written by ``scenes``)."""
    if name == "empty_lab":
        return empty_lab()
    if name in NAMED_SEEDS:
        return generate_world(PRESETS[name], seed=NAMED_SEEDS[name], name=name)
    raise ValueError(f"unknown named scene '{name}': expected one of {['empty_lab', *NAMED_SEEDS]}")
