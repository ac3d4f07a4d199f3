"""Infrared range sensors around the chassis: where they sit and where their readings end.

The robot carries ``len(azimuths_rad)`` Sharp GP2Y0A21YK0F-class infrared distance sensors (datasheet: 10-80 cm,
a narrow beam, a new reading every 38.3 +- 9.6 ms), looking out horizontally from a ring of radius
``mount_radius_m`` at ``height_m`` above the floor (robot frame: the floor under the wheels is z = 0). The ring
lies inside the bumper (radius 0.16 m) so that the sensor's 10 cm dead zone, where its output folds back, ends at
the bumper: anything the bumper has not touched is at least ``min_range_m`` away. ``height_m`` is the middle of
the bumper band (0.045-0.11 m): what the rays see, the bumper would hit, and flat slabs 9-10 cm thick (which
the bumper meets and the wheels cannot climb) are seen. So low, a ray must not pass a wheel: the sensors look
every 30 deg but toward the three wheels (60, 180, 300 deg), keeping 30 deg (6 cm at the wheel) clear of them.

Both HAL sides report the same thing (``robot.hal.DriveStatus.ranges``): the distance (m) from each sensor along
its ray to the first surface, ``math.inf`` when nothing is within ``max_range_m``. The firmware converts the
sensors' voltages (firmware/src/ranges.c); the simulator casts MuJoCo rays (ssl_sim.physics.sim_drive).

Frames: azimuths in the ROBOT frame (rad, CCW from +x forward); ``ray_ends`` returns world-frame points.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robot.config_values import need

__all__ = ["RangeLayout", "ray_ends"]


@dataclass(frozen=True)
class RangeLayout:
    """Where the range sensors sit on the robot (robot frame, SI units)."""

    azimuths_rad: tuple[float, ...] = tuple(math.radians(a) for a in (0, 30, 90, 120, 150, 210, 240, 270, 330))
    mount_radius_m: float = 0.06     # ray origins: 0.06 m + the 0.10 m dead zone = the bumper's 0.16 m
    height_m: float = 0.075          # above the floor: the middle of the bumper band
    min_range_m: float = 0.10        # GP2Y0A21YK0F datasheet: 10 cm ...
    max_range_m: float = 0.80        # ... to 80 cm

    def __post_init__(self) -> None:
        need(self, len(self.azimuths_rad) >= 1, "azimuths_rad", "at least one sensor")
        need(self, all(math.isfinite(a) for a in self.azimuths_rad), "azimuths_rad", "finite angles (rad)")
        need(self, self.mount_radius_m >= 0, "mount_radius_m", ">= 0 m")
        need(self, self.height_m > 0, "height_m", "> 0 m")
        need(self, 0 <= self.min_range_m < self.max_range_m, "min_range_m", "in [0, max_range_m)")

    @property
    def n(self) -> int:
        return len(self.azimuths_rad)

    def check(self, ranges) -> np.ndarray:
        """``ranges`` as a float array of one reading per sensor (m, ``inf`` = no return), or a ValueError."""
        r = np.asarray(ranges, float)
        if r.shape != (self.n,):
            raise ValueError(f"ranges: expected {self.n} readings (one per sensor), got shape {r.shape}")
        if np.isnan(r).any() or (r < 0).any():
            raise ValueError(f"ranges: expected distances >= 0 m or inf, got {r.tolist()}")
        return r


def ray_ends(layout: RangeLayout, pose, ranges) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World-frame rays of one reading taken at ``pose`` (x, y, yaw; world m, rad).

    Returns ``starts`` (n, 2), ``ends`` (n, 2) and ``hit`` (n,): a ray with a return ends at the surface it saw
    (``hit``); one without ends at ``max_range_m`` (free floor up to there, nothing seen)."""
    r = layout.check(ranges)
    x, y, yaw = (float(v) for v in pose[:3])
    az = yaw + np.asarray(layout.azimuths_rad, float)
    u = np.stack([np.cos(az), np.sin(az)], axis=1)
    starts = np.array([x, y]) + layout.mount_radius_m * u
    hit = np.isfinite(r) & (r <= layout.max_range_m)
    ends = starts + np.where(hit, r, layout.max_range_m)[:, None] * u
    return starts, ends, hit


#: Readings go into the grid once per 5 cm of travel or 10 deg of turn: readings from one spot repeat one error
#: (a tilted ray on the same floor), and control ticks are 1.25 cm apart.
SCAN_SPACING_M = 0.05
SCAN_TURN = math.radians(10.0)


class RangeScans:
    """Feeds range readings into an occupancy grid (anything with ``mark_rays(starts, ends, hit)``), thinned to
    one per ``SCAN_SPACING_M`` of travel or ``SCAN_TURN`` of turn. Call it with each (pose, status) of a move;
    ``force=True`` takes a reading whatever the spacing (the one that stopped a move)."""

    def __init__(self, grid, layout: RangeLayout) -> None:
        self.grid, self.layout = grid, layout
        self._last: np.ndarray | None = None

    def __call__(self, pose, status, force: bool = False) -> None:
        if status.ranges is None:
            return
        last = self._last
        if not force and last is not None and math.hypot(pose[0] - last[0], pose[1] - last[1]) < SCAN_SPACING_M \
                and abs(math.remainder(pose[2] - last[2], 2 * math.pi)) < SCAN_TURN:
            return
        self._last = np.array(pose[:3], float)
        self.grid.mark_rays(*ray_ends(self.layout, pose, status.ranges))
