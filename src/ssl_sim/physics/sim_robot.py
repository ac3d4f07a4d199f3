"""``SimRobot``: the simulated omni robot in a MuJoCo world, behind a small API.

Commands go in as body twists (robot frame, through ``robot.kinematics.twist_to_wheels``)
or wheel speeds; physics advances with a fixed timestep; reads give ground-truth pose,
wheel encoders, IMU, microphone positions (world frame) and collisions.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import mujoco
import numpy as np

from robot.hal import WheelOdometry
from robot.kinematics import OmniDriveParams, twist_to_wheels
from robot.ranging import RangeLayout
from ssl_sim.physics import robot_model as rm
from ssl_sim.physics.world_mjcf import FLOOR_GEOM, world_spec
from ssl_sim.world import World

#: Warnings that mean the simulation is no longer trustworthy.
_FATAL_WARNINGS = (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQPOS, mujoco.mjtWarning.mjWARN_BADQVEL,
                   mujoco.mjtWarning.mjWARN_CNSTRFULL, mujoco.mjtWarning.mjWARN_CONTACTFULL,
                   mujoco.mjtWarning.mjWARN_INERTIA)
#: Geom groups the range sensors see: the world's solids are group 0 (the robot's visual-only parts are 1 and 3).
_RAY_GROUPS = np.array([1, 0, 0, 0, 0, 0], np.uint8)
_FATAL_INDEX = np.array([int(w) for w in _FATAL_WARNINGS])


class PhysicsError(RuntimeError):
    """The physics went unstable (NaN, divergence, solver warnings)."""


@dataclass(frozen=True)
class Pose:
    """Robot base frame in the world: position (m), yaw (rad, about +z) and full orientation quaternion (w, x, y, z)."""

    x: float
    y: float
    z: float
    yaw: float
    quat: np.ndarray

    @property
    def rotation(self) -> np.ndarray:
        m = np.zeros(9)
        mujoco.mju_quat2Mat(m, self.quat)
        return m.reshape(3, 3)

    @property
    def tilt(self) -> float:
        """Angle (rad) between the robot's +z and the world's +z."""
        return float(np.arccos(np.clip(self.rotation[2, 2], -1.0, 1.0)))


@dataclass(frozen=True)
class Imu:
    """IMU at the ``imu`` site: specific force (m/s^2) and angular rate (rad/s) in the sensor (robot) frame,
    orientation quaternion (w, x, y, z) of the sensor frame in the world."""

    accel: np.ndarray
    gyro: np.ndarray
    quat: np.ndarray


@dataclass(frozen=True)
class Contact:
    """A contact between a robot geom and a world geom that is not the floor."""

    robot_geom: str
    world_geom: str
    position: np.ndarray        # world frame, m
    normal_force: float         # N
    obstacle: int | None        # index into World.obstacles, None for the room walls


class SimRobot:
    """The robot in ``world`` (``None``: alone on a flat floor), physics step ``timestep`` s."""

    def __init__(self, world: World | None = None, config: rm.RobotModelConfig = rm.RobotModelConfig(),
                 timestep: float = rm.DEFAULT_TIMESTEP, start: tuple[float, float, float] | None = None,
                 bumper_threshold: float = 1.0, park_settled: bool = False) -> None:
        if not 0 < timestep <= config.contact_timeconst / 2:
            raise ValueError("timestep: expected 0 < timestep <= contact_timeconst / 2 = "
                             f"{config.contact_timeconst / 2} s "
                             f"(validated at {rm.DEFAULT_TIMESTEP}), got {timestep}")
        self.world, self.config = world, config
        if world is None:
            spec = rm.robot_spec(config, pose=start or (0.0, 0.0, 0.0), timestep=timestep)
        else:
            spec = world_spec(world, config, timestep, robot_pose=start)
        self.model = spec.compile()
        self.data = mujoco.MjData(self.model)
        self.bumper_threshold = float(bumper_threshold)
        m = self.model
        self._base = m.body(rm.BASE_BODY).id
        self._array = m.body(rm.ARRAY_BODY).id
        self._wheel_qpos = np.array([m.jnt_qposadr[m.joint(j).id] for j in rm.WHEEL_JOINTS])
        self._wheel_dof = np.array([m.jnt_dofadr[m.joint(j).id] for j in rm.WHEEL_JOINTS])
        self._base_dof = int(m.jnt_dofadr[m.joint("base_free").id])
        #: Skip the physics while the motors stand and the robot is at rest (``_settled``): time advances, the
        #: state does not (the sub-millimetre creep of a parked robot on soft contacts is left out).
        self.park_settled = bool(park_settled)
        self._mics = np.array([m.site(rm.mic_site(i)).id for i in range(config.array.n_mics)])
        self._motors = np.array([m.geom(f"motor{i}_body").id for i in range(3)])
        self._robot_bodies = self._subtree(self._base)
        self._floor = m.geom(FLOOR_GEOM).id
        self._robot_geom = np.isin(m.geom_bodyid, self._robot_bodies)   # per geom: part of the robot
        self._bumper = m.geom(rm.BUMPER_GEOM).id
        # Static geoms the bumper can meet: everything of the world's but the floor and small debris.
        self._bumper_targets = np.array([g for g in range(m.ngeom) if m.geom_bodyid[g] not in self._robot_bodies
                                         and g != self._floor and m.geom_contype[g] & rm.WORLD_CONTYPE], int)
        self._sensor = {m.sensor(i).name: slice(m.sensor_adr[i], m.sensor_adr[i] + m.sensor_dim[i])
                        for i in range(m.nsensor)}
        self._stale = False
        self._state = 0        # counts changes of the physical state (steps, placing, reset): reads cached on it
        self._bumper_read: tuple[int, bool] | None = None
        self._requested = 0.0  # simulated time asked for through step(), s
        self._base_qpos = int(m.jnt_qposadr[m.joint("base_free").id])
        mujoco.mj_forward(self.model, self.data)
        self._restart_yaw_log()

    # -- set-up ------------------------------------------------------------------------------
    def _subtree(self, root: int) -> np.ndarray:
        ids = [b for b in range(self.model.nbody) if self._is_descendant(b, root)]
        return np.asarray(ids)

    def _is_descendant(self, b: int, root: int) -> bool:
        while b > 0:
            if b == root:
                return True
            b = int(self.model.body_parentid[b])
        return False

    @property
    def params(self) -> OmniDriveParams:
        return self.config.drive

    @property
    def timestep(self) -> float:
        return float(self.model.opt.timestep)

    @property
    def state_version(self) -> int:
        """Counts changes of the physical state (steps, placing, reset): equal values, equal state."""
        return self._state

    @property
    def time(self) -> float:
        """Simulated time (s) since the start or the last reset."""
        return float(self.data.time)

    def reset(self) -> None:
        """Back to the start pose, at rest, time 0."""
        mujoco.mj_resetData(self.model, self.data)
        mujoco.mj_forward(self.model, self.data)
        self._stale = False
        self._state += 1
        self._requested = 0.0
        self._restart_yaw_log()

    # -- commands -------------------------------------------------------------------------------
    def set_wheel_speeds(self, wheel_speeds) -> np.ndarray:
        """Command wheel angular speeds (rad/s, ``robot.kinematics`` order and sign); returns what the
        motors were given (clipped to the motor limit)."""
        w = np.asarray(wheel_speeds, float)
        if w.shape != (3,) or not np.all(np.isfinite(w)):
            raise ValueError(f"wheel_speeds: expected 3 finite numbers (rad/s), got {wheel_speeds!r}")
        w = np.clip(w, -self.params.max_wheel_speed, self.params.max_wheel_speed)
        self.data.ctrl[:3] = w
        return w

    def set_twist(self, vx: float, vy: float, omega: float) -> np.ndarray:
        """Command a body twist (m/s, m/s, rad/s, robot frame) through the inverse kinematics with
        direction-keeping saturation; returns the wheel speeds commanded (rad/s)."""
        return self.set_wheel_speeds(twist_to_wheels((vx, vy, omega), self.params))

    def stop(self) -> None:
        self.data.ctrl[:3] = 0.0

    @property
    def wheel_commands(self) -> np.ndarray:
        return self.data.ctrl[:3].copy()

    def place(self, x: float, y: float, yaw: float, wheel_angles=None, advance_s: float = 0.0) -> None:
        """Kinematic mode: put the base at ``(x, y)`` (world m), heading ``yaw`` (rad), level at its current
        height, everything at rest; set the wheel encoders to ``wheel_angles`` (rad) if given; advance the
        clock by ``advance_s`` without dynamics. Positions, sensors and contacts are then those of the new pose."""
        m, d = self.model, self.data
        adr = m.jnt_qposadr[m.joint("base_free").id]
        d.qpos[adr:adr + 2] = (x, y)
        d.qpos[adr + 3:adr + 7] = (np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2))
        if wheel_angles is not None:
            d.qpos[self._wheel_qpos] = np.asarray(wheel_angles, float)
        d.qvel[:] = 0.0
        d.time += float(advance_s)
        self._requested = float(d.time)
        mujoco.mj_forward(m, d)
        self._stale = False
        self._state += 1
        self._restart_yaw_log()

    # -- physics -----------------------------------------------------------------------------------
    def step(self, duration: float | None = None) -> None:
        """Advance by ``duration`` s (one physics step if None). Durations that are not whole
        steps are rounded, and the rounding is carried over, so requested and simulated time
        never drift apart by more than half a step.

        Raises ``PhysicsError`` on NaN state or MuJoCo instability warnings."""
        if duration is None:
            self._requested = self.time + self.timestep
        else:
            if not duration >= 0:
                raise ValueError(f"duration: expected >= 0 s, got {duration}")
            self._requested += duration
        n = int(round((self._requested - self.time) / self.timestep))
        if n <= 0:
            return
        if self.park_settled and self._settled():
            self.data.time += n * self.timestep  # parked: the state stays as it is (see __init__)
            self._log_yaw()
            return
        before = self.data.warning.number[_FATAL_INDEX]
        mujoco.mj_step(self.model, self.data, nstep=n)
        self._log_yaw()
        # mj_step leaves positions, sensors and contacts one step behind the state; refresh on first read.
        self._stale = True
        self._state += 1
        after = self.data.warning.number[_FATAL_INDEX]
        grew = {w.name: int(a - b) for w, a, b in zip(_FATAL_WARNINGS, after, before) if a > b}
        if grew or not np.all(np.isfinite(self.data.qpos)):
            raise PhysicsError(f"physics unstable at t={self.time:.3f} s: warnings {grew or 'none'}, "
                               f"finite state {bool(np.all(np.isfinite(self.data.qpos)))}")

    def _settled(self) -> bool:
        """Motors commanded to stand and the robot (nearly) at rest: base under 2 mm/s and 0.01 rad/s, wheels
        under 0.05 rad/s (a parked robot on soft contacts jitters at the 90th percentiles 1.1 mm/s, 0.004 rad/s
        and 0.03 rad/s, measured in light_rubble_three)."""
        if np.any(self.data.ctrl[:3]):
            return False
        v = self.data.qvel[self._base_dof: self._base_dof + 6]
        return bool(np.linalg.norm(v[:3]) < 2e-3 and np.linalg.norm(v[3:]) < 1e-2
                    and np.max(np.abs(self.data.qvel[self._wheel_dof])) < 5e-2)

    # -- yaw history (what a gyro averaging over a window sees) ------------------------------------
    def _qpos_yaw(self) -> float:
        w, x, y, z = self.data.qpos[self._base_qpos + 3: self._base_qpos + 7]   # the state itself, not one step behind
        return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))

    def _restart_yaw_log(self) -> None:
        self._yaw_raw = self._qpos_yaw()
        # (time s, unwrapped yaw rad) at the end of each step() call; 256 cover > 0.1 s even of single steps
        self._yaw_log: deque[tuple[float, float]] = deque([(self.time, self._yaw_raw)], maxlen=256)

    def _log_yaw(self) -> None:
        yaw = self._qpos_yaw()
        unwrapped = self._yaw_log[-1][1] + math.remainder(yaw - self._yaw_raw, 2 * math.pi)
        self._yaw_raw = yaw
        self._yaw_log.append((self.time, unwrapped))

    def mean_yaw_rate(self, window: float, end: float | None = None) -> float:
        """Mean rate (rad/s, CCW) of the base's yaw over the ``window`` s that end at ``end`` (default: now; at
        most ~0.1 s back): the yaw change over it (linear between the ends of the physics steps taken, which
        are at most a control tick or an audio chunk long) divided by its length. What a gyro's z axis averaged
        over that window reports while the base is near level (body and world z rates differ by the cosine of
        the tilt: 0.4 % at 5 deg). Parked physics (``park_settled``) does not turn the base: a parked robot's
        rate is 0."""
        if not window > 0:
            raise ValueError(f"window: expected > 0 s, got {window}")
        log = self._yaw_log
        t1 = log[-1][0] if end is None else min(float(end), log[-1][0])
        t0 = max(t1 - window, log[0][0])     # the log may not reach back that far (just started or reset)
        if t1 <= t0:
            return 0.0
        # Interpolate in the entries from the last one at or before t0 on: the same brackets as in the whole
        # log (read every control tick, the whole 256-entry log was most of the read's cost).
        k = len(log) - 1
        while k > 0 and log[k][0] > t0:
            k -= 1
        times, yaws = np.array([log[j] for j in range(k, len(log))]).T
        y0, y1 = np.interp([t0, t1], times, yaws)
        return float(y1 - y0) / (t1 - t0)

    def warning_counts(self) -> dict[str, int]:
        """MuJoCo's cumulative counters of the warnings that invalidate a run."""
        return {w.name: int(self.data.warning[int(w)].number) for w in _FATAL_WARNINGS}

    # -- state (all reads are at ``time``) ------------------------------------------------------------
    def _sync(self) -> None:
        if self._stale:
            mujoco.mj_forward(self.model, self.data)
            self._stale = False
    def pose(self) -> Pose:
        """Ground-truth pose of the robot (base) frame."""
        self._sync()
        q = self.data.xquat[self._base].copy()
        p = self.data.xpos[self._base]
        w, x, y, z = q
        yaw = float(np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
        return Pose(float(p[0]), float(p[1]), float(p[2]), yaw, q)

    def body_twist(self) -> np.ndarray:
        """Ground-truth (vx, vy, omega_z) of the base in its own frame (m/s, m/s, rad/s)."""
        self._sync()
        v = np.zeros(6)
        # XBODY: the body frame (mjOBJ_BODY would be the principal-inertia frame).
        mujoco.mj_objectVelocity(self.model, self.data, mujoco.mjtObj.mjOBJ_XBODY, self._base, v, 1)
        return np.array([v[3], v[4], v[2]])

    def wheel_odometry(self) -> WheelOdometry:
        """Encoders: cumulative wheel angles (rad) and speeds (rad/s), ``robot.kinematics`` order and sign."""
        return WheelOdometry(timestamp=self.time, wheel_angles=self.data.qpos[self._wheel_qpos].copy(),
                             wheel_speeds=self.data.qvel[self._wheel_dof].copy())

    def sensor(self, name: str) -> np.ndarray:
        """Raw reading of a model sensor (``enc_pos0``, ``imu_accel``, ``bumper``, ``motor_torque0``, ...)."""
        if name not in self._sensor:
            raise ValueError(f"unknown sensor '{name}': expected one of {sorted(self._sensor)}")
        self._sync()
        return self.data.sensordata[self._sensor[name]].copy()

    def imu(self) -> Imu:
        return Imu(self.sensor("imu_accel"), self.sensor("imu_gyro"), self.sensor("imu_quat"))

    def ray_distances(self, layout: RangeLayout) -> np.ndarray:
        """Ground truth of ``layout``'s range sensors now: the distance (m) from each sensor along its ray (robot
        frame, tilted with the base) to the first geom, ``inf`` beyond ``max_range_m``. The base's own geoms are
        excluded (the rays start inside the bumper); the layout keeps the rays clear of the wheels."""
        self._sync()
        d = self.data
        rot = d.xmat[self._base].reshape(3, 3)
        az = np.asarray(layout.azimuths_rad, float)
        u = np.stack([np.cos(az), np.sin(az), np.zeros_like(az)], axis=1)
        starts = d.xpos[self._base] + (layout.mount_radius_m * u + [0.0, 0.0, layout.height_m]) @ rot.T
        dirs = u @ rot.T
        out = np.full(len(az), np.inf)
        geom = np.zeros(1, np.int32)
        for k in range(len(az)):
            r = mujoco.mj_ray(self.model, d, starts[k], dirs[k], _RAY_GROUPS, 1, self._base, geom)
            if 0 <= r <= layout.max_range_m:
                out[k] = r
        return out

    def mic_positions(self) -> np.ndarray:
        """World positions of the microphones (n_mics, 3), m, from the model's mic sites."""
        self._sync()
        return self.data.site_xpos[self._mics].copy()

    def motor_positions(self) -> np.ndarray:
        """World positions of the three gear motors' centres (3, 3), m (ego-noise sources)."""
        self._sync()
        return self.data.geom_xpos[self._motors].copy()

    def array_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """Array frame in the world: (origin (3,), rotation (3, 3) whose columns are the array axes)."""
        self._sync()
        return self.data.xpos[self._array].copy(), self.data.xmat[self._array].reshape(3, 3).copy()

    def bumper(self) -> bool:
        """Whether the bumper switch is closed: the bumper band is within its travel
        (``robot_model.BUMPER_TRAVEL``) of a wall or big obstacle, or its touch sensor feels more than
        ``bumper_threshold`` N. Distance, not force alone: pressed against a wall the slipping wheels
        make the contact chatter at sub-millimetre scale and the force flicker.

        Read once per physical state (a control tick reads the drive's status two or three times)."""
        if self._bumper_read is not None and self._bumper_read[0] == self._state:
            return self._bumper_read[1]
        pressed = self._bumper_now()
        self._bumper_read = (self._state, pressed)
        return pressed

    def _bumper_now(self) -> bool:
        self._sync()
        if self.sensor("bumper")[0] > self.bumper_threshold:
            return True
        m, d = self.model, self.data
        g = self._bumper_targets
        reach = m.geom_rbound[self._bumper] + rm.BUMPER_TRAVEL + m.geom_rbound[g]
        gap = np.linalg.norm(d.geom_xpos[g] - d.geom_xpos[self._bumper], axis=1)
        near = g[(gap <= reach) | (m.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE)]  # bounding spheres overlap
        return any(mujoco.mj_geomDistance(m, d, self._bumper, int(k), rm.BUMPER_TRAVEL, None) < rm.BUMPER_TRAVEL
                   for k in near)

    def contacts(self) -> list[Contact]:
        """Current contacts between the robot and anything but the floor."""
        self._sync()
        m, d = self.model, self.data
        out = []
        f6 = np.zeros(6)
        if not d.ncon:
            return out
        # Robot-vs-world contacts other than the floor, picked out for all contacts at once: most are the wheels'
        # on the floor, read every control tick (one array test instead of a Python loop over them).
        g1s, g2s = d.contact.geom1, d.contact.geom2
        r1s, r2s = self._robot_geom[g1s], self._robot_geom[g2s]
        other = np.where(r1s, g2s, g1s)
        for k in np.flatnonzero((r1s != r2s) & (other != self._floor)).tolist():
            c = d.contact[k]
            g1, g2 = int(c.geom1), int(c.geom2)
            rg, wg = (g1, g2) if bool(r1s[k]) else (g2, g1)
            mujoco.mj_contactForce(m, d, k, f6)
            name = m.geom(wg).name
            obstacle = int(name[3:]) if name.startswith("obs") else None
            out.append(Contact(m.geom(rg).name, name, c.pos.copy(), float(f6[0]), obstacle))
        return out
