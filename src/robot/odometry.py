"""Odometry: wheel encoder increments, fused with a gyro's yaw rate when there is one, to a planar pose.

Odometry frame: fixed to the ground, origin and axes where the robot stood
when the estimator was (re)set (unless another start pose is given), +z up.
Pose ``(x, y, yaw)`` in m, m, rad; yaw CCW from the odometry frame's +x.

Gyro fusion (heading from the gyro, its bias from standstills, translation from the wheels):
wheels measure heading well while they grip but lie when they slip (pushing against rubble, a bump
recovery: one measured recovery added 41 deg of heading error); a rate gyro does not slip, and its error
is its bias integrated over the driving time. So:

* **heading**: between two readings at most ``max_gyro_dt_s`` apart (the control loop's), the gyro's
  increment: its reported rate (the mean over the drive's last gyro window, 50 ms, ending at most a window
  before the reading: ``robot.hal.DriveStatus.yaw_rate``) minus the bias, times the interval. Over longer
  gaps (a listen, a settle) one rate does not describe what happened in between: the wheels' increment
  (the robot is braking or standing there);
* **bias**: learnt only while the robot stands, the zero-velocity update: the caller says the drive is
  commanded to stand (``stationary``), the wheels turn slower than ``still_wheel_speed`` and the encoders
  have moved by less than ``still_wheel_angle`` between readings for at least two gyro windows (the window
  reported ends up to one window before the reading).
  Then the gyro reads its bias; a scalar Kalman filter (the bias a random walk of ``bias_walk``, each
  reading its noise ``rate_noise``) averages these readings, gating ones beyond ``bias_gate`` sigma (the robot
  bumped while standing). Moving wheels are no reference: their own heading error is what the gyro corrects;
* **slip**: if the wheels' yaw increment differs from the gyro's by more than ``slip_rate`` x dt, the wheels
  slipped (a wheel pressing on rubble below the bumper turns in place while the base stays put: measured in
  light rubble, 0.5 m of false travel in 4 s without a bumper or stall signal).

Translation is the wheels', turned by the fused heading, from the wheels that are not **loaded** when the caller
says what the drive was commanded (``commanded``; ``TravelConfig``). A wheel whose mean speed over the interval
(encoder increment / interval, what the firmware's 50 ms count window gives too) is more than ``loaded_speed`` off
its mean commanded speed works against a resistance its speed loop cannot overcome: the base pushes debris or a wall,
or rubble drags that wheel. Its encoder then over-reports the base's motion (measured in light rubble: in intervals
with loaded wheels the base made 40-70 % of the three wheels' translation on average, from nothing to all of it).
A free wheel rolls: its rim speed is the base's velocity along its rolling direction plus base_radius x yaw rate.
With the yaw from the gyro, each free wheel thus fixes one component of the base's motion; the translation is the
smallest one consistent with the free wheels (three: the least-squares fit, which ignores a slip common to all
three, as that is yaw; two: exact; one: along its rolling direction only; none: the base is held, no travel).
Without a command (``commanded`` never called: a caller that does not drive) the wheels' translation is kept,
dropped when their yaw slips.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from robot.config_values import need
from robot.hal import WheelOdometry
from robot.kinematics import OmniDriveParams, forward_kinematics, integrate_pose, twist_to_wheels


class Pose2D(NamedTuple):
    """Planar pose in the odometry/world frame: x, y (m), yaw (rad, CCW from +x)."""

    x: float
    y: float
    yaw: float


def pose_at(trajectory, time: float) -> Pose2D:
    """Pose at ``time`` (s) linearly interpolated in a trajectory (k, 4) of rows ``(time, x, y, yaw)`` with
    increasing times (yaw unwrapped first; held at the ends)."""
    tr = np.asarray(trajectory, float)
    if tr.ndim != 2 or tr.shape[1] != 4 or len(tr) < 1 or not np.all(np.isfinite(tr)):
        raise ValueError(f"trajectory: expected finite (k >= 1, 4) rows (time, x, y, yaw), got shape {tr.shape}")
    if np.any(np.diff(tr[:, 0]) <= 0):
        raise ValueError("trajectory: times must increase")
    t = float(time)
    yaw = np.unwrap(tr[:, 3])
    return Pose2D(float(np.interp(t, tr[:, 0], tr[:, 1])), float(np.interp(t, tr[:, 0], tr[:, 2])),
                  float(np.interp(t, tr[:, 0], yaw)))


@dataclass(frozen=True)
class GyroFusionConfig:
    """How the gyro's yaw rate is fused (see the module docstring). Rates in rad/s."""

    max_gyro_dt_s: float = 0.15        # longer gaps between readings: wheels only (control loop runs at 0.05 s)
    gyro_window_s: float = 0.05        # the drive's gyro rate is the mean over this window (firmware ENC_WINDOW_MS)
    slip_rate: float = 0.15            # rad/s of wheel-vs-gyro disagreement that means slip. Measured in light
    #                                    rubble (seeds 0-3, 200 s): the gyro's error per reading <= 0.001 rad/s, the
    #                                    gripping wheels' 90th percentile 0.02; all 189 intervals above 0.15 were true
    #                                    slips (wheels vs truth > 0.1 rad/s), none over 0.15 true slip was missed
    still_wheel_speed: float = 0.05    # rad/s: wheels slower than this stand (a parked robot's wheels jitter at
    #                                    0.03 rad/s, 90th percentile, measured in light rubble: SimRobot._settled)
    still_wheel_angle: float = 0.01    # rad of encoder travel since the previous reading that still counts as
    #                                    standing (two counts of a 1200-count encoder)
    rate_noise: float = math.radians(0.07)   # one standstill reading's spread about the bias: the MPU-6050's noise
    #                                    over the 50 ms window is 0.016 deg/s, but the base still rocks on its
    #                                    contacts after braking: 0.06-0.08 deg/s measured in light rubble, seeds 0-3
    bias_sigma0: float = math.radians(1.0)   # prior uncertainty of the bias the drive's calibration leaves (the gate
    #                                    below starts at bias_gate x this: a larger residual needs a larger prior)
    bias_walk: float = math.radians(0.001)   # rad/s/sqrt(s) the bias may drift (thermal; as ssl_sim's model)
    bias_gate: float = 5.0             # standstill readings further than this many sigma from the estimate are
    #                                    ignored (a knock while standing: up to 0.9 deg/s seen in light rubble)

    def __post_init__(self) -> None:
        need(self, self.max_gyro_dt_s > 0, "max_gyro_dt_s", "> 0 s")
        need(self, self.gyro_window_s > 0, "gyro_window_s", "> 0 s")
        need(self, self.slip_rate > 0, "slip_rate", "> 0 rad/s")
        need(self, self.still_wheel_speed > 0, "still_wheel_speed", "> 0 rad/s")
        need(self, self.still_wheel_angle > 0, "still_wheel_angle", "> 0 rad")
        need(self, self.rate_noise > 0, "rate_noise", "> 0 rad/s")
        need(self, self.bias_sigma0 > 0, "bias_sigma0", "> 0 rad/s")
        need(self, self.bias_walk >= 0, "bias_walk", ">= 0 rad/s/sqrt(s)")
        need(self, self.bias_gate > 0, "bias_gate", "> 0 sigma")


