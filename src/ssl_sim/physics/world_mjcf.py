"""``ssl_sim.world.World`` -> MuJoCo scene (MjSpec / MJCF text) with the robot in it.

Geom names tie the physics back to the World: obstacle ``i`` is geom ``obs{i}``, the
floor is ``floor`` and the room walls are ``room_wall_{xmin,xmax,ymin,ymax}`` (planes facing
into the room). All world geoms are static (world body or jointless tile bodies); the ceiling is
left out (the robot cannot reach it). Friction and colour come from the surface material name.
"""
from __future__ import annotations

import mujoco
import numpy as np

from ssl_sim.physics.robot_model import (DEBRIS_CONTYPE, DEFAULT_TIMESTEP, WORLD_CONAFFINITY, WORLD_CONTYPE,
                                         RobotModelConfig, add_robot, configure_options)
from ssl_sim.world import World

FLOOR_GEOM = "floor"
ROOM_WALL_PREFIX = "room_wall_"
TILE = 1.0  # m

#: material name -> (Coulomb friction, rgba). Names follow pyroomacoustics' material database.
MATERIALS: dict[str, tuple[float, tuple[float, float, float, float]]] = {
    "concrete": (0.8, (0.62, 0.62, 0.6, 1)),
    "rough_concrete": (0.9, (0.58, 0.57, 0.54, 1)),
    "unpainted_concrete": (0.8, (0.66, 0.66, 0.64, 1)),
    "concrete_floor": (0.8, (0.5, 0.5, 0.5, 1)),
    "brickwork": (0.8, (0.62, 0.33, 0.25, 1)),
    "plasterboard": (0.5, (0.9, 0.9, 0.86, 1)),
    "wood_16mm": (0.6, (0.55, 0.4, 0.25, 1)),
    "hard_surface": (0.7, (0.7, 0.7, 0.7, 1)),
    "rubble": (0.8, (0.55, 0.5, 0.44, 1)),  # debris-covered floor: friction as concrete
}
_DEFAULT_MATERIAL = (0.8, (0.6, 0.6, 0.6, 1))


def obstacle_geom(i: int) -> str:
    return f"obs{i}"


def _material(name: str) -> tuple[float, tuple[float, float, float, float]]:
    return MATERIALS.get(name, _DEFAULT_MATERIAL)


def _static_box(parent: mujoco.MjsBody, name: str, center, half, yaw: float, material: str):
    mu, rgba = _material(material)
    g = parent.add_geom(name=name, type=mujoco.mjtGeom.mjGEOM_BOX, size=list(half), pos=list(center),
                                quat=[np.cos(yaw / 2), 0, 0, np.sin(yaw / 2)], friction=[mu, 0.005, 0.0001],
                                rgba=list(rgba))
    g.contype, g.conaffinity = WORLD_CONTYPE, WORLD_CONAFFINITY
    return g


def world_spec(world: World, robot: RobotModelConfig | None = RobotModelConfig(),
               timestep: float = DEFAULT_TIMESTEP,
               robot_pose: tuple[float, float, float] | None = None) -> mujoco.MjSpec:
    """MuJoCo scene of ``world`` with the robot at ``robot_pose`` (default ``world.robot_start``).

    ``robot=None`` builds the static scene only."""
    spec = mujoco.MjSpec()
    spec.modelname = world.name
    configure_options(spec, timestep)
    Lx, Ly, Lz = world.room.size
    mu, rgba = _material(world.room.floor_material)
    floor = spec.worldbody.add_geom(name=FLOOR_GEOM, type=mujoco.mjtGeom.mjGEOM_PLANE,
                                    size=[Lx / 2, Ly / 2, 0.25],
                                    pos=[Lx / 2, Ly / 2, 0], friction=[mu, 0.005, 0.0001], rgba=list(rgba))
    floor.contype, floor.conaffinity = WORLD_CONTYPE, WORLD_CONAFFINITY
    # Room walls are planes facing into the room: an exact, cheap half-space test for every
    # robot geom (boxes this size defeat MuJoCo's bounding-sphere pre-filter).
    wmu, wrgba = _material(world.room.wall_material)
    walls = {  # name: (point on the wall, inward normal, half extents along the wall and up)
        "xmin": ((0.0, Ly / 2, Lz / 2), (1, 0, 0), (Ly / 2, Lz / 2)),
        "xmax": ((Lx, Ly / 2, Lz / 2), (-1, 0, 0), (Ly / 2, Lz / 2)),
        "ymin": ((Lx / 2, 0.0, Lz / 2), (0, 1, 0), (Lx / 2, Lz / 2)),
        "ymax": ((Lx / 2, Ly, Lz / 2), (0, -1, 0), (Lx / 2, Lz / 2)),
    }
    for side, (c, n, (h_along, h_up)) in walls.items():
        n = np.asarray(n, float)
        along = np.cross([0.0, 0.0, 1.0], n)
        rot = np.column_stack([along, [0.0, 0.0, 1.0], n])  # plane local z = inward normal
        q = np.zeros(4)
        mujoco.mju_mat2Quat(q, rot.ravel())
        g = spec.worldbody.add_geom(name=f"{ROOM_WALL_PREFIX}{side}", type=mujoco.mjtGeom.mjGEOM_PLANE,
                                    size=[h_along, h_up, 0.25], pos=list(c), quat=q,
                                    friction=[wmu, 0.005, 0.0001], rgba=[*wrgba[:3], 0.25])
        g.contype, g.conaffinity = WORLD_CONTYPE, WORLD_CONAFFINITY
    # Obstacles live in static bodies, one per TILE x TILE m floor cell: MuJoCo's broadphase then
    # pairs the robot with nearby cells only (one world body holding all boxes costs ~2.5x more
    # collision time in dense rubble, bench_physics).
    tiles: dict[tuple[int, int], mujoco.MjsBody] = {}
    for i, b in enumerate(world.obstacles):
        key = (int(b.center[0] // TILE), int(b.center[1] // TILE))
        if key not in tiles:
            tiles[key] = spec.worldbody.add_body(name=f"tile_{key[0]}_{key[1]}")
        g = _static_box(tiles[key], obstacle_geom(i), b.center, np.asarray(b.size) / 2, b.yaw, b.material)
        if b.climbable:
            g.contype = DEBRIS_CONTYPE  # tested against wheels and motors only (see robot_model)
    for k, v in enumerate(world.victims):
        spec.worldbody.add_site(name=f"victim{k}", pos=list(v.position), size=[0.05, 0, 0], rgba=[1, 0.1, 0.6, 0.8])
    light = spec.worldbody.add_light(name="ceiling_light", pos=[Lx / 2, Ly / 2, Lz], dir=[0, 0, -1])
    light.castshadow = False
    if robot is not None:
        add_robot(spec, robot, world.robot_start if robot_pose is None else robot_pose)
    return spec


def world_to_mjcf(world: World, robot: RobotModelConfig | None = RobotModelConfig(),
                  timestep: float = DEFAULT_TIMESTEP) -> str:
    """MJCF text of the scene (robot included unless ``robot=None``)."""
    return world_spec(world, robot, timestep).to_xml()
