"""Simulation HAL backends: the MuJoCo robot and the acoustic simulator behind ``robot.hal``.

``SimAudioSource`` is the microphone array of a :class:`~ssl_sim.physics.SimRobot`: reading
``n`` samples advances the physics by ``n / fs`` seconds (the robot keeps doing what the drive
was last told) and renders what the microphones hear over that interval with an
:class:`~ssl_sim.acoustics.AcousticSimulator`, at the microphones' world positions taken from
the MuJoCo model. Together with ``SimDriveBase`` and ``SimClock`` (``ssl_sim.physics``) the
rescue behaviour runs on simulated time, deterministically and as fast as the CPU allows::

    hal = make_sim_hal(world, acoustic_config=AcousticConfig(seed=1))
    behaviour = RescueBehaviour(hal.audio, hal.drive, hal.clock, localizer, start_pose=world.robot_start)

Time: one timeline for both. Audio sample ``k`` is at simulated time ``k / fs``; a read starts
at the physics time rounded to a sample and ends when the physics reaches the block's end
(within half a physics step; no drift accumulates).

Moving while listening: the physics is stepped first, recording the microphone positions every
``chunk_s``; if no microphone moved more than ``still_tolerance_m`` the whole block is rendered at
one pose, the mean of the recorded ones (one FFT convolution, RIRs cached per pose), otherwise each
chunk is rendered at its own pose (piecewise-constant receiver positions, the usual
moving-receiver approximation). A parked robot is not perfectly still in MuJoCo (it creeps by a
fraction of a degree per second on its passive rollers); the default 3 mm tolerance treats that as
standing (the mean pose is then within 1.5 mm, 0.07 sample at 16 kHz, of every true pose).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from robot.hal import AudioBlock, AudioSource
from ssl_sim.acoustics import AcousticConfig, AcousticSimulator, SoundSource
from ssl_sim.acoustics.ego_noise import EgoNoise, EgoNoiseConfig
from ssl_sim.physics import SimClock, SimDriveBase, SimRobot
from ssl_sim.world import World

__all__ = ["SimAudioSource", "SimHal", "make_sim_hal", "array_frame_directions"]


class SimAudioSource(AudioSource):
    """The simulated array of ``robot`` in the world of ``acoustics`` (see the module docstring).

    ``chunk_s``: pose sampling interval (s) while the robot moves during a read.
    ``still_tolerance_m``: largest microphone displacement (m) during a block that still
    counts as standing still (rendered at the block's mean pose).
    ``on_block``: optional callback ``(block, mic_positions_world)`` after every read
    (instrumentation: visualisation, timing); ``mic_positions_world`` is (n_chunks, n_mics, 3).
    ``ego_noise``: the drive's motor/gear/roller noise (:mod:`ssl_sim.acoustics.ego_noise`), from the
    wheel speeds at the chunk boundaries (linear in between); None: a silent drive.
    ``pose_hold_m``: while the array moves, a chunk is rendered at the pose the previous chunk was rendered at as
    long as no microphone is farther than this from it (m; 0: every chunk at its own pose). The room's response
    is the costly part of a chunk (about half of a 50 ms read while driving); held for 2.5 cm it is computed for
    every third 50 ms read at 0.25 m/s, and a source 1 m away is rendered at most 1.4 deg off its bearing; the
    sources' sound at a held pose is rendered 0.2 s ahead (``AcousticSimulator.render_ahead``).
    """

    def __init__(self, robot: SimRobot, acoustics: AcousticSimulator, chunk_s: float = 0.05,
                 still_tolerance_m: float = 3e-3, on_block=None,
                 ego_noise: EgoNoiseConfig | None = EgoNoiseConfig(), pose_hold_m: float = 0.0) -> None:
        if robot.world is not None and acoustics.world is not robot.world and acoustics.world != robot.world:
            raise ValueError("SimAudioSource: robot and acoustics must simulate the same World")
        if not chunk_s > 0:
            raise ValueError(f"chunk_s: expected > 0 s, got {chunk_s}")
        if not still_tolerance_m >= 0:
            raise ValueError(f"still_tolerance_m: expected >= 0 m, got {still_tolerance_m}")
        if not (np.isfinite(pose_hold_m) and pose_hold_m >= 0):
            raise ValueError(f"pose_hold_m: expected a distance >= 0 m, got {pose_hold_m}")
        self.pose_hold_m = float(pose_hold_m)
        if pose_hold_m > 0:   # a held pose lasts 2-3 reads of 50 ms at 0.25 m/s: its sound rendered once for 0.2 s
            acoustics.render_ahead = max(acoustics.render_ahead, int(round(4 * chunk_s * acoustics.config.fs)))
        # the microphone positions a moving chunk was last rendered at, with the block's (mics, motors) for the
        # ego noise
        self._held: tuple[np.ndarray, tuple | None] | None = None
        self.robot, self.acoustics = robot, acoustics
        self.chunk_s, self.still_tolerance_m = float(chunk_s), float(still_tolerance_m)
        self.on_block = on_block
        self.ego_noise = EgoNoise(acoustics, ego_noise) if ego_noise is not None else None
        self._n_mics = robot.mic_positions().shape[0]
        self.blocks_read = 0
        self.moving_blocks = 0
        #: Array poses ``(origin (3,), rotation (3, 3))`` (world) at the chunk boundaries of the last read.
        self.last_array_poses: list[tuple[np.ndarray, np.ndarray]] = []
        #: Wall-clock seconds spent in reads, split into stepping the physics and rendering the audio.
        self.timing = {"physics": 0.0, "acoustics": 0.0}
        #: The same split in CPU seconds of this process (what a loaded machine does not inflate).
        self.cpu = {"physics": 0.0, "acoustics": 0.0}

    @property
    def sample_rate(self) -> int:
        return int(self.acoustics.config.fs)

    @property
    def n_channels(self) -> int:
        return self._n_mics

    def read(self, n_samples: int) -> AudioBlock:
        """``n_samples`` per channel from now on; advances the physics to the block's end."""
        n = int(n_samples)
        if n <= 0:
            raise ValueError(f"n_samples: expected > 0, got {n_samples}")
        fs = self.sample_rate
        n0 = int(round(self.robot.time * fs))
        chunk = max(1, int(round(self.chunk_s * fs)))
        bounds = list(range(0, n, chunk)) + [n]
        t_start, c_start = time.perf_counter(), time.process_time()
        mics = [self.robot.mic_positions()]
        poses = [self.robot.array_pose()]
        speeds = [self.robot.wheel_odometry().wheel_speeds]
        motors = [self.robot.motor_positions()] if self.ego_noise is not None else []
        for a, b in zip(bounds[:-1], bounds[1:]):
            self._step_to((n0 + b) / fs)
            mics.append(self.robot.mic_positions())
            poses.append(self.robot.array_pose())
            speeds.append(self.robot.wheel_odometry().wheel_speeds)
            if self.ego_noise is not None:
                motors.append(self.robot.motor_positions())
        self.last_array_poses = poses
        t_phys, c_phys = time.perf_counter(), time.process_time()
        self.timing["physics"] += t_phys - t_start
        self.cpu["physics"] += c_phys - c_start
        traj = np.stack(mics)  # poses at the chunk boundaries (n_chunks + 1, n_mics, 3)
        moved = float(np.max(np.linalg.norm(traj - traj[0], axis=-1)))
        mid = len(traj) // 2
        ego_pose = (traj[mid], motors[mid]) if self.ego_noise is not None else None
        if moved <= self.still_tolerance_m:
            used = _rigid_fit(traj[0], traj.mean(axis=0, keepdims=True))
            self._held = None
        else:
            self.moving_blocks += 1
            # Each chunk at the pose in its middle (mean of its end poses, made rigid again) or the held one.
            used = _rigid_fit(traj[0], 0.5 * (traj[:-1] + traj[1:]))
            if self.pose_hold_m > 0:
                for i in range(len(used)):
                    if self._held is not None and float(np.max(np.linalg.norm(used[i] - self._held[0], axis=-1))) \
                            <= self.pose_hold_m:
                        used[i] = self._held[0]
                    else:
                        self._held = (used[i].copy(), ego_pose)
                # the motors' paths held with the microphones' (they move together)
                ego_pose = self._held[1] if ego_pose is not None else None
        ego = None
        if ego_pose is not None:
            # Wheel speeds per sample (linear between chunk boundaries); motors and mics at the block's middle
            # (they move together: only the reflections' geometry changes along the block).
            w = np.stack([np.interp(np.arange(n), bounds, np.asarray(speeds)[:, i]) for i in range(3)])
            ego = self.ego_noise.pressure(ego_pose[0], ego_pose[1], w, n0)
            if not np.any(ego):
                ego = None
        if moved <= self.still_tolerance_m:
            x = self.acoustics.listen(used[0], n / fs, n0 / fs, extra_pressure=ego)
        else:
            x = np.concatenate([self.acoustics.listen(used[i], (b - a) / fs, (n0 + a) / fs,
                                                      extra_pressure=None if ego is None else ego[:, a:b])
                                for i, (a, b) in enumerate(zip(bounds[:-1], bounds[1:]))], axis=1)
        self.timing["acoustics"] += time.perf_counter() - t_phys
        self.cpu["acoustics"] += time.process_time() - c_phys
        self.blocks_read += 1
        block = AudioBlock(x, fs, n0 / fs)
        if self.on_block is not None:
            self.on_block(block, used)
        return block

    def _step_to(self, t_end: float) -> None:
        dt = self.robot.timestep
        steps = int(round((t_end - self.robot.time) / dt))
        if steps > 0:
            self.robot.step(steps * dt)

    def flush(self) -> None:
        """Nothing is buffered: a simulated array renders from the current physics time on."""


def _rigid_fit(reference: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """The rigid motion of ``reference`` (n_mics, 3) closest to each of ``targets`` (k, n_mics, 3) in least
    squares (Kabsch), applied to ``reference``: averaged poses of a turning array are slightly shrunk (the mean
    of two rotated points lies inside the arc), and the acoustics key the diffuse field on the exact
    inter-microphone distances, so the averaged array is made rigid again (moved by ~0.1 mm at 0.1 rad per chunk)."""
    ref_c = reference - reference.mean(axis=0)
    centres = targets.mean(axis=1, keepdims=True)
    h = np.einsum("mi,kmj->kij", ref_c, targets - centres)  # (k, 3, 3) cross-covariance
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.einsum("kji,klj->kil", vt, u)))  # det(V U^T): no reflections
    fix = np.ones((targets.shape[0], 3))
    fix[:, 2] = d
    rot = np.einsum("kji,kj,klj->kil", vt, fix, u)  # V diag(1, 1, d) U^T
    return np.einsum("kij,mj->kmi", rot, ref_c) + centres