@dataclass(frozen=True)
class TravelConfig:
    """Which wheels the translation trusts (module docstring).

    ``loaded_speed``: rad/s between a wheel's mean speed and its mean command over an interval beyond which the wheel
    is loaded. In the simulator the wheels run under a speed loop (``ssl_sim`` robot model: 0.5 N m s/rad), which
    then pushes with 0.25 N m, a quarter of the stall torque; a wheel rolling freely tracks within 0.1-0.2 rad/s.
    The firmware drives open loop (duty proportional to the command), where the motor's back-EMF acts as a softer
    loop (stall torque / no-load speed, about 0.05 N m s/rad for 1 N m and 20 rad/s): the same 0.25 N m is then about
    5 rad/s off the command. Measure it on the robot before trusting this default there. Measured in light rubble (``ssl_sim.runner.odometry_drift`` runs,
    every control interval's encoders and commands logged, replayed against MuJoCo's end pose; seeds 0-15, 200 s):
    largest end error 0.18 / 0.20 / 0.30 / 0.56 m with 0.4 / 0.5 / 0.6 / 0.75 rad/s, mean 0.10 / 0.09 / 0.10 / 0.18 m,
    against 0.36 m and 0.16 m with the slipping intervals' travel dropped and the wheels trusted otherwise."""

    loaded_speed: float = 0.5

    def __post_init__(self) -> None:
        need(self, self.loaded_speed > 0, "loaded_speed", "> 0 rad/s")


