"""``robot.hal`` backends on top of ``SimRobot``: the drive base and a simulated clock.

Time only moves when the behaviour sleeps on ``SimClock`` (which steps the physics),
so a rescue run is deterministic and as fast as the CPU allows.
"""
from __future__ import annotations

import math

import numpy as np

from robot.hal import Clock, DriveBase, DriveStatus, WheelOdometry
from ssl_sim.physics.sim_robot import SimRobot


class SimClock(Clock):
    """Simulated time of a ``SimRobot``; ``sleep`` advances the physics."""

    def __init__(self, robot: SimRobot) -> None:
        self.robot = robot

    def now(self) -> float:
        return self.robot.time

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self.robot.step(seconds)


class SimDriveBase(DriveBase):
    """The MuJoCo robot as a ``DriveBase``.

    ``stalled``: some wheel commanded at >= ``stall_min_speed`` rad/s has turned at less than
    ``stall_ratio`` of its command for ``stall_time`` s (sampled each time ``status`` is read).

    ``yaw_rate``: the IMU's gyro about the robot's +z (the model's ``imu_gyro`` sensor, which MuJoCo
    computes noise-free) plus what an MPU-6050-class gyro adds: white noise of ``gyro_noise_density``
    (datasheet: 0.005 deg/s/sqrt(Hz)) over ``gyro_bandwidth`` Hz (its low-pass filter, 42 Hz setting) and
    a constant ``gyro_bias`` (rad/s; what a start-up calibration leaves: an assumption, the datasheet's
    +-20 deg/s zero-rate offset is before calibration). ``seed`` seeds the noise."""

    def __init__(self, robot: SimRobot, stall_min_speed: float = 1.0, stall_ratio: float = 0.25,
                 stall_time: float = 0.3, gyro_noise_density: float = math.radians(0.005),
                 gyro_bandwidth: float = 42.0, gyro_bias: float = math.radians(0.1), seed: int = 0) -> None:
        self.robot = robot
        self.stall_min_speed, self.stall_ratio, self.stall_time = stall_min_speed, stall_ratio, stall_time
        self._slow_since: float | None = None
        self.gyro_sigma = float(gyro_noise_density) * math.sqrt(float(gyro_bandwidth))
        self.gyro_bias = float(gyro_bias)
        self._rng = np.random.default_rng(seed)

    def set_twist(self, vx: float, vy: float, omega: float) -> None:
        if not np.all(np.isfinite([vx, vy, omega])):
            raise ValueError(f"set_twist: expected finite (vx, vy, omega), got {(vx, vy, omega)}")
        self.robot.set_twist(vx, vy, omega)

    def stop(self) -> None:
        self.robot.stop()
        self._slow_since = None

    def odometry(self) -> WheelOdometry:
        return self.robot.wheel_odometry()

    def status(self) -> DriveStatus:
        cmd = self.robot.wheel_commands
        speed = self.robot.wheel_odometry().wheel_speeds
        driven = np.abs(cmd) >= self.stall_min_speed
        slow = bool(np.any(driven & (np.abs(speed) < self.stall_ratio * np.abs(cmd))))
        now = self.robot.time
        if not slow:
            self._slow_since = None
        elif self._slow_since is None:
            self._slow_since = now
        stalled = self._slow_since is not None and now - self._slow_since >= self.stall_time
        yaw_rate = float(self.robot.imu().gyro[2]) + self.gyro_bias + self.gyro_sigma * float(self._rng.normal())
        return DriveStatus(bumper=self.robot.bumper(), stalled=stalled, yaw_rate=yaw_rate)

    def close(self) -> None:
        self.stop()
