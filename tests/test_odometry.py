"""Dead reckoning from wheel encoders (odometry frame)."""
import numpy as np
import pytest

from robot.hal import DriveStatus, WheelOdometry
from robot.kinematics import OmniDriveParams, inverse_kinematics
from robot.odometry import GyroFusionConfig, Odometry, TravelConfig, wrap_angle

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


# ----------------------------------------------------------------------------- gyro fusion
def _true_rate_readings(true_twists, wheel_twists, dt=0.05):
    """Readings whose encoders follow ``wheel_twists`` while the base truly moves with ``true_twists``."""
    readings, rates = _readings(list(zip(wheel_twists, [dt] * len(wheel_twists))), dt=dt), [0.0]
    rates += [float(t[2]) for t in true_twists]
    return readings, rates


def test_gyro_rejects_wheel_slip_heading_and_travel():
    """Wheels spinning in place (+0.8 rad/s yaw, 0.2 m/s forward on the encoders) while the base is held:
    the gyro reads 0, so the heading stays and the false travel is dropped."""
    n = 40
    readings, rates = _true_rate_readings([(0, 0, 0.0)] * n, [(0.2, 0.0, 0.8)] * n)
    odo = Odometry(P)
    for r, w in zip(readings, rates):
        odo.update(r, w)
    np.testing.assert_allclose(odo.pose, [0, 0, 0], atol=1e-9)
    assert odo.slip_intervals == n
    wheel_only = _run(readings)
    assert abs(wheel_only.pose[2] - 0.8 * n * 0.05) < 1e-6


def test_gyro_bias_learnt_standing_still_then_integrated_out_while_slipping():
    """A 0.5 deg/s gyro bias, standstill readings with the spread the filter expects (seeded): learnt from 2 s of
    them (zero-velocity update); a slipping spin afterwards (wheels say +0.8 rad/s, the base truly turns 0.2 rad/s
    for 5 s) integrates the gyro without the bias. Readings while driving do not teach the bias: a later drive
    with the wheels disagreeing leaves it."""
    bias, noise = np.radians(0.5), GyroFusionConfig().rate_noise
    rng = np.random.default_rng(1)
    odo = Odometry(P)
    still, _ = _true_rate_readings([(0, 0, 0.0)] * 40, [(0, 0, 0.0)] * 40)
    for r in still:
        odo.update(r, bias + noise * rng.normal(), stationary=True)
    assert odo.bias_updates == 39                    # the first reading after the reference is one window still
    # 39 readings: the mean is within 3 sigma / sqrt(39) (the prior is 14x wider than the spread)
    assert abs(odo.gyro_bias - bias) < 3 * noise / np.sqrt(39)
    assert odo.gyro_bias_sigma < 1.1 * noise / np.sqrt(39)
    learnt = odo.gyro_bias
    slip, slip_rates = _true_rate_readings([(0, 0, 0.2)] * 100, [(0, 0, 0.8)] * 100)
    t0, a0 = still[-1].timestamp, still[-1].wheel_angles
    for r, w in zip(slip[1:], slip_rates[1:]):
        odo.update(WheelOdometry(t0 + r.timestamp, a0 + r.wheel_angles, r.wheel_speeds), w + bias)
    assert odo.pose[2] == pytest.approx(0.2 * 5.0, abs=5.0 * 3 * noise / np.sqrt(39))
    assert odo.slip_intervals == 100 and odo.gyro_bias == learnt and odo.bias_updates == 39


def test_no_bias_learnt_unless_commanded_and_wheels_stand():
    """Standstill readings teach the bias only when the caller says the drive stands AND the encoders agree."""
    odo = Odometry(P)
    still, _ = _true_rate_readings([(0, 0, 0.0)] * 10, [(0, 0, 0.0)] * 10)
    for r in still:                                  # the drive is not said to stand: no update
        odo.update(r, 0.01)
    assert odo.bias_updates == 0 and odo.gyro_bias == 0.0
    moving, rates = _true_rate_readings([(0.1, 0, 0.3)] * 10, [(0.1, 0, 0.3)] * 10)
    odo2 = Odometry(P)
    for r, w in zip(moving, rates):                  # said to stand, but the wheels turn (braking): no update
        odo2.update(r, w + 0.01, stationary=True)
    assert odo2.bias_updates == 0 and odo2.gyro_bias == 0.0
    assert odo2.pose[2] == pytest.approx(0.3 * 0.5 + 0.01 * 0.5, abs=1e-9)   # the gyro's heading, bias and all


