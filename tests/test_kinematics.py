"""Omni-drive kinematics against geometry (robot/body frame, SI units)."""
import numpy as np
import pytest

from robot.kinematics import (
    OmniDriveParams,
    forward_kinematics,
    heading_to_twist,
    integrate_pose,
    inverse_kinematics,
    saturate,
    twist_to_wheels,
)

P = OmniDriveParams()
RNG = np.random.default_rng(20240501)


def test_ik_then_fk_is_identity():
    twists = RNG.uniform([-0.5, -0.5, -3.0], [0.5, 0.5, 3.0], size=(200, 3))
    np.testing.assert_allclose(forward_kinematics(inverse_kinematics(twists, P), P), twists, atol=1e-12)
    wheels = RNG.uniform(-20, 20, size=(200, 3))
    np.testing.assert_allclose(inverse_kinematics(forward_kinematics(wheels, P), P), wheels, atol=1e-10)


def test_ik_fk_identity_for_unusual_geometry():
    p = OmniDriveParams(wheel_radius=0.05, base_radius=0.2, wheel_angles=(0.3, 2.0, 4.1))
    t = np.array([0.12, -0.31, 0.7])
    np.testing.assert_allclose(forward_kinematics(inverse_kinematics(t, p), p), t, atol=1e-12)


def test_pure_rotation_gives_equal_wheel_speeds():
    omega = 1.3
    w = inverse_kinematics([0.0, 0.0, omega], P)
    # Every wheel rolls on the circle of radius R: rim speed R*omega, angular speed R*omega/r.
    np.testing.assert_allclose(w, np.full(3, P.base_radius * omega / P.wheel_radius), rtol=1e-12)
    # ... and equal wheel speeds give a pure rotation back.
    np.testing.assert_allclose(forward_kinematics([5.0, 5.0, 5.0], P)[:2], 0.0, atol=1e-12)


def test_pure_translation_wheel_speeds_sum_to_zero():
    # Three wheels at 120 deg: the tangential directions sum to zero, so any pure translation does too.
    for az in np.linspace(-np.pi, np.pi, 13):
        w = inverse_kinematics(heading_to_twist(az, 0.3), P)
        assert abs(w.sum()) < 1e-12


def test_wheel_speed_is_rim_projection_of_contact_velocity():
    # Independent derivation: velocity of the contact point = v + omega x r_i, projected on the rolling direction.
    t = np.array([0.2, -0.1, 0.8])
    w = inverse_kinematics(t, P)
    for i, th in enumerate(P.wheel_angles):
        r_i = P.base_radius * np.array([np.cos(th), np.sin(th)])
        v_contact = t[:2] + t[2] * np.array([-r_i[1], r_i[0]])
        d_i = np.array([-np.sin(th), np.cos(th)])
        assert w[i] * P.wheel_radius == pytest.approx(v_contact @ d_i, abs=1e-12)


@pytest.mark.parametrize("i", [0, 1, 2])
def test_single_wheel_motion_matches_geometry(i):
    # One wheel turning at w, the other two still: for a symmetric 3-wheel base the body moves
    # 2/3 of the rim speed along that wheel's rolling direction and turns by rim/(3R).
    w = np.zeros(3)
    w[i] = 4.0
    rim = 4.0 * P.wheel_radius
    th = P.wheel_angles[i]
    vx, vy, om = forward_kinematics(w, P)
    assert vx == pytest.approx(-2.0 / 3.0 * rim * np.sin(th), abs=1e-12)
    assert vy == pytest.approx(2.0 / 3.0 * rim * np.cos(th), abs=1e-12)
    assert om == pytest.approx(rim / (3.0 * P.base_radius), rel=1e-12)
    # The other two wheels' contact points must not move along their rolling directions (they are still).
    back = inverse_kinematics([vx, vy, om], P)
    np.testing.assert_allclose(np.delete(back, i), 0.0, atol=1e-12)


