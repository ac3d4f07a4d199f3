"""Odometry: wheel encoder increments, fused with a gyro's yaw rate when there is one, to a planar pose.

Odometry frame: fixed to the ground, origin and axes where the robot stood
when the estimator was (re)set (unless another start pose is given), +z up.
Pose ``(x, y, yaw)`` in m, m, rad; yaw CCW from the odometry frame's +x.

Gyro fusion (a complementary filter with a slip test and a standstill bias estimate):
wheels are exact while they grip but lie when they slip (pushing against rubble, a bump
recovery: one measured recovery added 41 deg of heading error); a gyro does not slip but
drifts with its bias and is only sampled at the reading times. So, per interval between
two readings:

* **bias**: while the wheels grip (their yaw increment within half the slip threshold of
  the gyro's) the difference is the gyro's bias; a first-order low-pass over
  ``bias_time_constant_s`` of such driving tracks it;
* **short interval** (<= ``max_gyro_dt_s``, the control loop's readings): the gyro's
  increment is the trapezoid of its two samples minus the bias. If the wheel increment
  differs from it by more than ``slip_rate`` x dt the wheels slipped: the gyro's increment
  is used, and the wheels' translation is dropped (a wheel pressing on rubble below the
  bumper turns in place while the base stays put: measured in light rubble, 0.5 m of false
  travel in 4 s without a bumper or stall signal); otherwise both, weighted
  ``wheel_weight`` : 1 - ``wheel_weight``;
* **long interval** (a listen, a settle): two samples do not describe what happened in
  between (the robot braked), so the wheels alone.

Translation is always the wheels', turned by the fused heading.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from robot.config_values import need
from robot.hal import WheelOdometry
from robot.kinematics import OmniDriveParams, forward_kinematics, integrate_pose


class Pose2D(NamedTuple):
    """Planar pose in the odometry/world frame: x, y (m), yaw (rad, CCW from +x)."""

    x: float
    y: float
    yaw: float


@dataclass(frozen=True)
class GyroFusionConfig:
    """How wheel and gyro yaw are combined (see the module docstring)."""

    max_gyro_dt_s: float = 0.15        # longer gaps between readings: wheels only (control loop runs at 0.05 s)
    slip_rate: float = 0.15            # rad/s of wheel-vs-gyro disagreement that means slip (~6x the gyro's
    #                                    sampling error while turning at 1.2 rad/s, measured in light rubble)
    wheel_weight: float = 0.0          # share of the wheels' yaw increment when both agree
    bias_time_constant_s: float = 10.0  # s of gripping drive over which the bias estimate settles

    def __post_init__(self) -> None:
        need(self, self.max_gyro_dt_s > 0, "max_gyro_dt_s", "> 0 s")
        need(self, self.slip_rate > 0, "slip_rate", "> 0 rad/s")
        need(self, 0 <= self.wheel_weight <= 1, "wheel_weight", "a fraction in [0, 1]")
        need(self, self.bias_time_constant_s > 0, "bias_time_constant_s", "> 0 s")


class Odometry:
    """Dead reckoning from cumulative wheel angles, with the gyro's yaw rate when given.

    Each update turns the wheel-angle increments since the previous reading
    into a body displacement through forward kinematics (linear, so increments
    map like speeds) and integrates it as a constant-twist arc, which is exact
    when the wheel speeds were constant between the two readings. The arc's
    heading change is the fused one (module docstring) when a yaw rate is given.
    """

    def __init__(self, params: OmniDriveParams = OmniDriveParams(), start_pose=(0.0, 0.0, 0.0),
                 gyro: GyroFusionConfig = GyroFusionConfig()) -> None:
        self.params = params
        self.gyro = gyro
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
        self._last_rate: float | None = None
        self._bias = 0.0
        self.slip_intervals = 0       # intervals in which the wheels' yaw was rejected as slip
        self.slipping = False         # the last interval was one of them

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

    @property
    def gyro_bias(self) -> float:
        """Current estimate of the gyro's bias (rad/s)."""
        return self._bias

    def update(self, reading: WheelOdometry, yaw_rate: float | None = None) -> np.ndarray:
        """Fold in one encoder reading and, if there is a gyro, its yaw rate (rad/s, CCW, sampled at the
        reading's time); returns the new pose."""
        angles = np.asarray(reading.wheel_angles, dtype=float)
        if angles.shape != (3,):
            raise ValueError(f"wheel_angles: expected 3 cumulative wheel angles (rad), got shape {angles.shape}")
        if self._last_time is not None and reading.timestamp < self._last_time:
            raise ValueError(
                f"timestamp: odometry readings must not go back in time ({reading.timestamp} < {self._last_time})"
            )
        if yaw_rate is not None and not np.isfinite(yaw_rate):
            raise ValueError(f"yaw_rate: expected a finite rate (rad/s) or None, got {yaw_rate!r}")
        speeds = np.asarray(reading.wheel_speeds, dtype=float)
        if self._last_angles is not None:
            step = forward_kinematics(angles - self._last_angles, self.params)  # (dx, dy, dyaw) body frame
            self.slipping = False
            if yaw_rate is not None and self._last_rate is not None:
                step[2], self.slipping = self._fused_yaw(float(step[2]), float(yaw_rate),
                                                         float(reading.timestamp) - self._last_time)
                if self.slipping:
                    step[:2] = 0.0
            self._pose = integrate_pose(self._pose, step, 1.0)
            # At constant body twist the speed is constant along the arc: length = |(dx, dy)|.
            self._distance += float(np.hypot(step[0], step[1]))
        self._last_angles = angles.copy()
        self._last_time = float(reading.timestamp)
        self._last_rate = None if yaw_rate is None else float(yaw_rate)
        self._twist = forward_kinematics(speeds, self.params)
        return self.pose

    def _fused_yaw(self, wheel_dyaw: float, rate: float, dt: float) -> tuple[float, bool]:
        """(heading increment, slipped) for one interval."""
        g = self.gyro
        if dt <= 0 or dt > g.max_gyro_dt_s:
            return wheel_dyaw, False
        gyro_dyaw = (0.5 * (rate + self._last_rate) - self._bias) * dt
        if abs(wheel_dyaw - gyro_dyaw) > g.slip_rate * dt:
            self.slip_intervals += 1
            return gyro_dyaw, True
        # Gripping wheels are the reference for the gyro's bias (a standstill reading is not: the base
        # creeps on its passive rollers, measured ~0.1 deg/s in MuJoCo, which the encoders do not see).
        # Only clean grip teaches it: half the slip threshold keeps pushes that did not quite slip out.
        if abs(wheel_dyaw - gyro_dyaw) <= 0.5 * g.slip_rate * dt:
            self._bias += min(1.0, dt / g.bias_time_constant_s) * ((gyro_dyaw - wheel_dyaw) / dt)
        return g.wheel_weight * wheel_dyaw + (1 - g.wheel_weight) * gyro_dyaw, False


def wrap_angle(a):
    """Wrap angle(s) in rad to ``[-pi, pi)``; a scalar gives a float."""
    w = (np.asarray(a, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi
    return float(w) if w.ndim == 0 else w
