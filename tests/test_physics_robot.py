"""The MuJoCo omni robot on flat ground: geometry, drive kinematics, sensors.

Truth comes from ssl_core's cube8 geometry and robot.kinematics (inverse/forward kinematics,
exact arc integration), not from recorded simulator output.
"""
from __future__ import annotations

import mujoco
import numpy as np
import pytest

from robot.kinematics import OmniDriveParams, forward_kinematics, integrate_pose
from ssl_core.geometry import cube8
from ssl_sim.physics import PhysicsError, RobotModelConfig, SimRobot, robot_spec
from ssl_sim.physics import robot_model as rm
from ssl_sim.physics.scenes import MODELS_DIR
from ssl_sim.world import Room, World

CFG = RobotModelConfig()


@pytest.fixture(scope="module")
def robot() -> SimRobot:
    return SimRobot()


def _mic_sites_in_array_frame(model: mujoco.MjModel) -> np.ndarray:
    arr = model.body(rm.ARRAY_BODY).id
    out = []
    for i in range(8):
        s = model.site(rm.mic_site(i))
        assert model.site_bodyid[s.id] == arr, "mic sites must be fixed in the array body"
        out.append(model.site_pos[s.id])
    return np.array(out)


def test_model_uses_the_project_drive_parameters():
    assert CFG.drive == OmniDriveParams()  # one source of truth for the firmware, odometry and the sim
    m = robot_spec().compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    for i, th in enumerate(CFG.drive.wheel_angles):
        p = d.xpos[m.body(f"wheel{i}").id]
        np.testing.assert_allclose(p[:2], CFG.drive.base_radius * np.array([np.cos(th), np.sin(th)]), atol=1e-9)
        assert p[2] == pytest.approx(CFG.drive.wheel_radius)
        lo, hi = m.actuator_ctrlrange[m.actuator(rm.WHEEL_ACTUATORS[i]).id]
        assert hi == pytest.approx(CFG.drive.max_wheel_speed) and lo == pytest.approx(-CFG.drive.max_wheel_speed)
        assert m.actuator_forcerange[m.actuator(rm.WHEEL_ACTUATORS[i]).id][1] == pytest.approx(CFG.motor_max_torque)
    assert sum(m.body_mass) == pytest.approx(CFG.total_mass)
    # The base moves only through contacts: one free joint, every other joint a hinge (wheels, rollers).
    types = m.jnt_type
    assert list(types).count(mujoco.mjtJoint.mjJNT_FREE) == 1
    assert np.all(types[1:] == mujoco.mjtJoint.mjJNT_HINGE)
    assert m.njnt == 1 + 3 + 3 * 2 * CFG.rollers_per_row
    # Rollers follow the wheel circle: lowest point of every roller row is wheel_radius from the axle.
    a, b = CFG.roller_semi_axes
    assert (CFG.drive.wheel_radius - b) + b == pytest.approx(CFG.drive.wheel_radius)


def test_mic_sites_match_cube8_in_array_frame():
    m = robot_spec().compile()
    np.testing.assert_allclose(_mic_sites_in_array_frame(m), cube8().positions, atol=1e-3)
    assert m.body_pos[m.body(rm.ARRAY_BODY).id] == pytest.approx([0, 0, CFG.array_height])
    np.testing.assert_allclose(m.body_quat[m.body(rm.ARRAY_BODY).id], [1, 0, 0, 0])


def test_shipped_robot_xml_matches_cube8_and_the_generator():
    path = MODELS_DIR / "omni_robot.xml"
    m_file = mujoco.MjModel.from_xml_path(str(path))
    m_gen = robot_spec().compile()
    np.testing.assert_allclose(_mic_sites_in_array_frame(m_file), cube8().positions, atol=1e-3)
    assert (m_file.nq, m_file.nv, m_file.nu, m_file.nsensor) == (m_gen.nq, m_gen.nv, m_gen.nu, m_gen.nsensor)
    np.testing.assert_allclose(m_file.body_mass, m_gen.body_mass, rtol=1e-6)


