"""Run a rescue scenario headlessly: the real ``robot.rescue`` behaviour and ``ssl_core`` localizer on
the simulated HAL (``ssl_sim.backends``), scored against the ground truth.

    result = run_scenario("paper_lab", seed=0, rerun="save:out/run.rrd")
    result["n_found"], result["victims"][0]["time_s"], result["path_length_m"]

What is measured (all from the simulator's truth, never from the robot's own estimates):

* **found**, **false finds**, **reached** and **SPL**: every ``victim_found`` declaration (its reported position
  is the behaviour's map estimate, the robot base the truth at that moment) is scored by ``ssl_sim.scoring``,
  the one definition shared with the sweep, the benchmarks and the gym env (``docs/design/scoring.md``): a find
  is a report within 0.5 m of an unfound victim with the base within 1.5 m of her, in time; SPL per victim on
  its graph, to within 1.5 m of her, legs in the order found. The run ends when every victim is found, the
  behaviour finishes (stuck, fault, ``max_victims``) or the time limit passes (at the next step boundary).
* **path**: length of the true horizontal path of the base; **collisions**: contact episodes of
  the robot with walls or non-climbable obstacles (sampled every control tick; contacts less than
  ``COLLISION_GAP_S`` apart belong to one episode).
* **shortest paths** (``scoring.FreeSpaceGraph``) from the start to within 1.5 m of each victim, with
  straight-line lower bounds beside them. **reachable floor**: the area (m^2) within 1.5 m of a victim where
  the robot centre can stand, reachable from the start (0: no behaviour can be credited with her).
* **listens**: every localization with its detections against the true directions of all
  sources in the ARRAY frame at the listening pose (each detection is matched to the nearest
  source that was sounding during the block; errors in degrees); ``moving``: heard while driving.
* **wall clock**: seconds spent in physics (MuJoCo and the simulated drive's sensors: what hardware does on the
  robot), acoustics, localization, the runner's truth bookkeeping (``truth``) and the rest (``other``: the
  behaviour, with its voice evidence); under ``cpu`` the same split in CPU seconds of this process (a machine
  shared with other work inflates the wall clock, not the CPU time).

results.json also lists every declaration (``declarations``: reported position, base position, its kind:
find, false_find, too_far or late; ``cue``: the ``robot.rescue.FindCriterion`` that declared it), the finds counted
by that cue (``finds_by_criterion``), every move that ended early counted by why (``contacts_by_kind``:
``robot.motion.ContactKind``), the false finds alone (``false_finds``), ``n_reached``, the scoring
constants (``scoring``) and where the result came from (``provenance``: commit, package versions, BLAS kernel,
CPU).
"""
from __future__ import annotations

import functools
import hashlib
import json
import math
import os
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import asdict, replace
from pathlib import Path
from typing import Any

import numpy as np

from robot.odometry import Odometry, wrap_angle
from robot.ranging import RangeLayout, ray_ends
from robot.monitored_audio import MonitoredAudio
from robot.mount import ArrayMount
from robot.motion import ContactKind
from robot.events import ContactPayload, Decision, FindCriterion, RescueEvent
from robot.rescue import RescueBehaviour
from robot.vad import ModelError
from ssl_core.geometry import cube8
from ssl_core.health import HealthConfig, MicHealth
from ssl_core.localizer import Detection, Localizer
from ssl_sim.acoustics import AcousticSimulator
from ssl_sim.backends import SimAudioSource, array_frame_directions
from ssl_sim.calibration import ego_noise_suppressor
from robot.interrupt import check_interrupt
from ssl_sim.physics import SimClock, SimDriveBase, SimRobot
from ssl_sim.provenance import provenance
from ssl_sim.scenario import Scenario, load_scenario
from ssl_sim.scoring import FIND_BASE_RADIUS_M, SCORING, FreeSpaceGraph, Judge, leg_spls, run_spl
from ssl_sim.viz import NullLogger, RunLogger, make_logger
from ssl_sim.world import World

__all__ = ["RescueRun", "run_scenario", "write_results", "odometry_drift"]

#: A robot contact with a wall or blocking obstacle after this long without one is a new collision (s).
COLLISION_GAP_S = 0.5


# ----------------------------------------------------------------------------- instrumentation
class _Stopwatch:
    """Wall and CPU seconds (this process) spent inside its ``with`` blocks."""

    __slots__ = ("seconds", "cpu_s", "_t", "_c")

    def __init__(self) -> None:
        self.seconds = self.cpu_s = 0.0

    def __enter__(self) -> _Stopwatch:
        self._t, self._c = time.perf_counter(), time.process_time()
        return self

    def __exit__(self, *exc) -> None:
        self.seconds += time.perf_counter() - self._t
        self.cpu_s += time.process_time() - self._c


def _bookkeeping(hook):
    """Time a runner hook (truth, scoring, logging) on the run's ``truth`` stopwatch."""
    @functools.wraps(hook)
    def timed(self, *args, **kwargs):
        with self.truth:
            return hook(self, *args, **kwargs)
    return timed


class _TracingClock(SimClock):
    """SimClock that times the physics and calls ``on_tick`` after every sleep."""

    def __init__(self, robot: SimRobot, on_tick, physics: _Stopwatch) -> None:
        super().__init__(robot)
        self.on_tick, self.physics = on_tick, physics

    def sleep(self, seconds: float) -> None:
        with self.physics:
            super().sleep(seconds)
        self.on_tick()


class _TimedDrive(SimDriveBase):
    """The simulated drive with its sensor reads and commands timed as physics: on the robot they are the
    firmware's and the hardware's work, not the behaviour's."""

    def __init__(self, robot: SimRobot, physics: _Stopwatch, **kw) -> None:
        super().__init__(robot, **kw)
        self.physics = physics

    def set_twist(self, vx: float, vy: float, omega: float) -> None:
        with self.physics:
            super().set_twist(vx, vy, omega)

    def stop(self) -> None:
        with self.physics:
            super().stop()

    def odometry(self):
        with self.physics:
            return super().odometry()

    def status(self):
        with self.physics:
            return super().status()


