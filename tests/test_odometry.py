"""Dead reckoning from wheel encoders (odometry frame)."""
import numpy as np
import pytest

from robot.hal import WheelOdometry
from robot.kinematics import OmniDriveParams, inverse_kinematics
from robot.odometry import Odometry, wrap_angle

P = OmniDriveParams()


def _readings(twists_and_durations, dt=0.02, start_angles=(0.0, 0.0, 0.0)):
    """Encoder readings every ``dt`` s while each body twist is held for its duration."""
    angles = np.asarray(start_angles, float).copy()
    t = 0.0
    out = [WheelOdometry(t, angles.copy(), np.zeros(3))]
    for twist, duration in twists_and_durations:
        w = inverse_kinematics(twist, P)
        n = max(1, int(round(duration / dt)))
        for _ in range(n):  # n equal ticks of duration/n s (~dt)
            angles = angles + w * (duration / n)
            t += duration / n
            out.append(WheelOdometry(t, angles.copy(), w))
    return out


def _run(readings, start=(0.0, 0.0, 0.0)):
    odo = Odometry(P, start)
    for r in readings:
        odo.update(r)
    return odo


def test_first_reading_is_only_the_reference():
    odo = Odometry(P)
    odo.update(WheelOdometry(0.0, np.array([10.0, -3.0, 7.0]), np.zeros(3)))
    np.testing.assert_array_equal(odo.pose, [0.0, 0.0, 0.0])


def test_straight_line_in_rotated_start_frame():
    odo = _run(_readings([((0.2, 0.0, 0.0), 2.0)], start_angles=(5.0, 1.0, -2.0)), start=(1.0, 1.0, np.pi / 2))
    np.testing.assert_allclose(odo.pose, [1.0, 1.4, np.pi / 2], atol=1e-9)
    assert odo.distance == pytest.approx(0.4, rel=1e-9)


def test_circle_closed_form():
    # Forward speed v with turn rate w: a circle of radius v/w centred at (0, R).
    v, om = 0.25, 0.5
    R = v / om
    half = _run(_readings([((v, 0.0, om), np.pi / om)], dt=0.01))
    np.testing.assert_allclose(half.pose, [0.0, 2 * R, np.pi], atol=1e-9)
    assert half.distance == pytest.approx(np.pi * R, rel=1e-9)
    full = _run(_readings([((v, 0.0, om), 2 * np.pi / om)], dt=0.05))
    np.testing.assert_allclose(full.pose[:2], [0.0, 0.0], atol=1e-9)
    assert wrap_angle(full.pose[2]) == pytest.approx(0.0, abs=1e-9)


def test_pure_spin_stays_in_place():
    odo = _run(_readings([((0.0, 0.0, 1.0), np.pi)]))
    np.testing.assert_allclose(odo.pose, [0.0, 0.0, np.pi], atol=1e-9)
    assert odo.distance == pytest.approx(0.0, abs=1e-12)


def test_matches_fine_euler_integration_of_world_velocity():
    rng = np.random.default_rng(7)
    segments = [(tuple(rng.uniform([-0.3, -0.3, -1.5], [0.3, 0.3, 1.5])), 0.4) for _ in range(8)]
    odo = _run(_readings(segments, dt=0.1))
    # Independent reference: rotate the body velocity into the world each tiny step (Euler, dt = 1e-4 s).
    x = y = yaw = 0.0
    h = 1e-4
    for (vx, vy, om), dur in segments:
        for _ in range(int(round(dur / h))):
            c, s = np.cos(yaw + 0.5 * om * h), np.sin(yaw + 0.5 * om * h)
            x += (c * vx - s * vy) * h
            y += (s * vx + c * vy) * h
            yaw += om * h
    np.testing.assert_allclose(odo.pose, [x, y, yaw], atol=1e-6)


def test_twist_from_wheel_speeds_and_reset():
    odo = Odometry(P)
    odo.update(WheelOdometry(0.0, np.zeros(3), inverse_kinematics([0.1, -0.2, 0.3], P)))
    np.testing.assert_allclose(odo.twist, [0.1, -0.2, 0.3], atol=1e-12)
    odo.update(WheelOdometry(1.0, np.ones(3), np.zeros(3)))
    assert odo.pose[2] != 0.0
    odo.reset((2.0, 3.0, 0.5))
    np.testing.assert_array_equal(odo.pose, [2.0, 3.0, 0.5])
    odo.update(WheelOdometry(2.0, np.full(3, 9.0), np.zeros(3)))  # new reference, no jump
    np.testing.assert_array_equal(odo.pose, [2.0, 3.0, 0.5])


def test_bad_readings_are_named():
    odo = Odometry(P)
    with pytest.raises(ValueError, match="wheel_angles"):
        odo.update(WheelOdometry(0.0, np.zeros(2), np.zeros(3)))
    odo.update(WheelOdometry(1.0, np.zeros(3), np.zeros(3)))
    with pytest.raises(ValueError, match="timestamp"):
        odo.update(WheelOdometry(0.5, np.zeros(3), np.zeros(3)))
    with pytest.raises(ValueError, match="pose"):
        Odometry(P, (0.0, 0.0))


def test_wrap_angle():
    assert wrap_angle(3 * np.pi / 2) == pytest.approx(-np.pi / 2)
    np.testing.assert_allclose(wrap_angle([0.1, -7.0]), [0.1, -7.0 + 2 * np.pi])
