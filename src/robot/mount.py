"""Where the microphone array sits on the robot: the one place the behaviour, the sound map and the ego-noise
model take the array's height from.

The array is mounted level, its axes aligned with the robot's (array frame = robot frame, rotated), its centre
on the base's vertical axis ``height_m`` above the floor. The height turns a bearing's depression into a range on
the floor (range = (height - mouth height) / tan(depression)), so it must be the real robot's: on the simulated
robot it is the robot model's cube height, which the simulator passes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["ArrayMount"]


@dataclass(frozen=True)
class ArrayMount:
    """The array's mounting: centre ``height_m`` (m) above the floor, on the robot's vertical axis, level."""

    height_m: float = 0.30

    def __post_init__(self) -> None:
        if not (isinstance(self.height_m, (int, float)) and math.isfinite(self.height_m) and self.height_m > 0):
            raise ValueError(f"ArrayMount.height_m: expected a height > 0 m, got {self.height_m!r}")

    def bearing_to(self, pose, position) -> tuple[float, float]:
        """Array-frame azimuth (CCW from the robot's forward) and elevation (up), rad, of the world point
        ``position`` (x, y, z m) seen from the robot at ``pose`` (x m, y m, yaw rad), odometry frame."""
        x, y, yaw = (float(v) for v in pose)
        dx, dy = position[0] - x, position[1] - y
        az = (math.atan2(dy, dx) - yaw + math.pi) % (2 * math.pi) - math.pi   # [-pi, pi)
        return float(az), float(math.atan2(position[2] - self.height_m, math.hypot(dx, dy)))
