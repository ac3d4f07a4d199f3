"""The robot driving in rubble: stability, no tunnelling, climbing small debris, HAL backends."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from robot.hal import DriveStatus, WheelOdometry
from robot.ranging import RangeLayout
from ssl_sim.physics import RobotModelConfig, SimClock, SimDriveBase, SimRobot, load_scene
from ssl_sim.world import Box, Room, World

CFG = RobotModelConfig()


def _robot_points(robot: SimRobot) -> np.ndarray:
    """World points that must never be inside an obstacle: bumper ring, wheel axles, chassis centre."""
    p = robot.pose()
    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    r = CFG.bumper_radius - 0.01
    ring = np.column_stack([r * np.cos(ang), r * np.sin(ang), np.full(16, np.mean(CFG.bumper_z))])
    th = np.asarray(CFG.drive.wheel_angles)
    wheels = np.column_stack([CFG.drive.base_radius * np.cos(th), CFG.drive.base_radius * np.sin(th),
                              np.full(3, CFG.drive.wheel_radius)])
    local = np.vstack([ring, wheels, [[0, 0, CFG.deck_z]], [[0, 0, CFG.array_height]]])
    return local @ p.rotation.T + [p.x, p.y, p.z]


def test_60_s_of_random_driving_in_dense_rubble_is_stable_and_solid():
    world = load_scene("dense_collapsed_room")
    robot = SimRobot(world)
    rng = np.random.default_rng(2024)
    blocking = [i for i, b in enumerate(world.obstacles) if not b.climbable]
    points, tilts, min_dist = [], [], 0.0
    debris_contacts = bumper_samples = 0
    path = 0.0
    last = np.array(world.robot_start[:2])
    for second in range(60):
        robot.set_twist(*rng.uniform([-0.35, -0.35, -1.2], [0.35, 0.35, 1.2]))
        for _ in range(20):
            robot.step(0.05)  # raises PhysicsError on NaN or MuJoCo instability warnings
            p = robot.pose()
            assert np.all(np.isfinite(robot.data.qpos)) and np.all(np.isfinite(robot.data.qvel))
            tilts.append(p.tilt)
            points.append(_robot_points(robot))
            d = robot.data
            if d.ncon:
                min_dist = min(min_dist, float(d.contact.dist[: d.ncon].min()))
            hits = robot.contacts()
            debris_contacts += any(c.obstacle is not None and world.obstacles[c.obstacle].climbable for c in hits)
            bumper_samples += robot.bumper()
            path += float(np.hypot(p.x - last[0], p.y - last[1]))
            last = np.array([p.x, p.y])
    assert robot.time == pytest.approx(60.0)
    assert all(v == 0 for v in robot.warning_counts().values())
    # It really drove around, over debris and into things.
    assert path > 5.0 and debris_contacts > 0 and bumper_samples > 0
    # Upright throughout: small debris tilts the robot by a few degrees only.
    assert np.degrees(max(tilts)) < 15.0
    # No tunnelling: contacts never sink deeper than 5 mm, and no point of the robot is ever inside a
    # wall, pillar, block or slab (shrunk by 5 mm) or outside the room.
    assert min_dist > -0.005
    pts = np.concatenate(points)
    assert np.all(world.room.contains(pts))
    for i in blocking:
        inside = world.obstacles[i].contains(pts, margin=-0.005)
        assert not inside.any(), f"robot inside obstacle {i} ({world.obstacles[i].kind})"


def _debris_world(height: float) -> World:
    step = Box(center=(1.65, 1.0, height / 2), size=(0.6, 1.6, height), kind="debris", climbable=True)
    return World(room=Room(size=(3.5, 2.0, 2.0)), obstacles=(step,), robot_start=(0.8, 1.0, 0.0))


@pytest.mark.parametrize("height, heading_deg", [(0.02, 30.0), (0.02, 90.0), (0.01, 0.0), (0.005, 60.0)])
def test_climbs_over_small_debris_and_stays_upright(height, heading_deg):
    """Omni wheels climb a step with their rolling direction, not sideways on their small rollers:
    2 cm is crossed at headings between the axles (30, 90, ... deg), 1 cm at nearly any heading,
    5 mm at every heading (see robot_model docs)."""
    world = _debris_world(height)
    a = np.deg2rad(heading_deg)
    # Turn the robot so that driving along ``heading`` in its frame moves it along world +x.
    robot = SimRobot(world, start=(0.8, 1.0, -a))
    robot.set_twist(0.3 * np.cos(a), 0.3 * np.sin(a), 0.0)
    zs, tilts, xs = [], [], []
    for _ in range(650):
        robot.step(0.01)
        p = robot.pose()
        zs.append(p.z)
        tilts.append(p.tilt)
        xs.append(p.x)
    assert xs[-1] > 1.65 + 0.3 + CFG.bumper_radius       # crossed the whole piece
    assert max(zs) == pytest.approx(height, abs=0.004)    # on top of it on the way
    assert abs(zs[-1]) < 2e-3                             # back on the floor
    assert np.degrees(max(tilts)) < 12.0


def test_a_wheel_pushed_sideways_into_a_2_cm_step_gets_stuck():
    """Physics, not a bug: the 20 mm rollers cannot climb a 2 cm edge along the wheel axle. The
    other wheels slip and keep turning, so the encoders alone do not reveal that the robot is stuck."""
    world = _debris_world(0.02)
    a = np.deg2rad(60.0)
    robot = SimRobot(world, start=(0.8, 1.0, -a))
    robot.set_twist(0.3 * np.cos(a), 0.3 * np.sin(a), 0.0)
    robot.step(1.5)
    x0, turned0 = robot.pose().x, robot.wheel_odometry().wheel_angles
    robot.step(1.5)
    assert robot.pose().x == pytest.approx(x0, abs=0.01)
    assert robot.pose().x < 1.35 - CFG.drive.base_radius + 0.05  # wheel 0 at the step's edge
    assert np.abs(robot.wheel_odometry().wheel_angles - turned0).max() > 3.0  # rad: wheels slipping
    assert robot.pose().tilt < np.deg2rad(5)


def test_drive_reports_a_stall_when_the_motors_cannot_turn_the_wheels():
    """With weak motors (0.1 N m < roller traction x wheel radius) pushing into a wall the wheels stop."""
    weak = RobotModelConfig(motor_max_torque=0.1)
    world = World(room=Room(size=(2.0, 2.0, 2.0)), robot_start=(1.0, 1.0, 0.0))
    robot = SimRobot(world, weak)
    drive, clock = SimDriveBase(robot), SimClock(robot)
    drive.set_twist(0.3, 0.0, 0.0)
    clock.sleep(0.5)
    assert not drive.status().stalled   # moving freely
    states = []
    for _ in range(40):
        clock.sleep(0.1)
        states.append(drive.status())
    assert states[-1].stalled and states[-1].bumper
    drive.stop()
    assert not drive.status().stalled


def test_same_commands_same_trajectory():
    world = load_scene("light_rubble")
    runs = []
    for _ in range(2):
        r = SimRobot(world)
        rng = np.random.default_rng(7)
        for _ in range(5):
            r.set_twist(*rng.uniform([-0.3, -0.3, -1.0], [0.3, 0.3, 1.0]))
            r.step(0.5)
        runs.append(np.concatenate([r.data.qpos, r.data.qvel]))
    np.testing.assert_array_equal(runs[0], runs[1])


def test_hal_backends_drive_the_simulated_robot():
    world = World(room=Room(size=(3.0, 3.0, 2.5)), robot_start=(1.0, 1.5, 0.0))
    robot = SimRobot(world)
    clock = SimClock(robot)
    with SimDriveBase(robot) as drive:
        assert clock.now() == 0.0
        drive.set_twist(0.3, 0.0, 0.0)
        clock.sleep(1.0)
        assert clock.now() == pytest.approx(1.0)
        odo = drive.odometry()
        assert isinstance(odo, WheelOdometry) and odo.timestamp == pytest.approx(1.0)
        assert robot.pose().x > 1.2
        st = drive.status()  # driving straight: no bumper, no fault, the gyro sees (almost) no turn, every wall
        #                      is > 1 m away (beyond the range sensors' 0.8 m)
        assert replace(st, yaw_rate=None, ranges=None) == DriveStatus() and abs(st.yaw_rate) < 0.05
        assert st.ranges == (np.inf,) * RangeLayout().n
        clock.sleep(6.5)  # into the +x wall
        st = drive.status()
        assert st.bumper and not st.ok
        drive.stop()
        np.testing.assert_array_equal(robot.wheel_commands, 0.0)
        with pytest.raises(ValueError, match="set_twist"):
            drive.set_twist(np.nan, 0.0, 0.0)
    np.testing.assert_array_equal(robot.wheel_commands, 0.0)  # close() stops
