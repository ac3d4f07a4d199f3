"""Baseline policies for ``SSLRescue-v0``: observations in, normalised actions out.

- :class:`RandomPolicy`: uniform random actions (seeded).
- :class:`MapPlanningPolicy`: the rescue behaviour's decision code as a policy: every step's detections
  go into a ``robot.sound_map.SoundMap`` at the dead-reckoned pose, bumps into a
  ``robot.occupancy.OccupancyGrid``, and ``robot.options.choose`` picks what is worth most (approach a source,
  explore, listen) with ``robot.planner.Planner``'s path, as ``robot.rescue.RescueBehaviour`` does; the action is
  a twist toward the path's next waypoint. Not used from the behaviour: its listen/act timing and motion
  primitives (the environment steps the robot) and its found model (the environment declares victims found, and
  the approached source is then marked found in the map). The observation carries no voice evidence, so every
  source stays unclassified (P(victim) 0.5).

A policy is a callable ``policy(obs) -> action`` with ``reset()`` at episode start.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from robot.coverage import ListeningCoverage
from robot.motion import MotionConfig
from robot.mount import ArrayMount
from robot.occupancy import OccupancyConfig, OccupancyGrid
from robot.odometry import wrap_angle
from robot.found import FoundModel
from robot.options import OptionKind, OptionsConfig, Timing, choose
from robot.planner import Planner, PlannerConfig
from robot.pursuit import PursuitConfig, Pursuits
from robot.sound_map import SoundMap, SoundMapConfig, SourceClass, SourceState
from ssl_core.grid import direction_from_angles
from ssl_sim.envs.config import EnvConfig
from ssl_sim.envs.rescue_env import LEVEL_CEIL_DB, LEVEL_FLOOR_DB
from ssl_sim.physics.robot_model import RobotModelConfig


class RandomPolicy:
    """Uniformly random actions from ``action_space``, seeded."""

    def __init__(self, action_space: spaces.Box, seed: int | None = None) -> None:
        self.action_space = action_space
        self._seed = seed
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self.action_space.seed(self._seed if seed is None else seed)

    def __call__(self, obs) -> np.ndarray:
        return self.action_space.sample()


@dataclass(frozen=True)
class Heard:
    """A detection decoded from the observation: azimuth, elevation (rad, array frame), level (dB)."""

    azimuth: float
    elevation: float
    power: float
    level_db: float


def compose(pose, delta) -> np.ndarray:
    """Pose ``(x, y, yaw)`` moved by ``delta = (dx, dy, dyaw)`` given in its own body frame."""
    x, y, yaw = (float(v) for v in pose)
    dx, dy, dyaw = (float(v) for v in delta)
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([x + c * dx - s * dy, y + s * dx + c * dy, float(wrap_angle(yaw + dyaw))])


def decode_detections(obs) -> list[Heard]:
    """The valid rows of ``obs["detections"]``, strongest (by SRP power) first."""
    out = []
    for row, valid in zip(obs["detections"], obs["detection_mask"]):
        if valid:
            c, s, se, p, lvl = (float(v) for v in row)
            out.append(Heard(math.atan2(s, c), math.asin(max(-1.0, min(1.0, se))), p,
                             LEVEL_FLOOR_DB + lvl * (LEVEL_CEIL_DB - LEVEL_FLOOR_DB)))
    return out


class MapPlanningPolicy:
    """The rescue behaviour's map + planner per environment step (see the module docstring).

    Frames: the policy's own odometry frame (dead-reckoned from ``obs["odometry"]``, origin at the episode
    start); detections in the array frame. Bumper: the contact is mapped ahead of the last motion and the
    robot backs away from it; the next steps plan around it."""

    def __init__(self, env_config: EnvConfig = EnvConfig(), motion: MotionConfig = MotionConfig(),
                 sound_map: SoundMapConfig = SoundMapConfig(),
                 planner: PlannerConfig = PlannerConfig(),
                 occupancy: OccupancyConfig = OccupancyConfig()) -> None:
        self.env_config, self.motion_config, self.planner_config = env_config, motion, planner
        self.sound_map_config = sound_map
        self.mount = ArrayMount(height_m=RobotModelConfig().array_height)   # the simulated robot's cube
        self.occupancy_config = occupancy
        self.options = OptionsConfig(victims_per_m2=float(FoundModel.load().provenance.get("victims_per_m2", 0.05)))
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self.pose = np.zeros(3)
        self.time = 0.0
        self.map = SoundMap(self.sound_map_config, self.mount)
        self.grid = OccupancyGrid(self.occupancy_config)
        self.coverage = ListeningCoverage(self.grid.origin, self.grid.n, self.grid.resolution)
        self.planner = Planner(self.planner_config)
        self.pursuits = Pursuits(PursuitConfig(), FoundModel.load().provenance.get("confirm_probability", 0.3))
        self.target: int | None = None
        self.heading = 0.0            # world direction of the last commanded motion (rad)

    def __call__(self, obs) -> np.ndarray:
        env = self.env_config
        self.pose = compose(self.pose, obs["odometry"])
        self.time += env.control_s + env.settle_s + env.listen_s
        if obs["found"][0] and self.target is not None:
            self.map.set_state(self.target, SourceState.FOUND, self.time)
            self.target = None
        if obs["bumper"][0]:
            self.grid.mark_contact(self.pose, self.heading, "bump")
            return self._twist(self.heading + math.pi, 0.6)
        self.grid.mark_free(self.pose[:2])
        evidence = [_Evidence(direction_from_angles(h.azimuth, h.elevation), self.time, h.level_db)
                    for h in decode_detections(obs)]
        self.map.update(evidence, self.pose, self.time)
        machines = [s.position[:2] for s in self.map.sources if s.cls is SourceClass.INTERFERER]
        self.coverage.listened(self.pose[:2], machines)
        cycle = env.control_s + env.settle_s + env.listen_s
        timing = Timing(self.motion_config.drive_speed, cycle, self.motion_config.drive_speed * env.control_s,
                        self.pursuits.config.confirm_probability, math.radians(self.sound_map_config.bearing_sigma_deg))
        option = choose(self.map.sources, self.pursuits, self.planner, self.grid, self.coverage, self.pose, self.time,
                        timing, self.options, self.target)
        plan = option.plan
        if option.kind in (OptionKind.APPROACH, OptionKind.TRIANGULATE):   # pursuing that source
            self.target = option.source.id
            self.map.set_state(option.source.id, SourceState.APPROACHING)
        if plan is None:
            return np.zeros(3, np.float32)
        goal = plan.waypoints[0]
        dx, dy = goal[0] - self.pose[0], goal[1] - self.pose[1]
        dist = math.hypot(dx, dy)
        speed = min(1.0, dist / (env.control_s * self.motion_config.drive_speed + 1e-9))
        return self._twist(math.atan2(dy, dx), speed)

    def _twist(self, heading_world: float, fraction: float) -> np.ndarray:
        """Translate along a world heading at ``fraction`` of the behaviour's drive speed, not turning."""
        self.heading = heading_world
        rel = heading_world - float(self.pose[2])
        v = fraction * self.motion_config.drive_speed / self.env_config.max_speed
        return np.clip(np.array([v * math.cos(rel), v * math.sin(rel), 0.0]), -1.0, 1.0).astype(np.float32)


@dataclass(frozen=True)
class _Evidence:
    """One decoded detection as sound-map evidence: no voice in the observation (P 0.5, log-odds 0)."""

    direction: np.ndarray
    time: float
    level_db: float
    track_id: int | None = None
    voice_probability: float = 0.5
    activity: float = 1.0