class _RecordingLocalizer:
    """The real Localizer, timed, reporting each result (the behaviour sees the same object API)."""

    def __init__(self, localizer: Localizer, on_result, oracle=None) -> None:
        self._loc = localizer
        self.geometry = localizer.geometry
        self.config = localizer.config
        self.coarse_grid = localizer.coarse_grid
        self.on_result = on_result
        self.oracle = oracle   # (result, samples) -> the result the behaviour sees instead (an ablation)
        self.seconds = 0.0
        self.cpu_s = 0.0

    @property
    def ego_noise(self):
        return self._loc.ego_noise

    def locate(self, samples, **kw):
        t, c = time.perf_counter(), time.process_time()
        res = self._loc.locate(samples, **kw)
        self.seconds += time.perf_counter() - t
        self.cpu_s += time.process_time() - c
        if self.oracle is not None:
            res = self.oracle(res, samples)
        self.on_result(res, samples.shape[-1])
        return res

    def peak_in_sector(self, result, azimuth, half_width, recording=None):
        t, c = time.perf_counter(), time.process_time()
        peak = self._loc.peak_in_sector(result, azimuth, half_width, recording)
        self.seconds += time.perf_counter() - t
        self.cpu_s += time.process_time() - c
        return peak


def _deg(x: float) -> float:
    return round(math.degrees(x), 2)


def _r(x: float, n: int = 3) -> float | None:
    return None if x is None or not math.isfinite(x) else round(float(x), n)


def _unit(az: float, el: float) -> np.ndarray:
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


# ----------------------------------------------------------------------------- the run
#: A source sounds in a window when its own signal does in at least this share of the window's 10 ms frames.
SOUNDING_FRACTION = 0.1
#: A listen whose window moved the array more than this (m) was heard while driving (``listens[i]["moving"]``): a
#: parked robot creeps by millimetres, a drive at 0.25 m/s moves it 0.25 m in a 1 s window.
MOVING_M = 0.02

#: Ablations of the robot's hearing by name (``benchmarks/bench_rescue.py --oracle``, ``tools/failure_breakdown.py
#: --oracle``): the ``RescueRun`` switches each sets.
ORACLES: dict[str, dict[str, bool]] = {"no_false_detections": {"drop_false_detections": True},
                                       "exact_directions": {"snap_detections": True},
                                       "localization": {"oracle_localization": True},
                                       "hearing": {"oracle_localization": True, "oracle_voice": True}}


