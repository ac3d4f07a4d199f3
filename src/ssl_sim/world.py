"""One description of a rescue world, shared by physics (MuJoCo) and acoustics
(pyroomacoustics), so both always simulate the same geometry.

World frame: right-handed, metres, +z up; the room spans ``[0, Lx] x [0, Ly] x [0, Lz]``
and the floor is z = 0. Yaw angles are radians about +z.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from typing import Any

import numpy as np

OBSTACLE_KINDS = ("block", "slab", "wall", "pillar", "debris")


def _vec(name: str, value: Any, n: int) -> tuple[float, ...]:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (n,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}: expected {n} finite numbers, got {value!r}")
    return tuple(float(v) for v in arr)


def _from_mapping(cls, data: dict, where: str):
    known = {f.name for f in fields(cls)}
    unknown = set(data) - known
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {sorted(unknown)}; expected some of {sorted(known)}")
    return cls(**data)


@dataclass(frozen=True)
class Box:
    """An obstacle: a box of full ``size`` (m) centred at ``center`` (world, m), turned by ``yaw`` (rad)."""

    center: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw: float = 0.0
    material: str = "concrete"
    kind: str = "block"
    #: Small debris (top below ~2 cm) that the robot is meant to drive over.
    climbable: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _vec("box.center", self.center, 3))
        object.__setattr__(self, "size", _vec("box.size", self.size, 3))
        if min(self.size) <= 0:
            raise ValueError(f"box.size: all extents must be > 0 m, got {self.size}")
        if self.kind not in OBSTACLE_KINDS:
            raise ValueError(f"box.kind: expected one of {OBSTACLE_KINDS}, got {self.kind!r}")

    @property
    def rotation(self) -> np.ndarray:
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def corners(self) -> np.ndarray:
        """The 8 corners in world coordinates, shape (8, 3)."""
        h = np.asarray(self.size) / 2
        signs = np.array([[sx, sy, sz] for sz in (-1, 1) for sy in (-1, 1) for sx in (-1, 1)], float)
        return (signs * h) @ self.rotation.T + np.asarray(self.center)

    def contains(self, points, margin: float = 0.0) -> np.ndarray:
        """Whether world points ``(..., 3)`` lie inside the box grown by ``margin`` (m)."""
        p = (np.asarray(points, float) - np.asarray(self.center)) @ self.rotation
        return np.all(np.abs(p) <= np.asarray(self.size) / 2 + margin, axis=-1)


@dataclass(frozen=True)
class Room:
    """A shoebox enclosure ``[0, Lx] x [0, Ly] x [0, Lz]`` (m) with surface materials.

    ``wall_open_fraction``: share of the wall area that is open (doorways, broken windows, holes):
    acoustically fully absorbing, spread evenly over the walls (the walls' absorption becomes
    ``f + (1 - f) alpha``); the robot still cannot leave through them."""

    size: tuple[float, float, float] = (6.0, 5.0, 3.0)
    wall_material: str = "brickwork"
    floor_material: str = "concrete_floor"
    ceiling_material: str = "plasterboard"
    wall_open_fraction: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "size", _vec("room.size", self.size, 3))
        if min(self.size) <= 0:
            raise ValueError(f"room.size: all extents must be > 0 m, got {self.size}")
        f = self.wall_open_fraction
        if isinstance(f, bool) or not isinstance(f, (int, float)) or not 0.0 <= f <= 0.9:
            raise ValueError(f"room.wall_open_fraction: expected a fraction in [0, 0.9], got {f!r}")

    def contains(self, points, margin: float = 0.0) -> np.ndarray:
        p = np.asarray(points, float)
        return np.all((p >= margin) & (p <= np.asarray(self.size) - margin), axis=-1)


@dataclass(frozen=True)
class VictimSite:
    """Where a victim lies: mouth position (world, m) and how buried it is (0 free .. 1 fully covered)."""

    position: tuple[float, float, float]
    buried: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _vec("victim.position", self.position, 3))
        if not 0.0 <= self.buried <= 1.0:
            raise ValueError(f"victim.buried: expected a fraction in [0, 1], got {self.buried}")


@dataclass(frozen=True)
class World:
    """Room + obstacles + victim sites + robot start pose ``(x, y, yaw)`` (world, m and rad)."""

    room: Room = field(default_factory=Room)
    obstacles: tuple[Box, ...] = ()
    victims: tuple[VictimSite, ...] = ()
    robot_start: tuple[float, float, float] = (1.0, 1.0, 0.0)
    name: str = "world"
    seed: int | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "obstacles", tuple(self.obstacles))
        object.__setattr__(self, "victims", tuple(self.victims))
        object.__setattr__(self, "robot_start", _vec("robot_start", self.robot_start, 3))

    def inside_obstacle(self, point, margin: float = 0.0, include_climbable: bool = False) -> int | None:
        """Index of the first (non-climbable) obstacle containing ``point``, else None."""
        for i, b in enumerate(self.obstacles):
            if (include_climbable or not b.climbable) and b.contains(point, margin):
                return i
        return None

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, data: dict) -> "World":
        data = dict(data)
        room = _from_mapping(Room, data.pop("room", {}), "world.room")
        obstacles = tuple(_from_mapping(Box, b, f"world.obstacles[{i}]") for i, b in enumerate(data.pop("obstacles", [])))
        victims = tuple(_from_mapping(VictimSite, v, f"world.victims[{i}]") for i, v in enumerate(data.pop("victims", [])))
        return _from_mapping(cls, {**data, "room": room, "obstacles": obstacles, "victims": victims}, "world")