def test_rests_on_its_wheels_at_ground_level(robot):
    robot.reset()
    robot.step(0.5)
    p = robot.pose()
    assert abs(p.z) < 1e-3 and p.tilt < np.deg2rad(0.5)
    origin, rot = robot.array_pose()
    assert origin[2] == pytest.approx(CFG.array_height, abs=2e-3)
    assert CFG.ground_clearance >= 0.03


def test_mic_world_positions_follow_the_robot(robot):
    robot.reset()
    before = robot.mic_positions()
    robot.set_twist(0.25, 0.1, 0.8)
    robot.step(1.5)
    p = robot.pose()
    after = robot.mic_positions()
    assert np.linalg.norm(after - before, axis=1).min() > 0.1
    expected = cube8().transformed(p.rotation, np.array([p.x, p.y, p.z]) + p.rotation @ [0, 0, CFG.array_height])
    np.testing.assert_allclose(after, expected, atol=1e-3)
    origin, rot = robot.array_pose()
    np.testing.assert_allclose(cube8().transformed(rot, origin), after, atol=1e-6)


TWISTS = [
    (0.3, 0.0, 0.0),
    (0.0, 0.3, 0.0),
    (-0.2, -0.2, 0.0),
    (0.0, 0.0, 1.2),
    (0.0, 0.0, -0.6),
    (0.25, -0.1, 0.6),
    (-0.15, 0.3, -1.0),
]


@pytest.mark.parametrize("twist", TWISTS)
def test_commanded_twist_is_tracked_within_5_percent(robot, twist):
    robot.reset()
    robot.set_twist(*twist)
    robot.step(0.5)  # transient: motors reach speed within ~0.1 s
    samples = []
    for _ in range(150):
        robot.step(0.01)
        samples.append(robot.body_twist())
    meas = np.mean(samples, axis=0)
    v_cmd, w_cmd = np.hypot(*twist[:2]), twist[2]
    if v_cmd > 0:
        assert np.linalg.norm(meas[:2] - twist[:2]) <= 0.05 * v_cmd, (twist, meas)
    else:
        assert np.linalg.norm(meas[:2]) < 0.01
    if w_cmd != 0:
        assert abs(meas[2] - w_cmd) <= 0.05 * abs(w_cmd), (twist, meas)
    else:
        assert abs(meas[2]) < 0.02
    assert robot.pose().tilt < np.deg2rad(2)


def test_twist_beyond_the_motor_limit_keeps_its_direction(robot):
    robot.reset()
    cmd = robot.set_twist(2.0, 1.0, 0.0)  # far above 20 rad/s * 5 cm = 1 m/s rim speed
    assert np.abs(cmd).max() == pytest.approx(CFG.drive.max_wheel_speed)
    robot.step(1.0)
    v = np.mean([robot.body_twist() for _ in range(20) if robot.step(0.01) is None], axis=0)
    assert np.arctan2(v[1], v[0]) == pytest.approx(np.arctan2(1.0, 2.0), abs=np.deg2rad(3))
    assert np.hypot(v[0], v[1]) < 1.0