def test_forward_motion_uses_front_wheels_opposite_and_rear_idle():
    # Wheels at 60 (front-left), 180 (rear), 300 (front-right): driving +x spins the front wheels
    # in opposite senses at equal magnitude and leaves the rear wheel (rolling along y) idle.
    w = inverse_kinematics([0.3, 0.0, 0.0], P)
    assert w[1] == pytest.approx(0.0, abs=1e-12)
    assert w[0] == pytest.approx(-w[2], rel=1e-12)
    assert w[0] == pytest.approx(-0.3 * np.sin(np.deg2rad(60)) / P.wheel_radius, rel=1e-12)


def test_saturation_keeps_direction_and_ratios():
    twists = RNG.uniform([-0.6, -0.6, -4.0], [0.6, 0.6, 4.0], size=(100, 3))
    raw = inverse_kinematics(twists, P)
    sat = saturate(raw, P.max_wheel_speed)
    peak = np.abs(raw).max(axis=1)
    assert np.all(np.abs(sat) <= P.max_wheel_speed + 1e-9)
    over = peak > P.max_wheel_speed
    assert over.any() and (~over).any()
    # Saturated rows are the raw rows scaled by one positive factor, so the wheel ratios are kept...
    scale = sat / raw
    np.testing.assert_allclose(scale[over], scale[over][:, :1] * np.ones((1, 3)), rtol=1e-9)
    assert np.all(scale[over] > 0)
    np.testing.assert_allclose(np.abs(sat[over]).max(axis=1), P.max_wheel_speed, rtol=1e-12)
    # ... and rows within the limit pass unchanged.
    np.testing.assert_array_equal(sat[~over], raw[~over])
    # ... and so is the body motion's direction (FK is linear): same heading, same curvature.
    tw_sat = forward_kinematics(sat, P)
    cos = np.sum(tw_sat * twists, axis=1) / (np.linalg.norm(tw_sat, axis=1) * np.linalg.norm(twists, axis=1))
    np.testing.assert_allclose(cos, 1.0, atol=1e-12)


def test_twist_to_wheels_saturates_and_zero_stays_zero():
    w = twist_to_wheels([5.0, 0.0, 0.0], P)
    assert np.abs(w).max() == pytest.approx(P.max_wheel_speed)
    np.testing.assert_array_equal(saturate(np.zeros(3), 1.0), np.zeros(3))


def test_heading_to_twist():
    np.testing.assert_allclose(heading_to_twist(np.pi / 2, 0.4, 0.1), [0.0, 0.4, 0.1], atol=1e-15)


def test_integrate_pose_straight_and_arc():
    # Straight line in a rotated frame.
    np.testing.assert_allclose(integrate_pose([1.0, 2.0, np.pi / 2], [0.5, 0.0, 0.0], 2.0), [1.0, 3.0, np.pi / 2],
                               atol=1e-12)
    # Constant forward speed v and turn rate w: a circle of radius v/w. After a quarter turn from the
    # origin heading +x, the robot is at (R, R) heading +y.
    v, om = 0.3, 0.6
    R = v / om
    np.testing.assert_allclose(integrate_pose([0, 0, 0], [v, 0.0, om], (np.pi / 2) / om), [R, R, np.pi / 2],
                               atol=1e-12)
    # Splitting the interval gives the same pose (exact arc integration).
    pose = np.zeros(3)
    for _ in range(10):
        pose = integrate_pose(pose, [0.1, 0.05, 0.4], 0.3)
    np.testing.assert_allclose(pose, integrate_pose([0, 0, 0], [0.1, 0.05, 0.4], 3.0), atol=1e-12)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="twist"):
        inverse_kinematics([1.0, 2.0])
    with pytest.raises(ValueError, match="wheel_speeds"):
        forward_kinematics([1.0, 2.0, 3.0, 4.0])
    with pytest.raises(ValueError, match="wheel_radius"):
        OmniDriveParams(wheel_radius=0.0)
