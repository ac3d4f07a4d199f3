"""Baseline policies for ``SSLRescue-v0``: observations in, normalised actions out.

- :class:`RandomPolicy`: uniform random actions (seeded).
- :class:`LoudestSourcePolicy`: the paper's heuristic as a policy - turn toward and drive to the
  loudest detected source - with ``robot.rescue``'s parameters (``RescueConfig``: turn tolerance,
  drive and turn speeds, target keeping by ``switch_ratio_db`` and ``track_gate_deg``, silent
  listens before exploring, back off + sidestep on a bump, found victims ignored afterwards
  (``exclusion_deg`` / ``exclusion_radius_m`` gate around their remembered positions) and
  exploring away from the nearest one). ``RescueBehaviour`` itself runs on a HAL with its own
  listen/act timing and its target choice is a private method of that state machine, so the few
  rules used here are restated from it (not the voice scoring, found criteria or the
  odometry-feedback motion primitives: the environment declares victims found).

A policy is a callable ``policy(obs) -> action`` with ``reset()`` at episode start.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from robot.odometry import wrap_angle
from robot.rescue import RescueConfig
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


class LoudestSourcePolicy:
    """Turn toward and drive to the loudest source (the paper's rule), see the module docstring.

    Per step: bumper pressed -> back off and sidestep (same side, the other after ``2`` bumps in
    a row); detections pointing at a victim already found are dropped; the target is the
    loudest, the current one kept while a detection lies within ``track_gate_deg`` of its
    remembered bearing and the loudest is less than
    ``switch_ratio_db`` louder; without detections the last target bearing is kept for
    ``explore_after_silent`` steps, then the robot explores straight ahead (away from the nearest
    found victim, whose calls mask the others). Toward the target:
    turn at up to ``turn_speed`` and, once it is within 60 degrees of ahead, translate along its
    azimuth at ``drive_speed`` (half that when the elevation says it is within ``bump_found_range_m``)."""

    def __init__(self, env_config: EnvConfig = EnvConfig(), rescue: RescueConfig | None = None) -> None:
        self.env_config = env_config
        self.rescue = rescue or RescueConfig(array_height_m=RobotModelConfig().array_height)
        self.reset()

    def reset(self, seed: int | None = None) -> None:
        self.pose = np.zeros(3)            # dead-reckoned from obs["odometry"] (policy's own frame)
        self.target_bearing: float | None = None  # rad, in the policy's frame
        self.target_level: float | None = None
        self.silent = 0
        self.bumps = 0
        self.side = 1.0
        self.found: list[np.ndarray] = []   # remembered positions of found victims (policy's frame)

    def __call__(self, obs) -> np.ndarray:
        cfg, env = self.rescue, self.env_config
        self.pose = compose(self.pose, obs["odometry"])
        if obs["found"][0] and self.target_bearing is not None:
            # The victim being approached was found: it is within reach, along the target bearing.
            self.found.append(self.pose[:2] + 0.5 * np.array([math.cos(self.target_bearing),
                                                               math.sin(self.target_bearing)]))
            self.target_bearing = self.target_level = None
        if obs["bumper"][0]:
            self.bumps += 1
            if self.bumps > 2:
                self.side, self.bumps = -self.side, 1
            return np.array([-0.6, 0.8 * self.side, 0.0], np.float32)
        self.bumps = 0
        yaw = float(self.pose[2])
        heard = [h for h in decode_detections(obs) if not self._is_found(yaw + h.azimuth)]
        target = self._choose(heard, yaw)
        if target is not None:
            self.silent = 0
            self.target_bearing, self.target_level = yaw + target.azimuth, target.level_db
            az, el = target.azimuth, target.elevation
        else:
            self.silent += 1
            if self.target_bearing is None or self.silent > cfg.explore_after_silent:
                self.target_bearing = None
                return self._explore(yaw)
            az, el = float(wrap_angle(self.target_bearing - yaw)), None
        return self._toward(az, el)

    def _is_found(self, bearing: float) -> bool:
        """Whether a bearing (policy frame, rad) points at a victim already found."""
        cfg = self.rescue
        for p in self.found:
            dx, dy = p - self.pose[:2]
            dist = max(math.hypot(dx, dy), 1e-6)
            gate = max(math.radians(cfg.exclusion_deg), math.atan2(cfg.exclusion_radius_m, dist))
            if abs(wrap_angle(bearing - math.atan2(dy, dx))) <= gate:
                return True
        return False

    def _explore(self, yaw: float) -> np.ndarray:
        """Straight ahead, or away from the nearest found victim."""
        heading = 0.0
        if self.found:
            p = min(self.found, key=lambda q: float(np.hypot(*(q - self.pose[:2]))))
            dx, dy = self.pose[:2] - p
            heading = float(wrap_angle(math.atan2(dy, dx) - yaw))
        v = self.rescue.drive_speed / self.env_config.max_speed
        return np.array([v * math.cos(heading), v * math.sin(heading), 0.0], np.float32)

    def _choose(self, heard: list[Heard], yaw: float) -> Heard | None:
        if not heard:
            return None
        cfg = self.rescue
        loudest = max(heard, key=lambda h: h.level_db)
        if self.target_bearing is not None:
            gate = math.radians(cfg.track_gate_deg)
            tracked = [h for h in heard if abs(wrap_angle(yaw + h.azimuth - self.target_bearing)) <= gate]
            if tracked:
                keep = max(tracked, key=lambda h: h.level_db)
                if loudest.level_db - keep.level_db < cfg.switch_ratio_db:
                    return keep
        return loudest

    def _toward(self, az: float, el: float | None) -> np.ndarray:
        cfg, env = self.rescue, self.env_config
        omega = 0.0
        if abs(az) > math.radians(cfg.turn_tolerance_deg):
            omega = float(np.clip(az / env.control_s, -cfg.turn_speed, cfg.turn_speed))
        vx = vy = 0.0
        if abs(az) <= math.radians(60.0):
            speed = cfg.drive_speed
            rng = cfg.range_from_elevation(el) if el is not None else None
            if rng is not None and rng < cfg.bump_found_range_m:
                speed *= 0.5
            # Translate along the azimuth at mid-turn (the body turns by omega * control_s meanwhile).
            heading = az - 0.5 * omega * env.control_s
            vx, vy = speed * math.cos(heading), speed * math.sin(heading)
        a = np.array([vx / env.max_speed, vy / env.max_speed, omega / env.max_turn_rate])
        return np.clip(a, -1.0, 1.0).astype(np.float32)