def test_yaw_rate_must_be_finite():
    odo = Odometry(P)
    with pytest.raises(ValueError, match="yaw_rate"):
        odo.update(WheelOdometry(0.0, np.zeros(3), np.zeros(3)), float("nan"))


# ----------------------------------------------------------------------------- wheel load (commanded speeds)
def _drive(true_twist, wheel_speeds, n=40, dt=0.05):
    """The base truly moves with ``true_twist`` (the gyro reads its yaw rate) under the command ``true_twist``
    while the encoders turn at ``wheel_speeds`` (rad/s) for ``n`` control intervals; the odometry told the command
    as ``Motion`` tells it (at each command, and a stop at the last reading). Returns (commanded, uncommanded)."""
    told, blind = Odometry(P), Odometry(P)
    angles, t = np.zeros(3), 0.0
    for i in range(n + 1):
        r = WheelOdometry(t, angles.copy(), np.asarray(wheel_speeds, float))
        told.update(r, float(true_twist[2]))
        blind.update(r, float(true_twist[2]))
        told.commanded(t, true_twist if i < n else None)
        angles, t = angles + np.asarray(wheel_speeds, float) * dt, t + dt
    return told, blind


def test_free_rolling_wheels_keep_their_travel():
    """Wheels that track their command (0.1 rad/s off) carry the base: the same pose as without a command."""
    twist = (0.15, 0.1, 0.3)
    w = inverse_kinematics(twist, P) + np.array([0.1, -0.1, 0.05])
    told, blind = _drive(twist, w)
    np.testing.assert_allclose(told.pose, blind.pose, atol=1e-12)
    assert told.loaded_intervals == 0


def test_held_base_with_every_wheel_loaded_makes_no_travel():
    """Sideways at 0.2 m/s commanded (wheels 2 / -4 / 2 rad/s), the base held: every wheel turns at 40 % of its
    command (its speed loop straining against the load). The base truly stands; the wheels alone say 0.16 m."""
    w = 0.4 * inverse_kinematics((0.0, 0.2, 0.0), P)
    told, blind = _drive((0.0, 0.2, 0.0), w)
    np.testing.assert_allclose(told.pose, [0.0, 0.0, 0.0], atol=1e-12)
    assert told.loaded_intervals == 40 and told.slip_intervals == 0
    assert blind.pose[1] == pytest.approx(0.4 * 0.2 * 2.0, rel=1e-9)


def test_one_slipping_wheel_is_left_out_of_the_translation():
    """The base truly moves sideways at 0.2 m/s without turning, as commanded; wheel 0 spins 1.5 rad/s faster than
    it rolls (lifted on debris), so the wheels' yaw (+0.2 rad/s) disagrees with the gyro's (0): slip. The two wheels
    that track their commands, with the gyro's yaw, give the true motion exactly; without a command the slipping
    intervals' travel is dropped."""
    truth = (0.0, 0.2, 0.0)
    w = inverse_kinematics(truth, P) + np.array([1.5, 0.0, 0.0])
    told, blind = _drive(truth, w)
    np.testing.assert_allclose(told.pose, [0.0, 0.4, 0.0], atol=1e-9)
    assert told.slip_intervals == 40 and told.loaded_intervals == 40
    np.testing.assert_allclose(blind.pose, [0.0, 0.0, 0.0], atol=1e-9)


def test_one_free_wheel_gives_the_motion_along_its_rolling_direction():
    """Commanded and truly moving at (0.05, 0.3) m/s without turning, wheels 0 and 2 held to 40 % of their commands
    (2.1 and 3.9 rad/s: loaded); the rear wheel 1 rolls freely (rolling direction -y in the body frame). The
    translation is the true motion's component along -y (0.6 m in 2 s); the x part, which only the loaded wheels
    saw, is not credited."""
    truth = np.array([0.05, 0.3, 0.0])
    w = inverse_kinematics(truth, P) * np.array([0.4, 1.0, 0.4])
    told, _ = _drive(tuple(truth), w)
    np.testing.assert_allclose(told.pose, [0.0, 0.6, 0.0], atol=1e-9)


