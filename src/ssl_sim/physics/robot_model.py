"""MuJoCo model of the paper's three-wheel omni robot carrying the 8-mic cube array.

Built with ``mujoco.MjSpec`` from the same numbers the rest of the project uses:
wheel layout from ``robot.kinematics.OmniDriveParams`` and microphone sites from
``ssl_core.geometry.cube8()`` (array frame), so the model cannot drift from them.

Frames. Robot (body) frame: origin at the base centre on the ground, +x forward,
+y left, +z up; the free-joint body ``base`` has exactly this frame, so its world
position is the robot pose (z ~ 0 on flat ground). Array frame: the child body
``array`` at ``(0, 0, array_height)``, axes aligned with the robot's.

Wheels really drive the robot through contacts: every omni wheel is a motor-driven
hub (hinge, velocity servo with a torque limit) carrying two staggered rows of
passive rollers (hinges along the roller axis). The rollers are ellipsoids whose
outer profile matches the wheel circle, so the rolling radius stays within a
fraction of a millimetre of ``wheel_radius`` as contact passes from roller to
roller. Nothing moves the base except contact forces.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from robot.kinematics import OmniDriveParams
from ssl_core.geometry import ArrayGeometry, cube8

#: Collision filtering (MuJoCo: two geoms collide if ``ct1 & ca2 or ct2 & ca1``).
#: Robot geoms hit the world but never each other; static world geoms never test each other.
#: Small climbable debris (``DEBRIS_CONTYPE``) is only tested against the parts that can reach
#: it, the rollers and the motors (lowest chassis point 3.75 cm vs debris top <= 2 cm): the
#: bumper, deck and cube sit higher, and skipping those pairs halves the collision cost in rubble.
ROBOT_CONTYPE = 1
ROBOT_CONAFFINITY = 2        # chassis parts: floor, walls, big debris
ROBOT_LOW_CONAFFINITY = 2 | 4  # rollers and motors: also small debris
WORLD_CONTYPE, WORLD_CONAFFINITY = 2, 0
DEBRIS_CONTYPE = 4

#: Physics step (s): 4 steps per 10 ms control tick; validated against the twist-tracking tests.
DEFAULT_TIMESTEP = 0.0025

BASE_BODY = "base"
ARRAY_BODY = "array"
IMU_SITE = "imu"
BUMPER_SITE = "bumper"
BUMPER_GEOM = "bumper"
BUMPER_TRAVEL = 0.002  # m: the bumper switch closes this close to an obstacle
WHEEL_JOINTS = ("wheel0", "wheel1", "wheel2")
WHEEL_ACTUATORS = ("motor0", "motor1", "motor2")


def mic_site(i: int) -> str:
    return f"mic{i}"


@dataclass(frozen=True)
class RobotModelConfig:
    """Physical parameters of the robot (SI units, robot frame).

    Sized as a small gear-motor robot of the paper's class (total 2.8 kg): 100 mm
    double-row omni wheels with 2 x 5 rubber rollers of 45 x 20 mm (58 mm wheels would
    leave under 2 cm of ground clearance), 25 mm 12 V gear motors (~190 rpm = 20 rad/s
    at the wheel, 1 N m stall torque) under a speed loop, the 15 cm cube on a mast.
    """

    drive: OmniDriveParams = field(default_factory=OmniDriveParams)
    rollers_per_row: int = 5             # two staggered rows -> 10 rollers per wheel
    roller_half_length: float = 0.45     # ellipsoid semi-axis along the roller / wheel_radius (45 x 20 mm rollers)
    row_offset: float = 0.011            # m, axial offset of each roller row from the wheel plane
    roller_friction: float = 0.9         # rubber on concrete
    roller_mass: float = 0.006           # kg each
    hub_mass: float = 0.07               # kg per wheel hub (aluminium plates)
    wheel_armature: float = 2.0e-4       # kg m^2, motor rotor inertia reflected through the gearbox
    wheel_damping: float = 2.0e-3        # N m s/rad, gearbox viscous loss
    roller_damping: float = 2.0e-6       # N m s/rad, roller bearing
    motor_kv: float = 0.5                # N m s/rad, motor driver speed-loop gain
    motor_max_torque: float = 1.0        # N m, gear-motor stall torque at the wheel
    chassis_mass: float = 1.2            # kg, decks + battery + electronics
    motor_mass: float = 0.18             # kg each
    motor_radius: float = 0.0125         # m, 25 mm gear motor
    motor_length: float = 0.06           # m
    bumper_mass: float = 0.2             # kg
    bumper_radius: float = 0.16          # m, encloses the wheels in plan view
    bumper_z: tuple[float, float] = (0.045, 0.11)   # m, bottom and top of the bumper band
    deck_z: float = 0.075                # m, bottom of the lower deck
    array_height: float = 0.27           # m, cube centre above the ground
    array_mass: float = 0.35             # kg, aluminium cube frame + microphones
    mast_mass: float = 0.1               # kg
    array: ArrayGeometry = field(default_factory=cube8)
    cube_edge: float = 0.15              # m
    chassis_friction: float = 0.4        # plastic bumper / aluminium
    contact_timeconst: float = 0.005     # s, stiff contacts (~0.2 mm sink); needs timestep <= timeconst / 2

    def __post_init__(self) -> None:
        if self.rollers_per_row < 3:
            raise ValueError(f"rollers_per_row: expected >= 3, got {self.rollers_per_row}")
        a = self.roller_half_length
        # Neighbouring rollers of a row must not overlap: angular half-span atan(a / (R - b)) < pi / n.
        if not 0.1 < a < 0.7 or np.arctan(a / (1 - a * a)) >= np.pi / self.rollers_per_row:
            raise ValueError(
                f"roller_half_length: {a} (fraction of wheel_radius) makes neighbouring rollers of a row overlap "
                f"with {self.rollers_per_row} rollers per row; expected a smaller value")
        for name in ("roller_mass", "hub_mass", "motor_kv", "motor_max_torque", "chassis_mass", "array_height"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: expected > 0, got {getattr(self, name)}")
        lo, hi = self.bumper_z
        if not 0 < lo < hi:
            raise ValueError(f"bumper_z: expected 0 < bottom < top (m), got {self.bumper_z}")
        if self.array_height - self.cube_edge / 2 < hi:
            raise ValueError("array_height: the cube must sit above the bumper band")

    @property
    def roller_semi_axes(self) -> tuple[float, float]:
        """(a, b): ellipsoid semi-axis along the roller and across it (m).

        ``b = a^2 / R`` makes the ellipse's curvature at its apex equal the wheel's, so
        the profile follows the wheel circle to fourth order."""
        r = self.drive.wheel_radius
        a = self.roller_half_length * r
        return a, a * a / r

    @property
    def ground_clearance(self) -> float:
        """Lowest point of the chassis (motors) above flat ground (m)."""
        return min(self.bumper_z[0], self.drive.wheel_radius - self.motor_radius)

    @property
    def total_mass(self) -> float:
        n_roll = 3 * 2 * self.rollers_per_row
        return (self.chassis_mass + 3 * self.motor_mass + self.bumper_mass + self.array_mass + self.mast_mass
                + 3 * self.hub_mass + n_roll * self.roller_mass)


def _quat_from_mat(m: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.asarray(m, float).ravel())
    return q


def _quat_z(angle: float) -> np.ndarray:
    return np.array([np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)])


def _robot_geom(body, cfg: RobotModelConfig, low: bool = False, **kw):
    g = body.add_geom(**kw)
    g.contype, g.conaffinity = ROBOT_CONTYPE, (ROBOT_LOW_CONAFFINITY if low else ROBOT_CONAFFINITY)
    g.priority = 1  # the robot's friction and softness win over the world's in every contact
    g.solref = [cfg.contact_timeconst, 1.0]
    return g


def _visual_geom(body, **kw):
    g = body.add_geom(**kw)
    g.contype = g.conaffinity = 0
    g.group = 1
    return g


def add_robot(spec: mujoco.MjSpec, cfg: RobotModelConfig = RobotModelConfig(),
              pose: tuple[float, float, float] = (0.0, 0.0, 0.0), z: float = 0.0) -> None:
    """Add the robot to ``spec`` at world pose ``(x, y, yaw)`` (m, m, rad), base frame ``z`` m up.

    Adds bodies, joints, actuators ``motor0..2`` (velocity servos, ctrl in rad/s of the
    wheel, order and sign as ``robot.kinematics``) and sensors: ``enc_pos{i}``/``enc_vel{i}``
    (wheel encoders, rad and rad/s), ``motor_torque{i}`` (N m), ``imu_accel`` (m/s^2),
    ``imu_gyro`` (rad/s), ``imu_quat`` (w, x, y, z) at site ``imu``, ``bumper`` (touch, N)."""
    d = cfg.drive
    R = d.wheel_radius
    x, y, yaw = (float(v) for v in pose)

    base = spec.worldbody.add_body(name=BASE_BODY, pos=[x, y, z], quat=_quat_z(yaw))
    base.add_freejoint(name="base_free")
    # Lower deck: carries battery and electronics (mass lumped here).
    plate_r = d.base_radius - cfg.row_offset - cfg.roller_semi_axes[1] - 0.02
    _robot_geom(base, cfg, name="deck", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[plate_r, 0.004, 0],
                pos=[0, 0, cfg.deck_z + 0.004], mass=cfg.chassis_mass, rgba=[0.25, 0.25, 0.28, 1],
                friction=[cfg.chassis_friction, 0.005, 0.0001])
    # Bumper band: outermost part of the robot in plan view; the touch sensor site wraps it.
    zb0, zb1 = cfg.bumper_z
    _robot_geom(base, cfg, name=BUMPER_GEOM, type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                size=[cfg.bumper_radius, (zb1 - zb0) / 2, 0], pos=[0, 0, (zb0 + zb1) / 2],
                mass=cfg.bumper_mass, rgba=[0.9, 0.6, 0.1, 0.35], friction=[cfg.chassis_friction, 0.005, 0.0001])
    base.add_site(name=BUMPER_SITE, type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                  size=[cfg.bumper_radius + 0.01, (zb1 - zb0) / 2 + 0.01, 0], pos=[0, 0, (zb0 + zb1) / 2],
                  rgba=[1, 0, 0, 0.1], group=4)
    base.add_site(name=IMU_SITE, size=[0.01, 0, 0], pos=[0, 0, cfg.deck_z + 0.02], group=4)
    # Mast from the deck to the cube.
    mast_lo, mast_hi = cfg.deck_z + 0.008, cfg.array_height - cfg.cube_edge / 2
    _visual_geom(base, name="mast", type=mujoco.mjtGeom.mjGEOM_CYLINDER, size=[0.012, (mast_hi - mast_lo) / 2, 0],
                 pos=[0, 0, (mast_lo + mast_hi) / 2], mass=cfg.mast_mass, rgba=[0.6, 0.6, 0.6, 1])

    a, b = cfg.roller_semi_axes
    hub_r = R - 2 * b - 0.002
    for i, th in enumerate(d.wheel_angles):
        u = np.array([np.cos(th), np.sin(th), 0.0])      # radial, outward
        t = np.array([-np.sin(th), np.cos(th), 0.0])     # rolling direction (robot.kinematics d_i)
        # Motor: along the axle, inboard of the wheel.
        m_r = d.base_radius - cfg.row_offset - b - 0.006 - cfg.motor_length / 2
        _robot_geom(base, cfg, low=True, name=f"motor{i}_body", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                    size=[cfg.motor_radius, cfg.motor_length / 2, 0], pos=list(m_r * u + [0, 0, R]),
                    quat=_quat_from_mat(np.column_stack([t, [0, 0, 1.0], u])), mass=cfg.motor_mass,
                    rgba=[0.3, 0.3, 0.35, 1], friction=[cfg.chassis_friction, 0.005, 0.0001])
        # Wheel frame: z = hinge axis = -u (so positive speed drives the robot along +t),
        # x = up, y = t.
        wheel = base.add_body(name=f"wheel{i}", pos=list(d.base_radius * u + [0, 0, R]),
                              quat=_quat_from_mat(np.column_stack([[0, 0, 1.0], t, -u])))
        wheel.add_joint(name=WHEEL_JOINTS[i], type=mujoco.mjtJoint.mjJNT_HINGE, axis=[0, 0, 1],
                        armature=cfg.wheel_armature, damping=cfg.wheel_damping)
        _visual_geom(wheel, name=f"hub{i}", type=mujoco.mjtGeom.mjGEOM_CYLINDER,
                     size=[hub_r, cfg.row_offset + 0.004, 0], mass=cfg.hub_mass, rgba=[0.7, 0.7, 0.75, 1])
        n = cfg.rollers_per_row
        for row, side in enumerate((-1.0, 1.0)):
            for k in range(n):
                phi = 2 * np.pi * k / n + row * np.pi / n
                c = np.array([(R - b) * np.cos(phi), (R - b) * np.sin(phi), side * cfg.row_offset])
                roller = wheel.add_body(name=f"roller{i}_{row}_{k}", pos=list(c), quat=_quat_z(phi + np.pi / 2))
                roller.add_joint(name=f"roller{i}_{row}_{k}", type=mujoco.mjtJoint.mjJNT_HINGE, axis=[1, 0, 0],
                                 damping=cfg.roller_damping, armature=1e-7)
                _robot_geom(roller, cfg, low=True, name=f"roller{i}_{row}_{k}", type=mujoco.mjtGeom.mjGEOM_ELLIPSOID,
                            size=[a, b, b], mass=cfg.roller_mass, condim=3,
                            friction=[cfg.roller_friction, 0.005, 0.0001], rgba=[0.1, 0.1, 0.1, 1])
        act = spec.add_actuator(name=WHEEL_ACTUATORS[i], target=WHEEL_JOINTS[i], trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_velocity(kv=cfg.motor_kv)
        act.ctrllimited = act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
        act.ctrlrange = [-d.max_wheel_speed, d.max_wheel_speed]
        act.forcerange = [-cfg.motor_max_torque, cfg.motor_max_torque]

    arr = base.add_body(name=ARRAY_BODY, pos=[0, 0, cfg.array_height])
    _visual_geom(arr, name="cube", type=mujoco.mjtGeom.mjGEOM_BOX, size=[cfg.cube_edge / 2] * 3,
                 mass=cfg.array_mass, rgba=[0.75, 0.78, 0.8, 0.4])
    # Cube8's mics sit on the faces; cube sides collide too (a robot tipping onto rubble).
    _robot_geom(arr, cfg, name="cube_collision", type=mujoco.mjtGeom.mjGEOM_BOX, size=[cfg.cube_edge / 2] * 3,
                mass=0.0, rgba=[0, 0, 0, 0], friction=[cfg.chassis_friction, 0.005, 0.0001]).group = 3
    for m, p in enumerate(cfg.array.positions):
        arr.add_site(name=mic_site(m), pos=list(p), size=[0.006, 0, 0], rgba=[0.9, 0.1, 0.1, 1])
    arr.add_site(name="array_centre", size=[0.004, 0, 0], group=4)

    _add_sensors(spec, cfg)


def _sensor_table(cfg: RobotModelConfig) -> list[tuple[str, mujoco.mjtSensor, mujoco.mjtObj, str]]:
    """Rows (sensor name, type, object type, object name)."""
    S, O = mujoco.mjtSensor, mujoco.mjtObj
    rows = []
    for i, j in enumerate(WHEEL_JOINTS):
        rows.append((f"enc_pos{i}", S.mjSENS_JOINTPOS, O.mjOBJ_JOINT, j))
        rows.append((f"enc_vel{i}", S.mjSENS_JOINTVEL, O.mjOBJ_JOINT, j))
        rows.append((f"motor_torque{i}", S.mjSENS_ACTUATORFRC, O.mjOBJ_ACTUATOR, WHEEL_ACTUATORS[i]))
    rows += [
        ("imu_accel", S.mjSENS_ACCELEROMETER, O.mjOBJ_SITE, IMU_SITE),
        ("imu_gyro", S.mjSENS_GYRO, O.mjOBJ_SITE, IMU_SITE),
        ("imu_quat", S.mjSENS_FRAMEQUAT, O.mjOBJ_SITE, IMU_SITE),
        ("bumper", S.mjSENS_TOUCH, O.mjOBJ_SITE, BUMPER_SITE),
    ]
    return rows


def _add_sensors(spec: mujoco.MjSpec, cfg: RobotModelConfig) -> None:
    for name, typ, objtype, objname in _sensor_table(cfg):
        spec.add_sensor(name=name, type=typ, objtype=objtype, objname=objname)


def configure_options(spec: mujoco.MjSpec, timestep: float = DEFAULT_TIMESTEP) -> None:
    """Solver settings the robot model is validated with (fixed physics timestep in s)."""
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST  # implicit in the motor gain
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC                  # isotropic friction, no pyramid artefacts
    spec.option.jacobian = mujoco.mjtJacobian.mjJAC_DENSE
    spec.option.iterations = 50
    spec.option.ls_iterations = 20


def add_floor(spec: mujoco.MjSpec, half_size: tuple[float, float] = (5.0, 5.0),
              center: tuple[float, float] = (0.0, 0.0), friction: float = 0.8) -> None:
    floor = spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE,
                                    size=[half_size[0], half_size[1], 0.05], pos=[center[0], center[1], 0],
                                    friction=[friction, 0.005, 0.0001], rgba=[0.5, 0.5, 0.5, 1])
    floor.contype, floor.conaffinity = WORLD_CONTYPE, WORLD_CONAFFINITY
    light = spec.worldbody.add_light(name="sun", pos=[center[0], center[1], 6.0], dir=[0, 0, -1])
    light.castshadow = False


def robot_spec(cfg: RobotModelConfig = RobotModelConfig(), pose=(0.0, 0.0, 0.0),
               timestep: float = DEFAULT_TIMESTEP, floor_half_size: float = 20.0) -> mujoco.MjSpec:
    """The robot alone on a large flat concrete floor."""
    spec = mujoco.MjSpec()
    spec.modelname = "omni_robot"
    configure_options(spec, timestep)
    add_floor(spec, (floor_half_size, floor_half_size))
    add_robot(spec, cfg, pose)
    return spec
