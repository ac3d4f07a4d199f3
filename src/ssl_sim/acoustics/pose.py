"""Where the microphones are: the cube array mounted on the robot, the robot posed in the world.

Frames (CONTEXT conventions): robot/body frame origin at the base centre on the ground,
+x forward, +y left, +z up; array frame origin at the cube centre, axes parallel to the
robot's. The array centre sits ``height_m`` above the body origin (plus an optional
horizontal offset). World pose = position of the body origin + yaw (about +z), pitch
(about +y, positive nose down) and roll (about +x), composed as ``R = Rz(yaw) Ry(pitch) Rx(roll)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from robot.mount import ArrayMount as RobotArrayMount
from ssl_core.geometry import ArrayGeometry, cube8


def rotation_matrix(yaw: float = 0.0, pitch: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """Body-to-world rotation ``Rz(yaw) @ Ry(pitch) @ Rx(roll)`` (angles in rad)."""
    cy, sy = np.cos(yaw), np.sin(yaw)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cr, sr = np.cos(roll), np.sin(roll)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return rz @ ry @ rx


@dataclass(frozen=True)
class RobotPose:
    """Body origin ``(x, y, z)`` in the world (m) and attitude ``yaw, pitch, roll`` (rad)."""

    x: float
    y: float
    z: float = 0.0
    yaw: float = 0.0
    pitch: float = 0.0
    roll: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x", "y", "z", "yaw", "pitch", "roll"):
            v = getattr(self, name)
            if not np.isfinite(v):
                raise ValueError(f"RobotPose.{name}: expected a finite number, got {v!r}")

    @property
    def rotation(self) -> np.ndarray:
        return rotation_matrix(self.yaw, self.pitch, self.roll)

    @property
    def position(self) -> np.ndarray:
        return np.array([self.x, self.y, self.z])


@dataclass(frozen=True)
class ArrayMount(RobotArrayMount):
    """The array on the simulated robot: the behaviour's ``robot.mount.ArrayMount`` (cube centre ``height_m`` above
    the body origin) with what only the simulator needs: the ``geometry`` (array frame) and ``offset_xy_m``
    forward/left of the body origin (robot frame, m).

    ``build_error_m``: standard deviation (per axis, m) of where each capsule really sits relative
    to the nominal geometry - a hand-built cube is off by millimetres; the localizer only knows
    the nominal positions. The error is fixed per ``build_seed`` (one physical array)."""

    geometry: ArrayGeometry = field(default_factory=cube8)
    offset_xy_m: tuple[float, float] = (0.0, 0.0)
    build_error_m: float = 0.0
    build_seed: int = 0

    def __post_init__(self) -> None:
        if not np.isfinite(self.height_m) or self.height_m <= 0:
            raise ValueError(f"ArrayMount.height_m: expected a height > 0 m, got {self.height_m}")
        if not np.isfinite(self.build_error_m) or not 0 <= self.build_error_m <= 0.02:
            raise ValueError(f"ArrayMount.build_error_m: expected 0..0.02 m, got {self.build_error_m}")

    @property
    def actual_positions(self) -> np.ndarray:
        """Capsule positions as built (array frame, m): nominal + fixed build error."""
        pos = np.asarray(self.geometry.positions, float)
        if self.build_error_m == 0:
            return pos
        rng = np.random.default_rng([int(self.build_seed) & 0xFFFFFFFF, 0xB17D])
        return pos + rng.normal(0.0, self.build_error_m, pos.shape)

    @property
    def centre_in_body(self) -> np.ndarray:
        return np.array([self.offset_xy_m[0], self.offset_xy_m[1], self.height_m])

    def centre_world(self, pose: RobotPose) -> np.ndarray:
        """Array centre in world coordinates (m)."""
        return pose.position + pose.rotation @ self.centre_in_body

    def mic_positions_world(self, pose: RobotPose) -> np.ndarray:
        """Microphone positions in world coordinates, shape (n_mics, 3) m."""
        r = pose.rotation
        return self.actual_positions @ r.T + (pose.position + r @ self.centre_in_body)

    def direction_in_array_frame(self, pose: RobotPose, point_world) -> tuple[float, float, float]:
        """Azimuth, elevation (rad) and distance (m) of a world point seen from the array centre, array frame."""
        d = pose.rotation.T @ (np.asarray(point_world, float) - self.centre_world(pose))
        r = float(np.linalg.norm(d))
        return float(np.arctan2(d[1], d[0])), float(np.arcsin(np.clip(d[2] / r, -1, 1))), r


def point_at(centre, azimuth: float, elevation: float, distance: float, rotation: np.ndarray | None = None) -> np.ndarray:
    """World point at ``distance`` (m) from ``centre`` in direction (azimuth, elevation) (rad) of the
    frame rotated by ``rotation`` (array-to-world; identity if None)."""
    u = np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
    if rotation is not None:
        u = np.asarray(rotation) @ u
    return np.asarray(centre, float) + distance * u