def test_command_is_averaged_over_the_interval():
    """A command that changes within a reading interval is compared by its time-weighted mean: wheels that follow
    a 0.1 -> 0.3 m/s step at mid-interval exactly (mean 0.2 m/s) are not loaded."""
    odo = Odometry(P)
    odo.update(WheelOdometry(0.0, np.zeros(3), np.zeros(3)), 0.0)
    odo.commanded(0.0, (0.0, 0.1, 0.0))
    odo.commanded(0.025, (0.0, 0.3, 0.0))
    w = inverse_kinematics((0.0, 0.2, 0.0), P)
    odo.update(WheelOdometry(0.05, w * 0.05, w), 0.0)
    assert odo.loaded_intervals == 0
    assert odo.pose[1] == pytest.approx(0.01, rel=1e-9)


def test_bad_travel_config_is_named():
    with pytest.raises(ValueError, match="loaded_speed"):
        TravelConfig(loaded_speed=0.0)
    with pytest.raises(ValueError, match="twist"):
        Odometry(P).commanded(0.0, (0.1, float("nan"), 0.0))


#: Simulated seconds of the closed-loop odometry runs: long enough that every run without range sensors meets
#: rubble with its bumper (the latest first bump on these seeds came at 109 s).
DRIFT_RUN_S = 120.0


@pytest.mark.slow
# With range sensors: seeds whose runs meet an obstacle with the rays several times (seed 1 met one once, and with
# another BLAS thread setting none, which tests the path and not the odometry).
@pytest.mark.parametrize("seed,range_sensors", [(s, False) for s in range(8)] + [(0, True), (2, True)])
def test_gyro_aided_odometry_against_mujoco_truth_in_light_rubble(seed, range_sensors):
    """The rescue behaviour for DRIFT_RUN_S in light rubble (bumps, recoveries, pushes against debris, a wheel
    pressing on rubble below the bumper; it keeps exploring after the last find). The issue's "run with bumps" is
    a robot without range sensors: it meets every obstacle with its bumper (with them it stops before most: two
    seeds of that too, where the wheels meet debris below the rays and turn loaded). The behaviour's gyro-aided
    odometry against MuJoCo's true pose at the end of the run within the issue's drift of 3 deg and 0.3 m per
    200 s (scaled to the run's length: the same drift rate), on the eight seeds of the issue's benchmark.
    Measured at 120 s: 0.05-0.81 deg and 0.01-0.13 m against limits of 1.8 deg and 0.18 m, 7.7-10.8 s of CPU per
    run (at 200 s: 0.02-0.86 deg and 0.03-0.19 m, 13-19 s of CPU). (Wheels alone on the same readings are
    printed, not asserted.)"""
    from ssl_sim.runner import odometry_drift

    r = odometry_drift("light_rubble_three", seed=seed, duration_s=DRIFT_RUN_S, range_sensors=range_sensors)
    print(r)
    scale = DRIFT_RUN_S / 200.0
    assert r["sim_time_s"] >= DRIFT_RUN_S - 1.0
    # With range sensors it stops before obstacles; without, it meets them with its bumper (most seeds bump within
    # the run; one that happens not to still checks the drift of a run through rubble).
    assert r["range_stops"] >= 1 if range_sensors else r["range_stops"] == 0
    assert r["bias_updates"] >= 100                          # the bias was learnt standing, listen after listen
    assert r["heading_error_deg"] <= 3.0 * scale and r["position_error_m"] <= 0.3 * scale


