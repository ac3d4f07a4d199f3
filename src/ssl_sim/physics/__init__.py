"""MuJoCo physics of the rescue testbed: the omni robot with the cube array, rubble scenes.

- ``robot_model``: the robot as an ``MjSpec`` (``RobotModelConfig``, ``add_robot``, ``robot_spec``)
- ``scene_gen``:   seeded rubble generator -> ``ssl_sim.world.World`` (``RubbleConfig``, ``generate_world``)
- ``world_mjcf``:  ``World`` -> MuJoCo scene (``world_spec``, ``world_to_mjcf``)
- ``scenes``:      named scenes in ``ssl_sim/models/scenes/*.toml`` (``load_scene``, ``save_scene``)
- ``sim_robot``:   ``SimRobot`` (twist in; pose, encoders, IMU, mics, contacts out)
- ``sim_drive``:   ``robot.hal`` backends ``SimDriveBase`` and ``SimClock``
"""
from ssl_sim.physics.robot_model import DEFAULT_TIMESTEP, RobotModelConfig, add_robot, robot_spec
from ssl_sim.physics.scene_gen import PRESETS, RubbleConfig, generate_world, named_scene
from ssl_sim.physics.scenes import load_scene, save_scene, scene_names, world_to_toml
from ssl_sim.physics.sim_drive import SimClock, SimDriveBase
from ssl_sim.physics.sim_robot import Contact, Imu, PhysicsError, Pose, SimRobot
from ssl_sim.physics.world_mjcf import world_spec, world_to_mjcf

__all__ = [
    "DEFAULT_TIMESTEP", "RobotModelConfig", "add_robot", "robot_spec",
    "PRESETS", "RubbleConfig", "generate_world", "named_scene",
    "load_scene", "save_scene", "scene_names", "world_to_toml",
    "SimClock", "SimDriveBase",
    "Contact", "Imu", "PhysicsError", "Pose", "SimRobot",
    "world_spec", "world_to_mjcf",
]
