"""Kinematics of the three-wheel omni-directional drive (robot/body frame).

Wheel ``i`` sits at angle ``theta_i`` (CCW from +x) on a circle of radius
``base_radius``; its rolling direction is tangential, ``d_i = (-sin, cos)``,
so a positive wheel speed pushes the robot counter-clockwise around its
centre. For a body twist ``(vx, vy, omega)`` (m/s, m/s, rad/s) the rim speed
of wheel i is ``d_i . (vx, vy) + R * omega`` (Doroftei and Stirbu 2010;
Tajti et al. 2014) and its angular speed that divided by the wheel radius.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np


@dataclass(frozen=True)
class OmniDriveParams:
    """Geometry and limits of the three-wheel omni drive (SI units)."""

    wheel_radius: float = 0.05           # m (100 mm double-row omni wheels: 2 cm debris, 3.7 cm ground clearance)
    base_radius: float = 0.125           # m, centre to wheel contact
    wheel_angles: tuple[float, float, float] = field(
        default=(np.deg2rad(60.0), np.deg2rad(180.0), np.deg2rad(300.0))
    )                                    # rad, CCW from +x: front-left, rear, front-right
    max_wheel_speed: float = 20.0        # rad/s (~190 rpm gear motor at the wheel)

    def __post_init__(self) -> None:
        if not self.wheel_radius > 0:
            raise ValueError(f"wheel_radius must be > 0 m, got {self.wheel_radius}")
        if not self.base_radius > 0:
            raise ValueError(f"base_radius must be > 0 m, got {self.base_radius}")
        if len(self.wheel_angles) != 3:
            raise ValueError(f"wheel_angles must hold 3 angles (rad), got {len(self.wheel_angles)}")
        if not self.max_wheel_speed > 0:
            raise ValueError(f"max_wheel_speed must be > 0 rad/s, got {self.max_wheel_speed}")

    @property
    def jacobian(self) -> np.ndarray:
        """Matrix J with ``wheel_speeds = J @ (vx, vy, omega)``, shape (3, 3), units 1/m and 1."""
        return _matrices(self)[0].copy()


@lru_cache(maxsize=8)
def _matrices(params: OmniDriveParams) -> tuple[np.ndarray, np.ndarray]:
    """(J, J^-1) of ``params``, read-only; cached because odometry converts every encoder reading."""
    th = np.asarray(params.wheel_angles, dtype=float)
    j = np.stack([-np.sin(th), np.cos(th), np.full(3, params.base_radius)], axis=1) / params.wheel_radius
    # The inverse by cofactors (columns: cross products of J's rows over det J), not LAPACK: see _apply.
    cof = np.stack([np.cross(j[1], j[2]), np.cross(j[2], j[0]), np.cross(j[0], j[1])], axis=1)
    j_inv = cof / np.sum(j[0] * cof[:, 0])
    j.flags.writeable = j_inv.flags.writeable = False
    return j, j_inv


def _apply(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v @ m.T`` for ``v`` of shape (..., 3), rounded the same on every CPU.

    A BLAS matmul rounds by the kernel the CPU selects (with or without fused multiply-add); a wheel command one
    last bit apart is a different trajectory once contacts amplify it, so a simulated run would depend on the CPU.
    Elementwise products summed in a fixed order round the same everywhere."""
    p = v[..., None, :] * m
    return p[..., 0] + p[..., 1] + p[..., 2]


def inverse_kinematics(twist, params: OmniDriveParams = OmniDriveParams()) -> np.ndarray:
    """Body twist(s) ``(..., 3)`` -> wheel angular speeds ``(..., 3)`` in rad/s (no saturation)."""
    t = np.asarray(twist, dtype=float)
    if t.shape[-1] != 3:
        raise ValueError(f"twist must end in 3 values (vx, vy, omega), got shape {t.shape}")
    return _apply(_matrices(params)[0], t)


def forward_kinematics(wheel_speeds, params: OmniDriveParams = OmniDriveParams()) -> np.ndarray:
    """Wheel angular speeds ``(..., 3)`` rad/s -> body twist ``(..., 3)`` (vx, vy in m/s, omega in rad/s)."""
    w = np.asarray(wheel_speeds, dtype=float)
    if w.shape[-1] != 3:
        raise ValueError(f"wheel_speeds must end in 3 values, got shape {w.shape}")
    return _apply(_matrices(params)[1], w)


def saturate(wheel_speeds, max_speed: float) -> np.ndarray:
    """Scale all wheels by one factor so none exceeds ``max_speed``: keeps the direction of motion."""
    w = np.asarray(wheel_speeds, dtype=float)
    peak = np.max(np.abs(w), axis=-1, keepdims=True)
    scale = np.where(peak > max_speed, max_speed / np.maximum(peak, 1e-300), 1.0)
    return w * scale


def twist_to_wheels(twist, params: OmniDriveParams = OmniDriveParams()) -> np.ndarray:
    """Inverse kinematics followed by direction-keeping saturation at ``params.max_wheel_speed``."""
    return saturate(inverse_kinematics(twist, params), params.max_wheel_speed)


def heading_to_twist(azimuth: float, speed: float, omega: float = 0.0) -> np.ndarray:
    """Translate along ``azimuth`` (rad, CCW from +x, robot frame) at ``speed`` m/s."""
    return np.array([speed * np.cos(azimuth), speed * np.sin(azimuth), omega])


def integrate_pose(pose, twist, dt: float) -> np.ndarray:
    """Advance a planar world pose ``(x, y, yaw)`` by a body-frame twist held for ``dt`` s (exact arc)."""
    x, y, yaw = (float(v) for v in pose)
    vx, vy, om = (float(v) for v in twist)
    if abs(om) < 1e-9:
        dx, dy = vx * dt, vy * dt
    else:
        s, c = np.sin(om * dt), np.cos(om * dt)
        dx = (vx * s - vy * (1 - c)) / om
        dy = (vx * (1 - c) + vy * s) / om
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.array([x + cy * dx - sy * dy, y + sy * dx + cy * dy, yaw + om * dt])
