"""Motion primitives with odometry feedback: turn in place, translate holding the yaw, follow a path, back off.

Frames: headings are in the ROBOT frame at the start of the move (rad, CCW from forward) unless stated;
poses in the odometry frame. Every primitive stops the drive when it ends; a bumper press, a stall (the
drive's own flag, or too little odometry progress for the command: ``StallWatch``), wheel slip that the
gyro exposes (``Odometry.slipping`` for ``slip_intervals`` readings in a row) or a fatal fault raise
``Blocked`` with the drive status, after stopping. A translation asked to (``stop_for_ranges``) also stops
before an obstacle its range sensors see in its way (``Blocked("range")``): a return inside the corridor the
bumper sweeps, within ``range_stop_m`` ahead of it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from enum import StrEnum
from typing import Callable, ClassVar, Sequence

import numpy as np

from robot.hal import Clock, DriveBase, DriveStatus
from robot.odometry import Odometry, wrap_angle
from robot.ranging import RangeLayout

__all__ = ["MotionConfig", "ContactKind", "Blocked", "Motion", "StallWatch"]


@dataclass(frozen=True)
class MotionConfig:
    """Parameters of the motion primitives (SI units; ``*_deg`` in degrees)."""

    control_dt: float = 0.05               # control loop period while moving (s)
    turn_speed: float = 1.2                # max turn rate (rad/s)
    drive_speed: float = 0.25              # m/s
    recover_speed: float = 0.15            # m/s while backing off
    backoff_m: float = 0.15                # back-off after a contact
    stall_window_s: float = 0.6            # own stall check: progress over this window ...
    stall_progress_ratio: float = 0.2      # ... below this fraction of the commanded motion = stalled
    slip_intervals: int = 4                # gyro-detected slip this many readings in a row (0.2 s) = blocked
    motion_timeout_factor: float = 3.0     # a move may take this many times its nominal duration
    range_stop_m: float = 0.12             # a range return this close ahead of the bumper stops a move (a control
    #                                        tick at 0.25 m/s is 0.0125 m; the rest is margin for braking)
    body_radius_m: float = 0.16            # the bumper ring (the corridor a translation sweeps is this wide each side)

    #: Fields that no longer exist (robot.config_values.field_values: ignored with a warning).
    RETIRED: ClassVar[dict[str, str]] = {
        "turn_tolerance_deg": "no motion primitive read it: the base translates, it never turns toward a heading"}

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"MotionConfig.{f.name}={v!r}: expected a finite number > 0")


class ContactKind(StrEnum):
    """Why a move ended early; the value is its keyword in logs, the occupancy grid and ``results.json``."""

    BUMPER = "bumper"   # the bumper ring touched something
    STALL = "stall"     # the drive's stall flag, or too little odometry progress for the command (StallWatch)
    SLIP = "slip"       # the gyro disagrees with the wheels for slip_intervals readings in a row
    RANGE = "range"     # a range return inside the swept corridor ahead (no touch: stopped before it)
    FAULT = "fault"     # a fatal drive fault (no contact: the mission ends)


class Blocked(Exception):
    """A move ended early: ``kind`` says why (``ContactKind``); ``heading`` the direction of the attempted motion
    in the odometry frame (rad) for mapping the contact."""

    def __init__(self, kind: ContactKind | str, status: DriveStatus, heading: float = 0.0) -> None:
        kind = ContactKind(kind)   # a name outside ContactKind raises ValueError here
        super().__init__(kind)
        self.kind, self.status, self.heading = kind, status, heading


class StallWatch:
    """Too little progress (odometry) for the commanded motion over ``stall_window_s``."""

    def __init__(self, cfg: MotionConfig, t: float, progress: float) -> None:
        self.cfg, self.t0, self.p0 = cfg, t, progress
        self.expected = 0.0
        self.last_t = t

    def stalled(self, t: float, progress: float, commanded_rate: float) -> bool:
        self.expected += commanded_rate * (t - self.last_t)
        self.last_t = t
        if t - self.t0 >= self.cfg.stall_window_s:
            made = abs(progress - self.p0)
            if self.expected > 0 and made < self.cfg.stall_progress_ratio * self.expected:
                return True
            self.t0, self.p0, self.expected = t, progress, 0.0
        return False


class Motion:
    """The primitives on ``drive`` with ``odometry`` fed by the drive's encoders and gyro.

    ``fatal``: called with each status; returns True when the mission must stop (faults).
    ``sensed``: called with the odometry pose and every drive status read (range readings for the map).
    ``range_layout``: where the range sensors sit (``robot.ranging``); None: no range stops."""

    def __init__(self, drive: DriveBase, clock: Clock, odometry: Odometry, config: MotionConfig = MotionConfig(),
                 fatal: Callable[[DriveStatus], bool] = lambda s: False,
                 sensed: Callable[[np.ndarray, DriveStatus], None] | None = None,
                 range_layout: RangeLayout | None = None) -> None:
        self.drive, self.clock, self.odometry, self.config, self.fatal = drive, clock, odometry, config, fatal
        self.sensed, self.range_layout = sensed, range_layout
        self._slips = 0

    def status(self) -> DriveStatus:
        """The drive's status now, handed to ``sensed`` with the pose it was read at."""
        st = self.drive.status()
        if self.sensed is not None:
            self.sensed(self.odometry.pose, st)
        return st

    def _drive(self, vx: float, vy: float, omega: float) -> None:
        """Command a body twist and tell the odometry (it compares the wheels against the command)."""
        self.drive.set_twist(vx, vy, omega)
        self.odometry.commanded(self.clock.now(), (vx, vy, omega))

    def stop(self) -> None:
        """Stop the drive (and tell the odometry)."""
        self.drive.stop()
        self.odometry.commanded(self.clock.now(), None)

    def update_odometry(self, stationary: bool = False):
        """Read encoders and gyro into the odometry; ``stationary``: the drive stands as commanded (every
        primitive has stopped it), so the odometry may learn the gyro's bias (zero-velocity update)."""
        return self.odometry.update(self.drive.odometry(), self.status().yaw_rate, stationary)

    def stand(self, seconds: float) -> None:
        """Stand still (drive stopped) for ``seconds``, reading the odometry every control tick: the braking
        is tracked and, once the wheels stand, each tick is a zero-velocity update of the gyro's bias."""
        self.stop()
        t_end = self.clock.now() + seconds
        while (left := t_end - self.clock.now()) > 1e-9:
            self.clock.sleep(min(self.config.control_dt, left))
            self.update_odometry(stationary=True)

    def _in_the_way(self, st: DriveStatus, direction: float, reach: float) -> bool:
        """A range return in the corridor swept by moving ``reach`` m along ``direction`` (rad, robot frame)?"""
        layout, cfg = self.range_layout, self.config
        if layout is None or st.ranges is None or reach <= 0:
            return False
        r = layout.check(st.ranges)
        seen = np.isfinite(r)
        az = np.asarray(layout.azimuths_rad, float)[seen]
        dist = layout.mount_radius_m + r[seen]          # from the robot centre
        along = dist * np.cos(az - direction)
        across = np.abs(dist * np.sin(az - direction))
        return bool(np.any((along > 0) & (across < cfg.body_radius_m) & (along < cfg.body_radius_m + reach)))

    def _check(self, bumper_armed: bool, heading_world: float, way: tuple[float, float] | None = None) -> None:
        """Stop and raise ``Blocked`` on a fault, bumper, stall or slip; ``way``: (direction in the robot frame,
        rad; distance still to go, m) of a translation that stops for range returns in its way."""
        st = self.status()
        kind = None
        if self.fatal(st):
            kind = ContactKind.FAULT
        elif st.bumper and bumper_armed:
            kind = ContactKind.BUMPER
        elif st.stalled:
            kind = ContactKind.STALL
        elif self._slips >= self.config.slip_intervals:
            kind = ContactKind.SLIP
        elif way is not None and self._in_the_way(st, way[0], min(way[1], self.config.range_stop_m)):
            kind = ContactKind.RANGE
        if kind is not None:
            self.stop()
            self.update_odometry()
            raise Blocked(kind, st, heading_world)

    def _tick_odometry(self):
        pose = self.update_odometry()
        self._slips = self._slips + 1 if self.odometry.slipping else 0
        return pose

    def turn(self, angle: float) -> None:
        """Turn in place by ``angle`` rad (CCW positive)."""
        cfg = self.config
        yaw0 = float(self._tick_odometry()[2])
        t_end = self.clock.now() + cfg.motion_timeout_factor * (abs(angle) / cfg.turn_speed + 0.5)
        watch = StallWatch(cfg, self.clock.now(), yaw0)
        self._slips = 0
        try:
            while True:
                yaw = float(self._tick_odometry()[2])
                remaining = angle - (yaw - yaw0)
                if abs(remaining) <= math.radians(1.0) or self.clock.now() >= t_end:
                    break
                omega = math.copysign(min(cfg.turn_speed, max(0.25, 2.5 * abs(remaining))), remaining)
                self._drive(0.0, 0.0, omega)
                self.clock.sleep(cfg.control_dt)
                self._check(True, yaw)
                if watch.stalled(self.clock.now(), float(self._tick_odometry()[2]), abs(omega)):
                    self.stop()
                    raise Blocked(ContactKind.STALL, DriveStatus(stalled=True), yaw)
        finally:
            self.stop()
        self.update_odometry()

    def translate(self, heading: float, distance: float, speed: float | None = None,
                  arm_bumper_on_release: bool = False, stop_for_ranges: bool = False,
                  pace: Callable[[float], bool] | None = None) -> float:
        """Move ``distance`` m along ``heading`` (rad, robot frame at the start) keeping the yaw; returns the
        distance made (odometry). ``arm_bumper_on_release``: a bumper pressed at the start only counts once
        released (backing away from a contact). ``stop_for_ranges``: stop before a range return in the way.
        ``pace(seconds)``: waits one control tick instead of the clock (reading that much audio: a drive that
        listens, ``robot.drive_hearing``); it returns False to end the move there (the distance made so far)."""
        cfg = self.config
        speed = cfg.drive_speed if speed is None else speed
        x0, y0, yaw0 = self._tick_odometry()
        world_heading = yaw0 + heading
        ux, uy = math.cos(world_heading), math.sin(world_heading)
        t_end = self.clock.now() + cfg.motion_timeout_factor * (distance / speed + 0.5)
        armed = not arm_bumper_on_release or not self.status().bumper
        watch = StallWatch(cfg, self.clock.now(), 0.0)
        self._slips = 0
        done = 0.0
        try:
            while True:
                x, y, yaw = self._tick_odometry()
                done = (x - x0) * ux + (y - y0) * uy
                remaining = distance - done
                if remaining <= 0.005 or self.clock.now() >= t_end:
                    break
                v = min(speed, max(0.05, 2.0 * remaining))
                rel = heading - (yaw - yaw0)  # hold the start yaw: the direction in the body frame turns back
                self._drive(v * math.cos(rel), v * math.sin(rel), -2.0 * (yaw - yaw0))
                going = True
                if pace is None:
                    self.clock.sleep(cfg.control_dt)
                else:
                    going = pace(cfg.control_dt)
                armed = armed or not self.status().bumper
                self._check(armed, world_heading, (rel, remaining) if stop_for_ranges else None)
                x, y, _ = self._tick_odometry()
                if watch.stalled(self.clock.now(), (x - x0) * ux + (y - y0) * uy, v):
                    self.stop()
                    raise Blocked(ContactKind.STALL, DriveStatus(stalled=True), world_heading)
                if not going:
                    done = (x - x0) * ux + (y - y0) * uy
                    break
        finally:
            self.stop()
        self.update_odometry()
        return done

    def follow(self, points: Sequence[np.ndarray], pace: Callable[[float], bool] | None = None,
               travelled: Callable[[np.ndarray, np.ndarray], None] | None = None) -> bool:
        """Drive straight to each of ``points`` (x, y m, odometry frame) in turn, keeping the yaw and stopping
        before a range return in the way; ``travelled(start, end)`` gets every stretch driven, also the one a
        contact ends (before ``Blocked`` propagates). ``pace`` as in ``translate``; False when it ended the drive."""
        going = True

        def paced(seconds: float) -> bool:
            nonlocal going
            going = pace(seconds)
            return going

        for point in points:
            start = self.odometry.pose[:2].copy()
            dx, dy = point - start
            try:
                self.translate(float(wrap_angle(math.atan2(dy, dx) - self.odometry.pose[2])), float(np.hypot(dx, dy)),
                               stop_for_ranges=True, pace=None if pace is None else paced)
            except Blocked:
                if travelled is not None:
                    travelled(start, self.odometry.pose[:2])
                raise
            if travelled is not None:
                travelled(start, self.odometry.pose[:2])
            if not going:
                return False
        return True

    def back_off(self, heading_world: float) -> None:
        """Back ``backoff_m`` away from a contact met while moving along ``heading_world`` (rad, odometry frame)."""
        yaw = float(self.odometry.pose[2])
        self.translate(heading_world + math.pi - yaw, self.config.backoff_m, self.config.recover_speed,
                       arm_bumper_on_release=True)
