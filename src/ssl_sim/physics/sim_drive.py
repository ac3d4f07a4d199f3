"""``robot.hal`` backends on top of ``SimRobot``: the drive base and a simulated clock.

Time only moves when the behaviour sleeps on ``SimClock`` (which steps the physics),
so a rescue run is deterministic and as fast as the CPU allows.
"""
from __future__ import annotations

import math

import numpy as np

from robot.hal import Clock, DriveBase, DriveStatus, WheelOdometry
from robot.protocol import ENCODER_WINDOW_S, GYRO_COUNTS_PER_RAD_S, twist_as_sent
from robot.ranging import RangeLayout
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

    ``yaw_rate``: what the firmware's TELEMETRY ``gyro_z`` reports of an MPU-6050 (firmware/src/gyro.c): the
    mean z rate over its last completed ``gyro_window`` (the firmware averages its 200 Hz samples over 50 ms
    windows on its own clock, so the window reported ends 0-50 ms before the read; its phase here is drawn
    from ``seed``), the base's true yaw change over that window (``SimRobot.mean_yaw_rate``), plus
    * white noise: ``gyro_noise_density`` (datasheet: 0.005 deg/s/sqrt(Hz), one-sided) averaged over the window
      leaves sigma = density / sqrt(2 window) = 0.016 deg/s, one draw per window (reads within a window agree);
    * a bias: ``gyro_bias`` at the start (rad/s; what is left after the host's standstill calibration: an
      assumption, the datasheet's +-20 deg/s zero-rate offset is before any calibration) that drifts as a random
      walk of ``gyro_bias_walk`` rad/s/sqrt(s) (0.001 deg/s/sqrt(s): over 200 s the bias wanders 0.014 deg/s,
      an assumption about slow thermal drift; an MPU-6050 at constant temperature measured 0.0012 deg/s bias
      instability on an Allan plot, robotics.stackexchange.com/q/8860);
    * the firmware's rounding to whole counts of 1/65.5 deg/s (``robot.protocol.GYRO_COUNTS_PER_RAD_S``).
    Sensitivity (datasheet: +-3 %) and cross-axis errors are not modelled. ``seed`` seeds noise and drift.
    ``gyro_bias`` holds the bias now (truth for tests).

    ``ranges``: the infrared range sensors of ``range_layout`` (``robot.ranging``; None: none fitted), MuJoCo rays
    from the true pose (``SimRobot.ray_distances``) plus Gaussian noise of ``range_noise`` times the distance (an
    assumption, not a measurement: the GP2Y0A21YK0F data sheet gives no noise figure), held to ``min_range_m`` below it and rounded to whole centimetres as the firmware
    reports them; inf where nothing is within ``max_range_m``. One reading per physics instant."""

    def __init__(self, robot: SimRobot, stall_min_speed: float = 1.0, stall_ratio: float = 0.25,
                 stall_time: float = 0.3, gyro_noise_density: float = math.radians(0.005),
                 gyro_window: float = ENCODER_WINDOW_S, gyro_bias: float = math.radians(0.1),
                 gyro_bias_walk: float = math.radians(0.001), seed: int = 0,
                 range_layout: RangeLayout | None = RangeLayout(), range_noise: float = 0.02) -> None:
        if not gyro_window > 0:
            raise ValueError(f"gyro_window: expected > 0 s, got {gyro_window}")
        if not (gyro_noise_density >= 0 and gyro_bias_walk >= 0 and math.isfinite(gyro_bias)):
            raise ValueError("gyro_noise_density, gyro_bias_walk: expected >= 0; gyro_bias: finite (rad/s), got "
                             f"{gyro_noise_density}, {gyro_bias_walk}, {gyro_bias}")
        if not range_noise >= 0:
            raise ValueError(f"range_noise: expected >= 0 (a fraction of the distance), got {range_noise}")
        self.robot = robot
        self.range_layout, self.range_noise = range_layout, float(range_noise)
        self._range_rng = np.random.default_rng([seed, 1])   # its own stream: the gyro's draws stay as they were
        self._ranges: tuple[float, tuple[float, ...]] | None = None
        self.stall_min_speed, self.stall_ratio, self.stall_time = stall_min_speed, stall_ratio, stall_time
        self._slow_since: float | None = None
        self._status: tuple[tuple, DriveStatus] | None = None   # (what it depends on, the last status read)
        self.gyro_window = float(gyro_window)
        self.gyro_sigma = float(gyro_noise_density) / math.sqrt(2.0 * self.gyro_window)
        self.gyro_bias = float(gyro_bias)
        self.gyro_bias_walk = float(gyro_bias_walk)
        self._bias_time = robot.time
        self._rng = np.random.default_rng(seed)
        self.gyro_phase = float(self._rng.uniform(0.0, self.gyro_window))   # windows end at gyro_phase + k window (s)
        self._window: tuple[float, float] | None = None                  # (end, reported rate) of the last window

    def set_twist(self, vx: float, vy: float, omega: float) -> None:
        if not np.all(np.isfinite([vx, vy, omega])):
            raise ValueError(f"set_twist: expected finite (vx, vy, omega), got {(vx, vy, omega)}")
        # at the serial link's resolution, as the firmware receives it: a twist that differs from another in
        # its last bits (one BLAS kernel's rounding against another's) then drives the same wheels
        self.robot.set_twist(*twist_as_sent(vx, vy, omega))

    def stop(self) -> None:
        self.robot.stop()
        self._slow_since = None

    def odometry(self) -> WheelOdometry:
        return self.robot.wheel_odometry()

    def status(self) -> DriveStatus:
        # Read again at the same physical state, time, commands and bias (a control tick reads it two or three
        # times), the status is the same: every part of it is a function of these (the noise draws happen only
        # when the time moved on), so the reading is kept.
        cmd = self.robot.wheel_commands
        key = (self.robot.state_version, self.robot.time, cmd.tobytes(), self.gyro_bias, self._slow_since)
        if self._status is not None and self._status[0] == key:
            return self._status[1]
        st = self._read_status(cmd)
        self._status = ((self.robot.state_version, self.robot.time, cmd.tobytes(), self.gyro_bias, self._slow_since),
                        st)
        return st

    def _read_status(self, cmd: np.ndarray) -> DriveStatus:
        speed = self.robot.wheel_odometry().wheel_speeds
        driven = np.abs(cmd) >= self.stall_min_speed
        slow = bool(np.any(driven & (np.abs(speed) < self.stall_ratio * np.abs(cmd))))
        now = self.robot.time
        if not slow:
            self._slow_since = None
        elif self._slow_since is None:
            self._slow_since = now
        stalled = self._slow_since is not None and now - self._slow_since >= self.stall_time
        if now > self._bias_time:
            self.gyro_bias += self.gyro_bias_walk * math.sqrt(now - self._bias_time) * float(self._rng.normal())
        self._bias_time = now
        w = self.gyro_window
        end = self.gyro_phase + math.floor((now - self.gyro_phase) / w + 1e-9) * w   # the last completed window's end
        if self._window is None or self._window[0] != end:
            rate = self.robot.mean_yaw_rate(w, end) + self.gyro_bias + self.gyro_sigma * float(self._rng.normal())
            self._window = (end, round(rate * GYRO_COUNTS_PER_RAD_S) / GYRO_COUNTS_PER_RAD_S)
        yaw_rate = self._window[1]
        return DriveStatus(bumper=self.robot.bumper(), stalled=stalled, yaw_rate=yaw_rate, ranges=self._read_ranges())

    @property
    def last_ranges(self) -> tuple[float, ...] | None:
        """The last reading ``status`` returned (None before the first or without sensors); reading it draws no
        noise, so watching a run does not change it."""
        return None if self._ranges is None else self._ranges[1]

    def _read_ranges(self) -> tuple[float, ...] | None:
        layout = self.range_layout
        if layout is None:
            return None
        now = self.robot.time
        if self._ranges is None or self._ranges[0] != now:
            d = self.robot.ray_distances(layout)
            seen = np.isfinite(d)
            noisy = d[seen] * (1.0 + self.range_noise * self._range_rng.standard_normal(int(seen.sum())))
            d[seen] = np.round(np.maximum(noisy, layout.min_range_m) * 100.0) / 100.0
            d[d > layout.max_range_m] = np.inf
            self._ranges = (now, tuple(float(v) for v in d))
        return self._ranges[1]

    def close(self) -> None:
        self.stop()