def _dead_reckoning_drive(robot: SimRobot, ramp: bool) -> tuple[float, float, float]:
    """Drive 10 s through five twists; dead-reckon from the encoders (forward kinematics, exact arcs
    at 100 Hz). Returns (position error m, yaw error rad, path length m) against ground truth."""
    robot.reset()
    p0 = robot.pose()
    est = np.array([p0.x, p0.y, p0.yaw])
    plan = [(0.3, 0.0, 0.0), (0.2, 0.15, 0.5), (0.0, -0.3, 0.0), (-0.2, 0.1, -0.8), (0.3, 0.0, 0.4)]
    dt, path, cmd = 0.01, 0.0, np.zeros(3)
    rate = np.array([1.0, 1.0, 3.0]) * dt   # ramp: 1 m/s^2, 3 rad/s^2
    prev = robot.wheel_odometry().wheel_angles
    for k in range(1000):
        target = np.array(plan[k // 200])
        cmd = cmd + np.clip(target - cmd, -rate, rate) if ramp else target
        robot.set_twist(*cmd)
        before = robot.pose()
        robot.step(dt)
        after = robot.pose()
        path += np.hypot(after.x - before.x, after.y - before.y)
        ang = robot.wheel_odometry().wheel_angles
        est = integrate_pose(est, forward_kinematics((ang - prev) / dt, CFG.drive), dt)
        prev = ang
    p = robot.pose()
    return float(np.hypot(est[0] - p.x, est[1] - p.y)), float(abs(np.angle(np.exp(1j * (est[2] - p.yaw))))), path


def test_wheel_odometry_agrees_with_the_simulated_pose_over_10_s(robot):
    """Ramped commands (as a motor controller does): wheels roll without slip, odometry drifts
    ~2 mm and ~0.05 deg over ~2.5 m (bench_physics). Step commands: the 1 N m motors out-pull the
    rollers' traction while accelerating, the wheels slip and dead reckoning drifts ~4.5 cm and
    ~2.4 deg; that is physics, not a model error, so it gets a looser bound."""
    pos_err, yaw_err, path = _dead_reckoning_drive(robot, ramp=True)
    assert path > 2.5
    assert pos_err < 0.005 * path, f"odometry drift {pos_err:.4f} m over {path:.2f} m"
    assert yaw_err < np.deg2rad(1.0), f"yaw drift {np.degrees(yaw_err):.2f} deg"
    pos_err, yaw_err, path = _dead_reckoning_drive(robot, ramp=False)
    assert pos_err < 0.03 * path, f"odometry drift {pos_err:.4f} m over {path:.2f} m"
    assert yaw_err < np.deg2rad(5.0), f"yaw drift {np.degrees(yaw_err):.2f} deg"


def test_encoder_and_imu_sensors(robot):
    robot.reset()
    robot.step(0.3)
    imu = robot.imu()
    np.testing.assert_allclose(imu.accel, [0, 0, 9.81], atol=0.05)   # specific force at rest
    np.testing.assert_allclose(imu.gyro, 0, atol=1e-2)
    robot.set_twist(0.0, 0.0, 1.0)
    robot.step(1.0)
    imu = robot.imu()
    assert imu.gyro[2] == pytest.approx(robot.body_twist()[2], abs=1e-3)
    # The yaw rate ripples by ~9 % as contact alternates between the two roller rows; on average it is 1 rad/s.
    rates = [robot.imu().gyro[2] for _ in range(50) if robot.step(0.01) is None]
    assert np.mean(rates) == pytest.approx(1.0, rel=0.03)
    np.testing.assert_allclose(np.abs(robot.imu().quat @ robot.pose().quat), 1.0, atol=1e-9)  # same orientation
    odo = robot.wheel_odometry()
    enc = np.array([robot.sensor(f"enc_pos{i}")[0] for i in range(3)])
    np.testing.assert_allclose(enc, odo.wheel_angles)
    np.testing.assert_allclose([robot.sensor(f"enc_vel{i}")[0] for i in range(3)], odo.wheel_speeds)
    assert odo.timestamp == pytest.approx(robot.time)
    with pytest.raises(ValueError, match="unknown sensor"):
        robot.sensor("lidar")


def test_bumper_and_contacts_when_driving_into_a_wall():
    world = World(room=Room(size=(3.0, 3.0, 2.5)), robot_start=(1.5, 1.5, 0.0))
    r = SimRobot(world)
    r.step(0.2)
    assert not r.bumper() and r.contacts() == []
    r.set_twist(0.4, 0.0, 0.0)
    r.step(4.5)  # would travel 1.8 m; the wall is 1.5 - 0.16 m ahead of the bumper
    hits, closed = [], []
    for _ in range(20):  # pressed against the wall, the contact chatters at sub-mm scale: sample 0.1 s
        r.step(0.005)
        hits += r.contacts()
        closed.append(r.bumper())
    assert all(closed)
    assert hits and {c.world_geom for c in hits} == {"room_wall_xmax"}
    assert {c.robot_geom for c in hits} == {"bumper"}
    assert all(c.obstacle is None for c in hits)
    assert r.pose().x < 3.0 - CFG.bumper_radius + 0.005   # did not pass through the wall
    torque = np.array([r.sensor(f"motor_torque{i}")[0] for i in range(3)])
    assert np.all(np.abs(torque) <= CFG.motor_max_torque + 1e-9)
    assert np.abs(torque).max() == pytest.approx(CFG.motor_max_torque)  # stalled motor saturates


def test_step_keeps_simulated_time_with_requested_time(robot):
    robot.reset()
    for _ in range(100):
        robot.step(0.003)  # 1.2 physics steps each
    assert robot.time == pytest.approx(0.3, abs=robot.timestep / 2)
    robot.step()
    assert robot.time == pytest.approx(0.3 + robot.timestep, abs=robot.timestep / 2)
    with pytest.raises(ValueError, match="duration"):
        robot.step(-1.0)


def test_bad_input_and_instability_are_reported(robot):
    with pytest.raises(ValueError, match="wheel_speeds"):
        robot.set_wheel_speeds([1.0, np.nan, 0.0])
    with pytest.raises(ValueError, match="timestep"):
        SimRobot(timestep=0.01)
    robot.reset()
    robot.data.qvel[0] = np.inf
    with pytest.raises(PhysicsError):
        robot.step(0.01)
    robot.reset()


def test_parked_robot_skips_the_physics_until_commanded():
    parked, stepped = SimRobot(park_settled=True), SimRobot()
    for r in (parked, stepped):
        r.step(1.0)  # settle on the wheels
    p0 = parked.pose()
    parked.step(2.0)
    p1 = parked.pose()
    assert parked.time == pytest.approx(3.0, abs=1e-9)      # time goes on
    assert (p1.x, p1.y, p1.yaw) == (p0.x, p0.y, p0.yaw)    # the state does not
    # Commanded again, it drives like the robot that was stepped all along (the same twist, the same 1 s).
    moved = []
    for r in (parked, stepped):
        q = r.pose()
        r.set_twist(0.2, 0.0, 0.0)
        r.step(1.0)
        moved.append(float(np.hypot(r.pose().x - q.x, r.pose().y - q.y)))
    assert moved[0] == pytest.approx(moved[1], rel=0.01)
    assert moved[0] > 0.15


def test_mean_yaw_rate_is_the_yaw_change_over_the_window():
    """The gyro's window mean: the base's yaw (read from the pose after every step, unwrapped) interpolated
    linearly between step ends at the window's two ends, over its length; for windows inside the log, reaching
    before it, and ending between step ends, while the robot spins through +-pi."""
    r = SimRobot()
    r.set_twist(0.0, 0.0, 2.5)
    times, yaws = [r.time], [r.pose().yaw]
    for k in range(400):
        r.step(0.0075 if k % 3 else 0.01)   # uneven step lengths, as control ticks and audio chunks make them
        times.append(r.time)
        yaws.append(r.pose().yaw)
    yaws = np.unwrap(yaws)
    assert yaws[-1] - yaws[0] > 2 * np.pi   # turned more than once: the log unwraps across +-pi
    for window, end in [(0.1, None), (0.05, None), (0.1, times[-5] - 0.003), (0.02, times[-40] + 0.001), (5.0, None)]:
        t1 = times[-1] if end is None else end
        t0 = max(t1 - window, times[-len(r._yaw_log)])   # the log keeps the last 256 step ends
        expected = (np.interp(t1, times, yaws) - np.interp(t0, times, yaws)) / (t1 - t0)
        assert r.mean_yaw_rate(window, end) == pytest.approx(expected, rel=1e-9, abs=1e-12)
    assert 2.0 < r.mean_yaw_rate(0.1) < 2.6   # near the commanded rate (the motors track it within a few %)
