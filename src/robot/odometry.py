"""Wheel odometry: integrate encoder increments to a planar pose in the odometry frame.

Odometry frame: fixed to the ground, origin and axes where the robot stood
when the estimator was (re)set (unless another start pose is given), +z up.
Pose ``(x, y, yaw)`` in m, m, rad; yaw CCW from the odometry frame's +x.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from robot.hal import WheelOdometry
from robot.kinematics import OmniDriveParams, forward_kinematics, integrate_pose


class Pose2D(NamedTuple):
    """Planar pose in the odometry/world frame: x, y (m), yaw (rad, CCW from +x)."""

    x: float
    y: float
    yaw: float


class Odometry:
    """Dead reckoning from cumulative wheel angles.

    Each update turns the wheel-angle increments since the previous reading
    into a body displacement through forward kinematics (linear, so increments
    map like speeds) and integrates it as a constant-twist arc, which is exact
    when the wheel speeds were constant between the two readings.
    """

    def __init__(self, params: OmniDriveParams = OmniDriveParams(), start_pose=(0.0, 0.0, 0.0)) -> None:
        self.params = params
        self.reset(start_pose)

    def reset(self, pose=(0.0, 0.0, 0.0)) -> None:
        """Set the pose (m, m, rad); the next reading becomes the new encoder reference."""
        p = np.asarray(pose, dtype=float)
        if p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f"pose: expected 3 finite numbers (x m, y m, yaw rad), got {pose!r}")
        self._pose = p
        self._last_angles: np.ndarray | None = None
        self._last_time: float | None = None
        self._twist = np.zeros(3)
        self._distance = 0.0

    @property
    def pose(self) -> np.ndarray:
        """Current pose ``(x, y, yaw)`` in the odometry frame (copy)."""
        return self._pose.copy()

    @property
    def twist(self) -> np.ndarray:
        """Latest body twist ``(vx, vy, omega)`` from the reported wheel speeds (robot frame)."""
        return self._twist.copy()

    @property
    def distance(self) -> float:
        """Path length travelled by the base centre since reset (m)."""
        return self._distance

    def update(self, reading: WheelOdometry) -> np.ndarray:
        """Fold in one encoder reading; returns the new pose."""
        angles = np.asarray(reading.wheel_angles, dtype=float)
        if angles.shape != (3,):
            raise ValueError(f"wheel_angles: expected 3 cumulative wheel angles (rad), got shape {angles.shape}")
        if self._last_time is not None and reading.timestamp < self._last_time:
            raise ValueError(
                f"timestamp: odometry readings must not go back in time ({reading.timestamp} < {self._last_time})"
            )
        if self._last_angles is not None:
            step = forward_kinematics(angles - self._last_angles, self.params)  # (dx, dy, dyaw) body frame
            self._pose = integrate_pose(self._pose, step, 1.0)
            # At constant body twist the speed is constant along the arc: length = |(dx, dy)|.
            self._distance += float(np.hypot(step[0], step[1]))
        self._last_angles = angles.copy()
        self._last_time = float(reading.timestamp)
        self._twist = forward_kinematics(np.asarray(reading.wheel_speeds, dtype=float), self.params)
        return self.pose


def wrap_angle(a):
    """Wrap angle(s) in rad to ``[-pi, pi)``; a scalar gives a float."""
    w = (np.asarray(a, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi
    return float(w) if w.ndim == 0 else w