class RescueRun:
    """One scenario run with ``seed`` (default: the scenario's); ``run()`` returns the results dict.

    ``world``: the run's World if already built (``scenario.world(seed)``; sweeps build it on the
    client so that workers need no scene files). ``range_layout``: the robot's range sensors (None: a robot
    without them, which learns obstacles by touch alone).

    Ablations of the robot's hearing (``ORACLES`` names them; the robot itself is unchanged): ``oracle_localization``
    replaces SRP-PHAT's detections by the true directions of the sources sounding in each listen
    (``_oracle_detections``), ``drop_false_detections`` drops those of no sounding source (``_true_detections``),
    ``snap_detections`` also moves each of the others to the true direction of the sounding source it detected
    (``_snapped_detections``: what SRP-PHAT misses stays missed, what it finds is exact),
    ``oracle_voice`` replaces the VAD's voice evidence by the truth (``_oracle_speech``; the robot's voice scan is
    then off, as with any ``speech`` given to the behaviour).

    ``record_snr``: every listen's truth (``listens``) also gives each source's band SNR at the array in that window
    (``snr_db``: ``AcousticSimulator.band_snr_db``, its own sound against all the others' and the ambient field)
    and whether its straight path to the array is clear of obstacles (``line_of_sight``), for analysis of what the
    robot could have heard; it renders every source again on its own."""

    def __init__(self, scenario: Scenario, seed: int | None = None, logger: RunLogger | None = None,
                 world: World | None = None, range_layout: RangeLayout | None = RangeLayout(),
                 oracle_localization: bool = False, oracle_voice: bool = False,
                 drop_false_detections: bool = False, snap_detections: bool = False,
                 record_snr: bool = False) -> None:
        t0 = time.perf_counter()
        self.scenario = sc = scenario if seed is None else scenario.with_overrides(seed=seed)
        self.seed = sc.seed
        self.logger = logger or NullLogger()
        self.world = world = world if world is not None else sc.world()
        self.sources = sc.sources(world, fs=sc.localizer.fs)
        self.n_victims = len(world.victims)
        self.record_snr = record_snr
        # Parked physics skipped (SimRobot.park_settled): 12-14 % less CPU per run (bench_scenario seeds 0-3: 27.0x
        # and 28.6x instead of 24.7x and 25.1x), callers found 3, 3, 2, 3 vs 3, 3, 1, 3.
        self.robot = robot = SimRobot(world, park_settled=True)
        acoustics = AcousticSimulator(world, sc.acoustic_config(), sources=self.sources)
        if acoustics.config.fs != sc.localizer.fs:
            raise ValueError(f"localizer.fs = {sc.localizer.fs} Hz differs from the simulated audio "
                             f"({acoustics.config.fs} Hz)")
        # Hearing while driving renders a 50 ms read per control tick, each otherwise a new room response: a
        # driving array's response is held for 2.5 cm (SimAudioSource.pose_hold_m).
        hold = 0.025 if sc.behaviour.listen_while_driving else 0.0
        self.audio = SimAudioSource(robot, acoustics, on_block=self._on_block, ego_noise=sc.ego_noise,
                                    pose_hold_m=hold)
        self.physics, self.truth = _Stopwatch(), _Stopwatch()   # the loop's split (results' wall_clock_s)
        # The run's seed draws the gyro's noise and drift.
        self.drive = _TimedDrive(robot, self.physics, seed=sc.seed, range_layout=range_layout)
        self.clock = _TracingClock(robot, self._on_tick, self.physics)
        # The drive's noise is suppressed by a calibration of the simulated drive (ssl_sim.calibration), as the
        # robot's own calibration file does on hardware; a silent drive needs none.
        ego = None
        if sc.ego_noise is not None and sc.behaviour.listen_while_driving:
            ego = ego_noise_suppressor(sc.ego_noise, sc.localizer.fs, robot.config.array_height)
        localizer = Localizer(cube8(), sc.localizer, ego_noise=ego)
        self.localizer = _RecordingLocalizer(localizer, self._on_result,
                                             self._oracle_detections if oracle_localization
                                             else self._snapped_detections if snap_detections
                                             else self._true_detections if drop_false_detections else None)
        # The robot's microphone health monitor, as on the real robot (faults go to rerun and results).
        self.mic_health = MonitoredAudio(self.audio, MicHealth(cube8(), HealthConfig(fs=sc.localizer.fs)),
                                         localizer, on_change=self._on_mic_faults)
        stages = sc.stage_configs()
        if stages["coverage"].area is None:
            # The search area, as a rescuer's floor plan gives it: the room's floor (world = odometry frame here).
            stages["coverage"] = replace(stages["coverage"], area=(0.0, 0.0, *map(float, world.room.size[:2])))
        # The behaviour's array height is the simulated robot's: its cube sits at the model's array_height.
        self.mount = ArrayMount(height_m=robot.config.array_height)
        self.behaviour = RescueBehaviour(self.mic_health, self.drive, self.clock, self.localizer, sc.behaviour,
                                         params=robot.params, mount=self.mount, start_pose=world.robot_start,
                                         speech=self._oracle_speech if oracle_voice else None, **stages)
        self.paths = FreeSpaceGraph(world)
        self.judge = Judge([s.position for s in self.sources[: self.n_victims]], sc.time_limit_s)
        # truth bookkeeping
        self._obstacle_blocks = [not b.climbable for b in world.obstacles]
        self.trajectory: list[tuple[float, float, float, float, float]] = []  # t, x, y, z, yaw
        self.cum_path: list[float] = []
        self.collisions: list[dict] = []
        self._last_contact_t = -math.inf
        self.listens: list[dict] = []
        self.found: dict[int, dict] = {}       # victim -> the declaration that found her
        self.declarations: list[dict] = []     # every declaration with its judgement
        self._find_legs: list[tuple[int, tuple[float, float], float]] = []   # victim, base xy, path (m), in order
        self.events: list[RescueEvent] = []
        self._blocks: list[tuple[int, int, list]] = []   # recent reads: first sample, length, array poses
        self._ticks = 0
        self.failure: dict[str, str] | None = None   # what failed, when a part of the robot ended the run
        self.setup_s = time.perf_counter() - t0
        self._record_pose()

    # -- hooks ----------------------------------------------------------------------------
    def _record_pose(self) -> None:
        p = self.robot.pose()
        t = self.robot.time
        if self.trajectory:
            _, x0, y0, _, _ = self.trajectory[-1]
            self.cum_path.append(self.cum_path[-1] + math.hypot(p.x - x0, p.y - y0))
        else:
            self.cum_path.append(0.0)
        self.trajectory.append((t, p.x, p.y, p.z, p.yaw))
        if self.logger.enabled:
            self.logger.robot(t, np.array([p.x, p.y, p.z]), p.quat, self.robot.mic_positions(),
                              self.robot.wheel_odometry().wheel_speeds)
            self._ticks += 1
            if self._ticks % 20 == 0:
                self.logger.trail(t, np.array([row[1:4] for row in self.trajectory[::4]] + [[p.x, p.y, p.z]]))

    @_bookkeeping
    def _on_tick(self) -> None:
        check_interrupt()  # every control tick and audio block (robot.interrupt)
        self._record_pose()
        touching = None
        for c in self.robot.contacts():
            blocking = c.obstacle is None or (0 <= c.obstacle < len(self._obstacle_blocks)
                                              and self._obstacle_blocks[c.obstacle])
            if blocking:
                touching = c
                break
        now = self.robot.time
        # One collision per contact episode: contacts chatter while pushing, so a new episode needs
        # COLLISION_GAP_S without contact before it.
        if touching is not None:
            if now - self._last_contact_t > COLLISION_GAP_S:
                self.collisions.append({"time_s": _r(now, 2), "position": [_r(v) for v in touching.position],
                                        "obstacle": touching.obstacle, "geom": touching.world_geom})
            self._last_contact_t = now

    def _on_mic_faults(self, t: float, new, cleared) -> None:
        for state, faults in (("microphone fault", new), ("microphone fault cleared", cleared)):
            for f in faults:
                self.logger.event(t, "health", f"{state}: {f}", "WARN" if f in new else "INFO")

    @_bookkeeping
    def _on_block(self, block, mics) -> None:
        n0 = int(round(block.timestamp * block.sample_rate))
        self._blocks.append((n0, block.samples.shape[1], self.audio.last_array_poses))
        del self._blocks[:-64]    # a heard window spans at most a second of 50 ms reads
        self._on_tick()           # a read advances the world as a clock tick does: pose, contacts

    def _window(self, n_samples: int) -> tuple[tuple[np.ndarray, np.ndarray], tuple[int, int] | None]:
        """The array's pose (origin, rotation; world) at the middle of the window of the last ``n_samples``
        samples read, and that window (first sample, length): a window heard while driving is many reads."""
        if not self._blocks:
            return self.robot.array_pose(), None
        n0, n, _ = self._blocks[-1]
        start = n0 + n - int(n_samples)
        middle = start + 0.5 * n_samples
        for b0, bn, poses in reversed(self._blocks):   # contiguous reads: the last one starting before the middle
            if b0 <= middle:
                k = int(round(min(max((middle - b0) / bn, 0.0), 1.0) * (len(poses) - 1))) if poses else 0
                return (poses[k] if poses else self.robot.array_pose()), (start, int(n_samples))
        return self.robot.array_pose(), (start, int(n_samples))

    def _moved_m(self, n_samples: int) -> float:
        """How far (m) the array centre moved over the window of the last ``n_samples`` samples read (0 for a
        window of one pose: a listen standing still)."""
        if not self._blocks:
            return 0.0
        n0, n, _ = self._blocks[-1]
        start = n0 + n - int(n_samples)
        poses = [p for b0, bn, ps in self._blocks if b0 + bn > start for p in (ps or ())]
        return float(np.linalg.norm(poses[-1][0] - poses[0][0])) if len(poses) > 1 else 0.0

    def _sources_heard(self, n_samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every source's azimuth, elevation (rad, array frame) and distance (m) at the middle of the window of the
        last ``n_samples`` samples read (a parked robot creeps slightly; a driving one moves), and the fraction of
        its 10 ms frames in that window in which it sounds (its own signal's RMS above 0.05 full scale)."""
        pos = np.array([s.position for s in self.sources]).reshape(-1, 3)
        (origin, rot), window = self._window(n_samples)
        az, el, dist = array_frame_directions(origin, rot, pos)
        active = np.ones(len(self.sources))
        if window is not None:
            n0, n = window
            for k, s in enumerate(self.sources):
                x = s.signal.render(n0, n)
                fr = x[: n // 160 * 160].reshape(-1, 160)
                active[k] = float(np.mean(np.sqrt(np.mean(fr**2, axis=1)) > 0.05)) if fr.size else 0.0
        return az, el, dist, active

    @_bookkeeping
    def _oracle_detections(self, res, samples):
        """``res`` with the truth's detections instead of SRP-PHAT's: one per source sounding in the window
        (``SOUNDING_FRACTION``), whatever its level, at its true direction (array frame), strongest beam first. Its
        power and level are the SRP-PHAT peak's and the delay-and-sum beam's within 3 deg of that azimuth (the power
        at least the behaviour's ``min_power``, so that none is ignored), its significance infinite. An ablation
        (``oracle_localization``): what the behaviour does with perfect localization."""
        az, el, _, active = self._sources_heard(samples.shape[-1])
        floor = self.scenario.behaviour.min_power
        dets = []
        for k in np.flatnonzero(active >= SOUNDING_FRACTION):
            peak = self.localizer.peak_in_sector(res, float(az[k]), math.radians(3.0), samples)
            power, level = (max(peak.power, floor), peak.level_db) if peak is not None else (floor, res.level_db)
            dets.append(Detection(float(az[k]), float(el[k]), _unit(az[k], el[k]), float(power), float(level),
                                  math.inf))
        dets.sort(key=lambda d: -d.level_db)
        return replace(res, detections=dets)

    @_bookkeeping
    def _true_detections(self, res, samples):
        """``res`` without its false detections (``drop_false_detections``, an ablation): those more than 10 deg
        from every source sounding in the window (``SOUNDING_FRACTION``). What SRP-PHAT misses stays missed."""
        az, el, _, active = self._sources_heard(samples.shape[-1])
        dirs = np.array([_unit(az[k], el[k]) for k in np.flatnonzero(active >= SOUNDING_FRACTION)]).reshape(-1, 3)
        cos = math.cos(math.radians(10.0))
        return replace(res, detections=[d for d in res.detections
                                        if len(dirs) and float(np.max(dirs @ np.asarray(d.direction, float))) >= cos])

    @_bookkeeping
    def _snapped_detections(self, res, samples):
        """``res``'s detections of sounding sources (within 10 deg of one sounding in the window,
        ``SOUNDING_FRACTION``), each moved to that source's true direction (array frame), the others dropped
        (``snap_detections``, an ablation): SRP-PHAT's misses and its power, level and significance kept, its
        direction errors and false detections gone."""
        az, el, _, active = self._sources_heard(samples.shape[-1])
        sounding = np.flatnonzero(active >= SOUNDING_FRACTION)
        if not len(sounding):
            return replace(res, detections=[])
        dirs = np.array([_unit(az[k], el[k]) for k in sounding])
        cos = math.cos(math.radians(10.0))
        dets = []
        for d in res.detections:
            c = dirs @ np.asarray(d.direction, float)
            j = int(np.argmax(c))
            if c[j] >= cos:
                k = sounding[j]
                dets.append(replace(d, azimuth=float(az[k]), elevation=float(el[k]), direction=dirs[j].copy()))
        return replace(res, detections=dets)

    @_bookkeeping
    def _oracle_speech(self, samples, detection, direction) -> float:
        """The behaviour's voice evidence from the truth (``oracle_voice``, an ablation): a beam toward a victim who
        sounds in the window (``SOUNDING_FRACTION``) within 5 deg of ``direction`` (unit vector, array frame) is all
        speech (fraction 1), any other beam none."""
        az, el, _, active = self._sources_heard(np.shape(samples)[-1])
        u, cos = np.asarray(direction, float), math.cos(math.radians(5.0))
        return float(any(active[k] >= SOUNDING_FRACTION and float(u @ _unit(az[k], el[k])) >= cos
                         for k in range(self.n_victims)))

    @_bookkeeping
    def _on_result(self, res, n_samples: int) -> None:
        t = self.robot.time
        pose = self.robot.pose()
        az, el, dist, active = self._sources_heard(n_samples)
        truth = [{"name": s.name, "kind": s.kind, "azimuth_deg": _deg(a), "elevation_deg": _deg(e),
                  "distance_m": _r(d), "active_fraction": _r(f, 2), "active": bool(f >= SOUNDING_FRACTION),
                  "direction": _unit(a, e)} for s, a, e, d, f in zip(self.sources, az, el, dist, active)]
        if self.record_snr:
            (origin, rot), window = self._window(n_samples)
            if window is not None:
                mics = origin + cube8().positions @ rot.T   # the array at the window's middle (world frame)
                acoustics = self.audio.acoustics
                for s, v, los in zip(truth, acoustics.band_snr_db(mics, *window), acoustics.line_of_sight(origin)):
                    s["snr_db"] = _r(float(v), 1)   # None: silent in the window (or alone in a silent room)
                    s["line_of_sight"] = bool(los)
        candidates = [k for k, s in enumerate(truth) if s["active"]] or list(range(len(truth)))
        dets = []
        for d in res.detections:
            u = np.asarray(d.direction, float)
            errs = [math.degrees(math.acos(float(np.clip(u @ truth[k]["direction"], -1, 1)))) for k in candidates]
            j = candidates[int(np.argmin(errs))] if candidates else None
            row = {**d.to_dict(), "direction": u}
            if j is not None:
                row.update({"source": truth[j]["name"], "source_kind": truth[j]["kind"],
                            "error_deg": round(min(errs), 2),
                            "azimuth_error_deg": _deg(wrap_angle(d.azimuth - az[j])),
                            "elevation_error_deg": _deg(d.elevation - el[j])})
            dets.append(row)
        rec = {"time_s": _r(t, 3), "pose": [_r(pose.x), _r(pose.y), _r(pose.yaw, 4)],
               "moving": self._moved_m(n_samples) > MOVING_M,
               "level_db": _r(res.level_db, 2), "active_frames": int(res.active_frames),
               "sources": [{k: v for k, v in s.items() if k != "direction"} for s in truth],
               "detections": [{k: v for k, v in d.items() if k != "direction"} for d in dets]}
        self.listens.append(rec)
        if self.logger.enabled:
            self.logger.listen(t, res.srp_map, self.localizer.coarse_grid.directions, dets, truth)
            unfound = [i for i in range(self.n_victims) if i not in self.found]
            near = min((math.hypot(pose.x - self.sources[i].position[0], pose.y - self.sources[i].position[1])
                        for i in unfound), default=None)
            self.logger.scalars(t, {"angular_error_deg": dets[0].get("error_deg") if dets else None,
                                    "distance_to_victim_m": near,
                                    "srp_peak_power": float(res.detections[0].power) if res.detections else 0.0})

    def _pose_at(self, t: float) -> tuple[float, float, float, float, float]:
        times = [row[0] for row in self.trajectory]
        k = max(0, int(np.searchsorted(times, t + 1e-9)) - 1)
        return self.trajectory[k]

    def _path_at(self, t: float) -> float:
        times = [row[0] for row in self.trajectory]
        k = max(0, int(np.searchsorted(times, t + 1e-9)) - 1)
        return self.cum_path[k]

    @_bookkeeping
    def _handle_events(self, events: list[RescueEvent]) -> None:
        sc = self.scenario
        for ev in events:
            self.events.append(ev)
            if self.logger.enabled:
                level = "WARN" if ev.decision in (Decision.RECOVER, Decision.STUCK, Decision.DRIVE_FAULT,
                                                  Decision.ERROR) else "INFO"
                self.logger.event(ev.time, ev.state.value, str(ev), level)
                if ev.decision is Decision.TARGET and self.audio.last_array_poses:
                    # Decided right after the listen: the array pose at the end of that block.
                    origin, rot = self.audio.last_array_poses[-1]
                    self.logger.target(ev.time, origin, rot @ _unit(ev.data.azimuth, ev.data.elevation))
            if ev.decision is not Decision.VICTIM_FOUND:
                continue
            _, x, y, _, _ = self._pose_at(ev.time)
            est = ev.data.position
            j = self.judge.declare(ev.time, est, (x, y))
            entry = {"time_s": _r(ev.time, 2), "criterion": ev.data.criterion, "cue": str(ev.data.cue),
                     "kind": j.kind,
                     "estimate": [_r(est[0]), _r(est[1])], "robot_position": [_r(x), _r(y)],
                     "victim": self.sources[j.victim].name if j.victim is not None else None,
                     "estimate_error_m": _r(j.report_error_m), "robot_distance_m": _r(j.base_distance_m),
                     "reached": self.sources[j.reached].name if j.reached is not None else None,
                     "late": j.late}
            self.declarations.append(entry)
            if j.kind == "find":
                self.found[j.victim] = entry
                self._find_legs.append((j.victim, (x, y), self._path_at(ev.time)))  # unrounded, for SPL
                if self.logger.enabled:
                    order = sorted(self.found)
                    h = [ev.data.height] * len(order)
                    est = np.array([[*self.found[k]["estimate"], hk] for k, hk in zip(order, h)], float)
                    self.logger.found(ev.time, est, np.array([self.sources[k].position for k in order]),
                                      [f"{self.sources[k].name} (off {self.found[k]['estimate_error_m']:.2f} m)"
                                       for k in order])

    def _log_map(self) -> None:
        """The behaviour's own picture: sound map, plan, learned obstacles, listening coverage (odometry frame =
        world frame here)."""
        b, t = self.behaviour, self.robot.time
        self.logger.sound_map(t, b.map.sources)
        self.logger.plan(t, b.pose[:2], None if b.plan is None else b.plan.waypoints)
        self.logger.obstacles(t, b.grid.obstacle_points(), b.grid.resolution)
        if self.drive.last_ranges is not None:
            starts, ends, hit = ray_ends(b.range_layout, b.pose, self.drive.last_ranges)
            z = np.full((len(starts), 1), b.range_layout.height_m)
            self.logger.ranges(t, np.hstack([starts, z]), np.hstack([ends, z]), hit)
        heard = b.coverage.in_area & (b.coverage.unheard < 1.0)
        ij = np.argwhere(heard)
        self.logger.coverage(t, b.grid.centre(ij), b.coverage.unheard[heard])

    # -- main loop ------------------------------------------------------------------------
    def run(self, progress: bool = False, close_logger: bool = True) -> dict[str, Any]:
        """Run to the end; ``close_logger=False`` leaves the (possibly slow) viewer flush to the caller,
        e.g. to write the results first."""
        sc = self.scenario
        self.logger.start(self.world, self.sources, self.robot.config,
                          f"{sc.name} (seed {self.seed}): {sc.description}")
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=round(sc.time_limit_s), unit="sim s", desc=sc.name, leave=True,
                       bar_format="{l_bar}{bar}| {n:.0f}/{total_fmt} sim s [{elapsed}<{remaining}{postfix}]")
            bar.set_postfix_str(f"found 0/{self.n_victims}")
        t_wall, c_loop = time.perf_counter(), time.process_time()
        end_reason = "time_up"
        try:
            while True:
                if len(self.found) == self.n_victims:
                    end_reason = "all_found"
                    break
                if self.behaviour.done:
                    last = self.behaviour.events[-1].decision if self.behaviour.events else "done"
                    end_reason = f"behaviour_{last}"
                    break
                if self.clock.now() >= sc.time_limit_s:
                    break
                try:
                    self._handle_events(self.behaviour.step())
                except ModelError as exc:   # the run failed (the drive is stopped): said so, never "audio ended"
                    self.failure = {"part": "model", "file": str(exc.path), "error": str(exc)}
                    end_reason = "failed_model"
                    break
                if self.logger.enabled:
                    self._log_map()
                if bar is not None:
                    bar.n = min(self.clock.now(), sc.time_limit_s)
                    bar.set_postfix_str(f"found {len(self.found)}/{self.n_victims}")
        finally:
            self.drive.stop()
            if bar is not None:
                bar.close()
        loop_s = time.perf_counter() - t_wall
        self._loop_cpu_s = time.process_time() - c_loop
        if self.logger.enabled:
            self.logger.trail(self.robot.time, np.array([row[1:4] for row in self.trajectory]))
            if close_logger:
                self.logger.close()
        return self._results(end_reason, loop_s)

    def fingerprint(self) -> str:
        """What the run did, hashed to the last bit (16 hex digits): the true trajectory at full precision, every
        decision (time, kind, reason, payload) and every listen's record. Two versions of the code whose seeded runs
        give the same fingerprint gave the same run: how a pure speed-up shows it changed nothing."""
        h = hashlib.sha256(np.asarray(self.trajectory, float).tobytes())
        for e in self.events:
            h.update(repr((e.time, e.state.value, e.decision.value, e.reason, e.data.to_dict())).encode())
        h.update(json.dumps(self.listens, sort_keys=True, default=repr).encode())
        return h.hexdigest()[:16]

    def _cpu_split(self) -> dict[str, float | None]:
        """The loop's CPU seconds (this process) split as the wall clock is (``wall_clock_s``)."""
        loop = getattr(self, "_loop_cpu_s", 0.0)
        phys = self.physics.cpu_s + self.audio.cpu["physics"]
        acou, loc, truth = self.audio.cpu["acoustics"], self.localizer.cpu_s, self.truth.cpu_s
        return {"loop": _r(loop, 3), "physics": _r(phys, 3), "acoustics": _r(acou, 3), "localization": _r(loc, 3),
                "truth": _r(truth, 3), "other": _r(loop - phys - acou - loc - truth, 3)}

    def _results(self, end_reason: str, loop_s: float) -> dict[str, Any]:
        sc = self.scenario
        start = self.world.robot_start[:2]
        vxy = [s.position[:2] for s in self.sources[: self.n_victims]]
        legs = {leg.victim: leg for leg in leg_spls(self.paths, vxy, start, self._find_legs)}
        reached = {k: j.time_s for k, j in self.judge.reached.items()}
        victims = []
        for i in range(self.n_victims):
            s = self.sources[i]
            row = {"name": s.name, "position": list(s.position), "buried": s.buried, "level_db_spl": s.level_db_spl,
                   "found": i in self.found, "time_s": None, "reached": i in reached,
                   "reached_time_s": _r(reached.get(i), 2),
                   "shortest_path_from_start_m": _r(self.paths.shortest_path(start, s.position, FIND_BASE_RADIUS_M)),
                   "straight_line_from_start_m": _r(max(0.0, math.hypot(s.position[0] - start[0],
                                                                        s.position[1] - start[1])
                                                        - FIND_BASE_RADIUS_M)),
                   "reachable_floor_m2": _r(self.paths.reachable_area(start, s.position, FIND_BASE_RADIUS_M), 4),
                   "spl": 0.0}
            if i in self.found:
                leg = legs[i]
                row.update({k: v for k, v in self.found[i].items() if k not in ("kind", "victim")})
                row.update({"leg_start": [_r(leg.start_xy[0]), _r(leg.start_xy[1])], "leg_path_m": _r(leg.path_m),
                            "leg_shortest_path_m": _r(leg.shortest_m), "spl": leg.spl})
            victims.append(row)
        errs = np.array([d["error_deg"] for rec in self.listens for d in rec["detections"] if "error_deg" in d])
        first = np.array([rec["detections"][0]["error_deg"] for rec in self.listens
                          if rec["detections"] and "error_deg" in rec["detections"][0]])

        def stats(a: np.ndarray) -> dict[str, Any]:
            if not a.size:
                return {"n": 0, "mean": None, "median": None, "p90": None, "max": None}
            return {"n": int(a.size), "mean": _r(a.mean(), 2), "median": _r(np.median(a), 2),
                    "p90": _r(np.percentile(a, 90), 2), "max": _r(a.max(), 2)}

        phys = self.physics.seconds + self.audio.timing["physics"]
        acou = self.audio.timing["acoustics"]
        loc, truth = self.localizer.seconds, self.truth.seconds
        sim_t = self.robot.time
        bumps = bumper_recoveries(self.events)
        return {
            "scenario": sc.name, "scenario_file": sc.path, "seed": self.seed, "scene": self.world.name,
            "fingerprint": self.fingerprint(),
            "description": sc.description,
            "n_victims": self.n_victims, "n_found": len(self.found), "success": len(self.found) == self.n_victims,
            "n_reached": len(reached),
            "end_reason": end_reason, "failure": self.failure, "time_limit_s": sc.time_limit_s,
            "sim_time_s": _r(sim_t, 2),
            "scoring": SCORING,
            "victims": victims, "false_finds": [d for d in self.declarations if d["kind"] == "false_find"],
            "declarations": self.declarations,
            "spl": run_spl(self.n_victims, list(legs.values())),
            "path_length_m": _r(self.cum_path[-1]), "collisions": len(self.collisions),
            "collision_log": self.collisions, "bumper_recoveries": bumps,
            "range_stops": sum(1 for e in self.events if e.decision is Decision.OBSTACLE),
            **outcome_counts(self.behaviour, self.declarations),
            "n_listens": len(self.listens),
            "angular_error_deg": {"all_detections": stats(errs), "strongest_detection": stats(first)},
            "listens": self.listens,
            "events": [str(e) for e in self.events],
            "microphone_faults": [{"time_s": _r(t, 2), "state": state, "kind": f.kind, "channels": list(f.channels),
                                   "detail": f.detail} for t, state, f in self.mic_health.history],
            "config": {"behaviour": asdict(sc.behaviour), "localizer": asdict(sc.localizer),
                       **{k: asdict(v) for k, v in sc.stage_configs().items()}, "mount": asdict(self.mount),
                       "acoustics": dict(sc.acoustics),
                       "noise": asdict(sc.noise) if sc.noise is not None else None},
            "provenance": provenance(),
            "wall_clock_s": {"setup": _r(self.setup_s, 3), "loop": _r(loop_s, 3), "physics": _r(phys, 3),
                             "acoustics": _r(acou, 3), "localization": _r(loc, 3), "truth": _r(truth, 3),
                             "other": _r(loop_s - phys - acou - loc - truth, 3),
                             "per_sim_second": _r(loop_s / max(sim_t, 1e-9), 4), "cpu": self._cpu_split()},
        }


def bumper_recoveries(events: list[RescueEvent]) -> int:
    """Contacts mapped with the bumper pressed (the robot backed off)."""
    return sum(1 for e in events if isinstance(e.data, ContactPayload) and e.data.bumper)


def outcome_counts(behaviour: RescueBehaviour, declarations: list[dict]) -> dict[str, dict[str, int]]:
    """``contacts_by_kind``: the behaviour's moves that ended early, by ``ContactKind``; ``finds_by_criterion``: the
    declarations scored "find", by the ``FindCriterion`` that declared them (every member listed, zeros too)."""
    return {"contacts_by_kind": {k.value: behaviour.contacts[k] for k in ContactKind},
            "finds_by_criterion": {c.value: sum(1 for d in declarations if d["kind"] == "find" and d.get("cue") == c)
                                   for c in FindCriterion}}


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, tuple):
        return list(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


class OutputPathError(ValueError):
    """An output location cannot be written."""


def check_output_dir(path: str | Path, what: str = "out_dir") -> Path:
    """Create directory ``path`` if needed and prove it writable now, before a long simulation;
    raises :class:`OutputPathError` naming ``what`` (the option or argument)."""
    p = Path(path)
    try:
        p.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=p, prefix=".write-test-"):
            pass
    except OSError as exc:
        raise OutputPathError(f"{what} {p}: cannot write there ({exc.strerror or exc})") from None
    return p


@contextmanager
def output_dir(path: str | Path, what: str = "out_dir") -> Iterator[Path]:
    """``check_output_dir`` for the body's outputs; when the body raises (a refused or failed run), the
    directories made here are removed again while still empty, so that a refused run leaves nothing behind."""
    p = Path(path)
    new = [d for d in (p, *p.parents) if not d.exists()]   # deepest first
    check_output_dir(p, what)
    try:
        yield p
    except BaseException:
        for d in new:
            try:
                d.rmdir()
            except OSError:   # not empty (the run wrote something) or gone: keep the rest
                break
        raise


def write_results(result: dict, out_dir: str | Path, name: str = "results.json") -> Path:
    """Write ``result`` as JSON to ``out_dir/name`` atomically: a reader (or a run killed meanwhile) never
    leaves or sees half a file."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    p = out / name
    tmp = out / f".{name}.partial"
    tmp.write_text(json.dumps(result, indent=1, default=_json_default))
    os.replace(tmp, p)
    return p


def run_scenario(scenario: Scenario | str | Path, seed: int | None = None, *, time_limit_s: float | None = None,
                 rerun: str | None = None, out_dir: str | Path | None = None, progress: bool = False) -> dict:
    """Run a scenario (object, shipped name or TOML path) and return its results dict.

    ``rerun``: ``save:PATH`` / ``spawn`` / ``connect[:ADDR]`` (see ``ssl_sim.viz``), None = no logging;
    an unreachable viewer falls back to ``out_dir/rescue.rrd`` (or no logging) with a warning.
    ``out_dir``: also write ``results.json`` there. Output locations are checked before simulating and the
    results are written before the viewer is flushed, so a finished run is not lost."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    sc = sc.with_overrides(seed=seed, time_limit_s=time_limit_s)
    out = None if out_dir is None else check_output_dir(out_dir)
    if rerun and rerun.startswith("save:"):
        check_output_dir(Path(rerun[5:]).parent, "rerun save path")
    logger = make_logger(rerun, recording_name=f"{sc.name} seed {sc.seed}",
                         fallback_save=None if out is None else out / "rescue.rrd")
    try:
        result = RescueRun(sc, logger=logger).run(progress=progress, close_logger=False)
        if logger.path is not None:
            result["rerun_file"] = str(logger.path)
        if out is not None:
            write_results(result, out)
    finally:
        logger.close()
    return result


def odometry_drift(scenario: Scenario | str | Path, seed: int, duration_s: float = 200.0,
                   range_sensors: bool = True) -> dict[str, Any]:
    """How far the behaviour's gyro-aided odometry drifts in ``duration_s`` s of a rescue run, against MuJoCo's truth,
    beside a wheels-only ``Odometry`` fed the same encoder readings. The behaviour runs the whole duration (after the
    last find it keeps exploring, bumps included); headings in deg, positions in m, rates in deg/s.
    ``range_sensors`` False: a robot without them, which meets obstacles by bumping into them."""
    sc = scenario if isinstance(scenario, Scenario) else load_scenario(scenario)
    run = RescueRun(sc.with_overrides(seed=seed, time_limit_s=duration_s),
                    range_layout=RangeLayout() if range_sensors else None)
    beh = run.behaviour
    wheels = Odometry(run.robot.params, run.world.robot_start)
    fused_update = beh.odometry.update

    def both(reading, yaw_rate=None, stationary=False):
        wheels.update(reading)
        return fused_update(reading, yaw_rate, stationary)

    beh.odometry.update = both
    t0 = time.process_time()
    while run.clock.now() < duration_s and not beh.done:
        run._handle_events(beh.step())
    truth = run.robot.pose()

    def errors(pose) -> tuple[float, float]:
        return abs(_deg(wrap_angle(pose[2] - truth.yaw))), math.hypot(pose[0] - truth.x, pose[1] - truth.y)

    (hf, pf), (hw, pw) = errors(beh.odometry.pose), errors(wheels.pose)   # pf, pw unrounded (m)
    return {"scenario": sc.name, "seed": seed, "sim_time_s": run.robot.time, "cpu_s": time.process_time() - t0,
            "bumper_recoveries": bumper_recoveries(run.events),
            "range_stops": sum(1 for e in run.events if e.decision is Decision.OBSTACLE),
            "n_found": len(run.found), "heading_error_deg": hf, "position_error_m": pf,
            "wheels_heading_error_deg": hw, "wheels_position_error_m": pw,
            "gyro_bias_deg_s": round(math.degrees(run.drive.gyro_bias), 4),
            "gyro_bias_estimate_deg_s": round(math.degrees(beh.odometry.gyro_bias), 4),
            "bias_updates": beh.odometry.bias_updates, "slip_intervals": beh.odometry.slip_intervals,
            "loaded_intervals": beh.odometry.loaded_intervals}


def format_summary(result: dict) -> str:
    """A short human-readable account of a run (what the CLI and ``make demo`` print)."""
    r = result
    lines = [f"scenario {r['scenario']} (seed {r['seed']}, scene {r['scene']}): "
             f"found {r['n_found']}/{r['n_victims']} victim(s) in {r['sim_time_s']:.1f} s simulated "
             f"(limit {r['time_limit_s']:g} s, end: {r['end_reason']})"]
    for v in r["victims"]:
        if v["found"]:
            lines.append(f"  {v['name']:<14} found at {v['time_s']:6.1f} s, robot {v['robot_distance_m']:.2f} m "
                         "from it, "
                         f"estimate off by {v['estimate_error_m']:.2f} m; leg {v['leg_path_m']:.2f} m driven vs "
                         f"{v['leg_shortest_path_m']:.2f} m shortest (SPL {v['spl']:.2f}); {v['criterion']}")
        else:
            lines.append(f"  {v['name']:<14} NOT found{' (reached)' if v['reached'] else ''} (shortest path from "
                         f"start {v['shortest_path_from_start_m']} m, {v['reachable_floor_m2']} m^2 of reachable "
                         "floor within 1.5 m)")
    for d in r["declarations"]:
        if d["kind"] != "find":
            lines.append(f"  {d['kind'].replace('_', ' ')} at {d['time_s']} s: report {d['estimate_error_m']} m and "
                         f"robot {d['robot_distance_m']} m from {d['victim']}")
    a = r["angular_error_deg"]["all_detections"]
    err = (f"median {a['median']:.1f} deg, mean {a['mean']:.1f} deg, p90 {a['p90']:.1f} deg over {a['n']} detections"
           if a["n"] else "no detections")
    lines.append(f"  path {r['path_length_m']:.2f} m, {r['collisions']} collision(s), {r['bumper_recoveries']} bumper "
                 f"recoveries, {r['range_stops']} range stops, {r['n_listens']} listens; direction error {err}; "
                 f"SPL {r['spl']:.2f}")
    w = r["wall_clock_s"]
    lines.append(f"  wall clock {w['loop']:.1f} s ({1 / max(w['per_sim_second'], 1e-9):.1f}x real time): physics "
                 f"{w['physics']:.1f} s, acoustics {w['acoustics']:.1f} s, localization {w['localization']:.1f} s, "
                 f"truth bookkeeping {w['truth']:.1f} s, behaviour {w['other']:.1f} s")
    return "\n".join(lines)