def test_sim_drive_reports_the_gyro_yaw_rate():
    """SimDriveBase.status().yaw_rate is what the firmware reports: the mean rate over its last completed 50 ms
    window (windows end at gyro_phase + k 50 ms; truth here from MuJoCo's pose every 5 ms), plus the configured
    bias and the MPU-6050's noise averaged over the window, in whole counts of 1/65.5 deg/s (seeded)."""
    import math

    from robot.protocol import GYRO_COUNTS_PER_RAD_S
    from ssl_sim.physics import SimDriveBase, SimRobot

    robot = SimRobot()
    drive = SimDriveBase(robot, gyro_bias=math.radians(0.1), gyro_bias_walk=0.0, seed=3)
    assert drive.gyro_sigma == pytest.approx(math.radians(0.005) / math.sqrt(2 * 0.05))   # 0.016 deg/s
    assert 0 <= drive.gyro_phase < 0.05
    drive.set_twist(0.0, 0.0, 0.8)
    robot.step(0.95)
    times, yaws = [robot.time], [robot.pose().yaw]
    rates, truth = [], []
    for _ in range(10):                                        # the pose log reaches a window back
        robot.step(0.005)
        times.append(robot.time)
        yaws.append(robot.pose().yaw)
    for _ in range(40):
        for _ in range(10):
            robot.step(0.005)
            times.append(robot.time)
            yaws.append(robot.pose().yaw)
        rates.append(drive.status().yaw_rate)
        assert drive.status().yaw_rate == rates[-1]             # the same window until the next one completes
        end = drive.gyro_phase + math.floor((robot.time - drive.gyro_phase) / 0.05 + 1e-9) * 0.05
        y0, y1 = np.interp([end - 0.05, end], times, np.unwrap(yaws))
        truth.append((y1 - y0) / 0.05)
    rates = np.array(rates)
    err = rates - np.array(truth)
    assert abs(np.mean(truth) - 0.8) < 0.05                   # it turns as commanded
    np.testing.assert_allclose(rates * GYRO_COUNTS_PER_RAD_S, np.round(rates * GYRO_COUNTS_PER_RAD_S), atol=1e-9)
    count = 1 / GYRO_COUNTS_PER_RAD_S
    sigma = math.hypot(drive.gyro_sigma, count / math.sqrt(12))  # noise and rounding
    assert abs(err.mean() - math.radians(0.1)) < 3 * sigma / math.sqrt(40) + 1e-6
    assert err.std() < 2 * sigma
    assert DriveStatus().yaw_rate is None                       # no gyro: the HAL says so


def test_sim_drive_commands_the_twist_at_the_serial_links_resolution():
    """The firmware receives a twist in whole mm/s and mrad/s (SetTwist): the simulated drive commands the wheels
    exactly so, so twists that differ below that resolution drive the same wheels and the same physics."""
    from robot.kinematics import twist_to_wheels
    from ssl_sim.physics import SimDriveBase, SimRobot

    robot = SimRobot()
    drive = SimDriveBase(robot)
    wheels = {}
    for twist in [(0.2004, -0.0496, 0.3), (0.2 + 1e-11, -0.05 - 1e-12, 0.3), (0.1996, -0.0504, 0.3004)]:
        drive.set_twist(*twist)
        wheels[twist] = robot.wheel_commands
    want = twist_to_wheels((0.2, -0.05, 0.3), robot.params)
    for w in wheels.values():
        assert w.tolist() == want.tolist()
    drive.set_twist(0.2006, -0.05, 0.3)                         # past the half step: the next mm/s
    np.testing.assert_allclose(robot.wheel_commands, twist_to_wheels((0.201, -0.05, 0.3), robot.params),
                               rtol=1e-12)


def test_sim_gyro_bias_drifts_as_a_seeded_random_walk():
    """The simulated bias wanders by gyro_bias_walk * sqrt(t): over 16 seeds and 100 s its change has that spread."""
    import math

    from ssl_sim.physics import SimDriveBase, SimRobot

    robot = SimRobot()
    walk = math.radians(0.001)
    changes = []
    for seed in range(16):
        robot.reset()
        drive = SimDriveBase(robot, gyro_bias=0.0, gyro_bias_walk=walk, seed=seed)
        for _ in range(10):
            robot.place(0.0, 0.0, 0.0, advance_s=10.0)
            drive.status()
        changes.append(drive.gyro_bias)
    robot.reset()
    again = SimDriveBase(robot, gyro_bias=0.0, gyro_bias_walk=walk, seed=15)
    for _ in range(10):
        robot.place(0.0, 0.0, 0.0, advance_s=10.0)
        again.status()
    assert again.gyro_bias == changes[-1]                      # seeded
    # the std of 16 draws of N(0, walk^2 100 s) lies within a factor 2 of walk * 10 (chi distribution, 15 dof)
    assert 0.5 * walk * 10 < np.std(changes) < 1.6 * walk * 10