class Odometry:
    """Dead reckoning from cumulative wheel angles, with the gyro's yaw rate when given.

    Each update turns the wheel-angle increments since the previous reading
    into a body displacement through forward kinematics (linear, so increments
    map like speeds) and integrates it as a constant-twist arc, which is exact
    when the wheel speeds were constant between the two readings. The arc's
    heading change is the fused one (module docstring) when a yaw rate is given.
    """

    def __init__(self, params: OmniDriveParams = OmniDriveParams(), start_pose=(0.0, 0.0, 0.0),
                 gyro: GyroFusionConfig = GyroFusionConfig(), travel: TravelConfig = TravelConfig()) -> None:
        self.params = params
        self.gyro = gyro
        self.travel = travel
        self._command: np.ndarray | None = None       # wheel speeds (rad/s) commanded now; None: never told
        self._command_since = 0.0                      # time (s) from which _command_sum has been accumulated
        self._command_sum = np.zeros(3)                # integral of the commanded wheel speeds since the last reading
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
        self._still_since: float | None = None
        self._bias = 0.0
        self._bias_var = self.gyro.bias_sigma0 ** 2
        self._bias_time: float | None = None
        self.bias_updates = 0         # standstill readings the bias estimate took in
        self.slip_intervals = 0       # intervals in which the wheels' yaw was rejected as slip
        self.slipping = False         # the last interval was one of them
        self.loaded_intervals = 0     # intervals driven with at least one loaded wheel (TravelConfig)
        self._command_sum = np.zeros(3)

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

    @property
    def gyro_bias_sigma(self) -> float:
        """Standard deviation of the bias estimate (rad/s)."""
        return math.sqrt(self._bias_var)

    def commanded(self, time: float, twist=None) -> None:
        """The drive is commanded body twist ``(vx, vy, omega)`` (m/s, m/s, rad/s, robot frame; None: stopped) from
        ``time`` (s, the readings' clock) on; the odometry turns it into wheel speeds as the drive does (inverse
        kinematics with direction-keeping saturation) and compares each interval's mean against the encoders."""
        t = float(time)
        tw = None if twist is None else np.asarray(twist, dtype=float)
        if tw is not None and (tw.shape != (3,) or not np.all(np.isfinite(tw))):
            raise ValueError(f"twist: expected 3 finite numbers (vx m/s, vy m/s, omega rad/s) or None, got {twist!r}")
        if self._command is not None:
            self._command_sum += self._command * max(0.0, t - self._command_since)
        self._command_since = max(t, self._command_since)
        self._command = np.zeros(3) if tw is None else twist_to_wheels(tw, self.params)

    def _mean_command(self, t0: float, t1: float) -> np.ndarray | None:
        """Mean commanded wheel speeds (rad/s) over the reading interval ``[t0, t1]``; None if never told."""
        if self._command is None:
            return None
        total = self._command_sum + self._command * max(0.0, t1 - self._command_since)
        self._command_sum = np.zeros(3)
        self._command_since = max(t1, self._command_since)
        return total / (t1 - t0) if t1 > t0 else self._command.copy()

    def update(self, reading: WheelOdometry, yaw_rate: float | None = None, stationary: bool = False) -> np.ndarray:
        """Fold in one encoder reading and, if there is a gyro, its yaw rate (rad/s, CCW: the mean over the gyro's
        last window); ``stationary``: the drive is commanded to stand (nothing sent
        since it stopped), so a reading whose wheels stand too is a zero-velocity update. Returns the new pose."""
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
        now = float(reading.timestamp)
        command = self._mean_command(now if self._last_time is None else self._last_time, now)
        if self._last_angles is not None:
            step = forward_kinematics(angles - self._last_angles, self.params)  # (dx, dy, dyaw) body frame
            dt = float(reading.timestamp) - self._last_time
            still = (stationary and float(np.max(np.abs(angles - self._last_angles))) < self.gyro.still_wheel_angle
                     and float(np.max(np.abs(speeds))) < self.gyro.still_wheel_speed)
            if not still:
                self._still_since = None
            elif self._still_since is None:
                self._still_since = self._last_time     # the encoders have not moved since the previous reading
            # The gyro's window ends up to one window before the reading (the firmware's own clock): two windows of
            # stillness keep the braking out of it (less a tenth: timestamps fall on physics/clock ticks).
            standing = still and reading.timestamp - self._still_since >= 1.9 * self.gyro.gyro_window_s
            self.slipping = False
            if yaw_rate is not None:
                if standing:
                    self._learn_bias(float(yaw_rate), float(reading.timestamp))
                else:
                    step[2], self.slipping = self._fused_yaw(float(step[2]), float(yaw_rate), dt)
            step[:2] = self._translation(angles - self._last_angles, step, dt, command)
            self._pose = integrate_pose(self._pose, step, 1.0)
            # At constant body twist the speed is constant along the arc: length = |(dx, dy)|.
            self._distance += float(np.hypot(step[0], step[1]))
        self._last_angles = angles.copy()
        self._last_time = float(reading.timestamp)
        self._twist = forward_kinematics(speeds, self.params)
        return self.pose

    def _translation(self, d_angles: np.ndarray, step: np.ndarray, dt: float,
                     command: np.ndarray | None) -> np.ndarray:
        """Body-frame (dx, dy) (m) of one interval: ``step`` is the wheels' (dx, dy) and the fused dyaw, ``d_angles``
        the encoder increments (rad), ``command`` the mean commanded wheel speeds (rad/s) or None."""
        driven = command is not None and 0.0 < dt <= self.gyro.max_gyro_dt_s and bool(np.any(command != 0.0))
        if not driven:
            return np.zeros(2) if self.slipping else step[:2]
        free = np.abs(d_angles / dt - command) <= self.travel.loaded_speed
        if free.all():
            return step[:2]                  # the least-squares fit of all three (forward kinematics)
        self.loaded_intervals += 1
        if not free.any():
            return np.zeros(2)
        jac = self.params.jacobian
        # Free wheel i rolls: J[i, :2] . (dx, dy) = d_i - J[i, 2] dyaw; the smallest (dx, dy) that satisfies them.
        return np.linalg.pinv(jac[free, :2]) @ (d_angles[free] - jac[free, 2] * step[2])

    def _fused_yaw(self, wheel_dyaw: float, rate: float, dt: float) -> tuple[float, bool]:
        """(heading increment, slipped) for one interval while not standing."""
        g = self.gyro
        if dt <= 0 or dt > g.max_gyro_dt_s:
            return wheel_dyaw, False
        gyro_dyaw = (rate - self._bias) * dt
        if abs(wheel_dyaw - gyro_dyaw) > g.slip_rate * dt:
            self.slip_intervals += 1
            return gyro_dyaw, True
        return gyro_dyaw, False

    def _learn_bias(self, rate: float, time: float) -> None:
        """Zero-velocity update: ``rate`` (rad/s) read standing still is the bias plus noise."""
        g = self.gyro
        if self._bias_time is not None:
            self._bias_var += g.bias_walk ** 2 * max(0.0, time - self._bias_time)
        self._bias_time = time
        s2 = self._bias_var + g.rate_noise ** 2
        innovation = rate - self._bias
        if innovation ** 2 > g.bias_gate ** 2 * s2:
            return
        k = self._bias_var / s2
        self._bias += k * innovation
        self._bias_var *= 1.0 - k
        self.bias_updates += 1


def wrap_angle(a):
    """Wrap angle(s) in rad to ``[-pi, pi)``; a scalar gives a float."""
    w = (np.asarray(a, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi
    return float(w) if w.ndim == 0 else w