def array_frame_directions(robot_or_origin, rotation_or_points, points_world=None
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Azimuth, elevation (rad) and distance (m) of world points ``(k, 3)`` seen from the array
    centre, in the ARRAY frame.

    ``array_frame_directions(robot, points)`` uses the robot's current ground-truth (possibly
    tilted) array pose; ``array_frame_directions(origin, rotation, points)`` a given one (origin
    (3,) world m, rotation (3, 3) whose columns are the array axes in the world)."""
    if points_world is None:
        origin, rot = robot_or_origin.array_pose()
        points_world = rotation_or_points
    else:
        origin, rot = np.asarray(robot_or_origin, float), np.asarray(rotation_or_points, float)
    d = (np.asarray(points_world, float).reshape(-1, 3) - origin) @ rot  # world -> array: R^T (p - o)
    r = np.linalg.norm(d, axis=1)
    az = np.arctan2(d[:, 1], d[:, 0])
    el = np.arcsin(np.clip(d[:, 2] / np.maximum(r, 1e-12), -1.0, 1.0))
    return az, el, r


@dataclass
class SimHal:
    """The simulated robot's HAL: ``audio``, ``drive`` and ``clock`` share ``robot`` (and its time)."""

    robot: SimRobot
    acoustics: AcousticSimulator
    audio: SimAudioSource
    drive: SimDriveBase
    clock: SimClock

    def close(self) -> None:
        self.drive.close()
        self.audio.close()


def make_sim_hal(world: World, sources: Sequence[SoundSource] | None = None,
                 acoustic_config: AcousticConfig | None = None, start: tuple[float, float, float] | None = None,
                 robot: SimRobot | None = None, chunk_s: float = 0.05,
                 ego_noise: EgoNoiseConfig | None = EgoNoiseConfig(), pose_hold_m: float = 0.0) -> SimHal:
    """Robot, acoustics and the three HAL backends for ``world``.

    ``sources``: sound sources (default: the world's victims with the config's default voices).
    ``start``: robot start pose (x, y, yaw) in the world (default ``world.robot_start``).
    ``robot``: an existing SimRobot of the same world to reuse instead of building one.
    ``ego_noise``: the drive's own noise while the wheels turn (None: silent drive). ``pose_hold_m``: see
    ``SimAudioSource``."""
    robot = robot if robot is not None else SimRobot(world, start=start)
    acoustics = AcousticSimulator(world, acoustic_config, sources=sources)
    return SimHal(robot, acoustics, SimAudioSource(robot, acoustics, chunk_s=chunk_s, ego_noise=ego_noise,
                                                  pose_hold_m=pose_hold_m), SimDriveBase(robot),
                  SimClock(robot))
