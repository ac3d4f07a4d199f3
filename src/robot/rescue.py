"""The rescue behaviour: listen, update the belief, declare what the belief says is found, do what is worth most.

One cycle (``RescueBehaviour._cycle``) walks the data path, each stage in its own module:

* **hear** standing still (``robot.listening``: SRP-PHAT detections, tracks, voice evidence; ARRAY frame), and
  with ``listen_while_driving`` also every ``listen_s`` of a move (``robot.drive_hearing``: the drive's noise
  suppressed; the move ends early when what it heard changes the option worth most);
* **believe** (``robot.sound_map`` + ``robot.coverage``): world-frame sources with position, covariance and
  P(victim); per floor cell, P(a caller there is still unheard);
* **found** (``robot.found``): every unfound source near the robot or heard now is judged by P(a victim lies within
  the find radius of its estimate), a logistic model whose cues are fitted on the benchmark's train split; at
  ``p_find`` or above it is declared (one knob: false finds against time);
* **choose** (``robot.options``): approach, triangulate, explore, listen again or recover, valued in expected
  victims confirmed per second; per-source pursuit state in ``robot.pursuit``;
* **move** (``robot.motion``, ``robot.recovery``): translate (holonomic base, omnidirectional array: no turning)
  at most ``step_m`` along the plan, then listen again.

Frames: evidence in the array frame (azimuth CCW from the robot's forward); poses, map and grid in the odometry
frame (``start_pose`` sets it). The drive is stopped at the end of every step and on any exception.
"""
from __future__ import annotations

import logging
import math
from collections import Counter
from dataclasses import replace

import numpy as np

from robot.coverage import CoverageConfig, ListeningCoverage
from robot.drive_hearing import DriveHearing
# The behaviour's vocabulary (robot.events), importable from here too.
from robot.events import (Decision, DrivePayload, FindCriterion, FoundPayload, HeardCandidate, HeardPayload,
                          ObstaclePayload, RescueEvent, RescueState, SourcePayload, TargetPayload)
from robot.found import FIND_RADIUS_M, Assessment, Finder, FoundModel
from robot.hal import AudioSource, Clock, DriveBase
from robot.kinematics import OmniDriveParams
from robot.listening import Listen, ListenEvidence, Listener
from robot.mission import Mission
from robot.motion import Blocked, ContactKind, Motion, MotionConfig
from robot.mount import ArrayMount
from robot.occupancy import MapMemoryError, OccupancyConfig, OccupancyGrid
from robot.odometry import GyroFusionConfig, Odometry, TravelConfig, pose_at
from robot.options import Option, OptionKind, OptionsConfig, Timing, choose
from robot.planner import Plan, Planner, PlannerConfig, path_start
from robot.pursuit import PursuitConfig, Pursuits
from robot.ranging import RangeLayout, RangeScans
from robot.recovery import Recovery, RecoveryConfig
from robot.rescue_config import FoundVictim, RescueConfig
from robot.sound_map import MapSource, SoundMap, SoundMapConfig, SourceState

__all__ = ["RescueBehaviour", "RescueConfig", "FoundVictim", "Decision", "FindCriterion", "RescueEvent",
           "RescueState"]

log = logging.getLogger(__name__)

class RescueBehaviour(Mission):
    """The behaviour on any HAL backend; call ``step()`` repeatedly or ``run(max_time)``.

    ``localizer``: ``locate(samples) -> result`` whose ``result.detections`` have ``azimuth``, ``elevation`` (rad,
    array frame), ``power`` and optionally ``direction``, ``level_db``; its ``geometry`` (or ``geometry``) gives
    the beams for the VAD; ``speech`` replaces the VAD (``robot.listening.Listener``). ``found_model``: the
    fitted P(find) model (default: ``robot/models/found_model.json``)."""

    def __init__(self, audio: AudioSource, drive: DriveBase, clock: Clock, localizer,
                 config: RescueConfig = RescueConfig(), *, motion: MotionConfig = MotionConfig(),
                 sound_map: SoundMapConfig = SoundMapConfig(), planner: PlannerConfig = PlannerConfig(),
                 occupancy: OccupancyConfig = OccupancyConfig(), params: OmniDriveParams = OmniDriveParams(),
                 gyro: GyroFusionConfig = GyroFusionConfig(), travel: TravelConfig = TravelConfig(),
                 coverage: CoverageConfig = CoverageConfig(), range_layout: RangeLayout = RangeLayout(),
                 pursuit: PursuitConfig = PursuitConfig(), options: OptionsConfig = OptionsConfig(),
                 recovery: RecoveryConfig = RecoveryConfig(), found_model: FoundModel | None = None,
                 mount: ArrayMount = ArrayMount(), start_pose=(0.0, 0.0, 0.0), geometry=None, speech=None) -> None:
        if not sound_map.source_height_m < mount.height_m:
            raise ValueError(f"SoundMapConfig.source_height_m: expected below the array (ArrayMount.height_m = "
                             f"{mount.height_m} m), got {sound_map.source_height_m}")
        super().__init__(drive, clock, config.fatal_faults)
        self.audio, self.localizer, self.config = audio, localizer, config
        self.mount = mount
        self.odometry = Odometry(params, start_pose, gyro, travel)
        self.grid = OccupancyGrid(occupancy, origin=np.asarray(start_pose, float)[:2])
        self.range_layout = range_layout
        self._scans = RangeScans(self.grid, range_layout)
        self.motion = Motion(drive, clock, self.odometry, motion, fatal=self._check_faults, sensed=self._scans,
                             range_layout=range_layout)
        geometry = geometry if geometry is not None else getattr(localizer, "geometry", None)
        self.listener = Listener(audio, clock, localizer, geometry, config.voice_threshold, speech,
                                 config.voice_scan_deg, drive=drive)
        if speech is None and self.listener.mic_positions is not None:
            _ = self.listener.vad   # the model files checked now (robot.vad.ModelError), not at the first listen
        # Hearing while driving needs the drive's own noise suppressed (else the array hears its motors: errors
        # of 170 deg at 0.2 m/s, experiments/results/listen_while_driving.md).
        self.drive_hearing = None
        if config.listen_while_driving and getattr(localizer, "ego_noise", None) is not None:
            self.drive_hearing = DriveHearing(self.listener, clock, lambda: self.pose, config.listen_s,
                                              config.min_power, self._heard_driving)
        # P(find)'s cues were fitted on runs that heard the way this one hears (robot.found.default_model_path)
        if found_model is None:
            found_model = FoundModel.load(driving=self.drive_hearing is not None)
        self.finder = Finder(found_model, mount.height_m, sound_map.source_height_m)
        self.map = SoundMap(sound_map, mount)
        self.coverage = ListeningCoverage(self.grid.origin, self.grid.n, self.grid.resolution, coverage,
                                          memory_budget_mb=self.grid.coverage_store_mb)
        self.planner = Planner(planner)
        fitted = found_model.provenance
        self.pursuits = Pursuits(pursuit, float(fitted.get("confirm_probability", 0.3)))
        if options.victims_per_m2 is None:
            options = replace(options, victims_per_m2=float(fitted.get("victims_per_m2", 0.05)))
        self.options = options
        self.timing = Timing(motion.drive_speed, config.settle_s + config.listen_s, config.step_m,
                             self.pursuits.config.confirm_probability, math.radians(sound_map.bearing_sigma_deg))
        self.contacts: Counter[ContactKind] = Counter()   # every move that ended early, by why (results.json)
        self.recovery = Recovery(self.motion, self.grid, self.coverage, self.contacts, self._emit,
                                 lambda why: self._finish(Decision.STUCK, why),
                                 replace(recovery, settle_s=config.settle_s))
        self.target: int | None = None            # map source id being approached
        self.plan: Plan | None = None
        self._started = False
        self._doing: tuple[OptionKind, int | None] | None = None   # the option the current move serves

    @property
    def pose(self) -> np.ndarray:
        """Robot pose (x m, y m, yaw rad) in the odometry frame."""
        return self.odometry.pose

    # -- the cycle ----------------------------------------------------------------
    def _cycle(self) -> None:
        if not self._ready():
            return
        judged = self._judge(self._listen())
        # One find per listen: the others' evidence changes with it (a second source beside a found victim is
        # mostly her own voice again: the near_found cue), judged again after the next listen.
        if judged and judged[0][1].probability >= self.config.p_find:
            self._declare(*judged[0])
            if self.done:
                return
        if not self._keep_on_map():
            return
        self._act(self._choose())

    def _choose(self) -> Option:
        return choose(self.map.sources, self.pursuits, self.planner, self.grid, self.coverage, self.pose,
                      self.clock.now(), self.timing, self.options, self.target)

    def _ready(self) -> bool:
        """Start odometry once; move the map's window; handle faults and a contact left from the last move."""
        if not self._started:
            self.motion.update_odometry()
            self.grid.mark_free(self.pose[:2])
            self._started = True
        self.state = RescueState.LISTEN
        if not self._keep_on_map():
            return False
        status = self.drive.status()
        if self._check_faults(status):
            return False
        if status.bumper or status.stalled:
            b = Blocked(ContactKind.BUMPER if status.bumper else ContactKind.STALL, status, float(self.pose[2]))
            self.contacts[b.kind] += 1
            self.state = RescueState.RECOVER
            self.recovery.after_contact(b, "at the start of a cycle")
            return False
        self.motion.stop()
        return True

    def _keep_on_map(self) -> bool:
        """Move the occupancy grid's and the coverage's window (together) near its edge; past the map's memory
        budget the mission ends (``FAULT``): False then."""
        try:
            if self.grid.follow(self.pose[:2]):
                self.coverage.move_to(self.grid.offset)
        except MapMemoryError as exc:
            self._finish(Decision.FAULT, f"the map reached its memory budget: {exc}")
            return False
        return True

    # -- hear and believe -----------------------------------------------------------
    def _listen(self) -> dict[int, ListenEvidence]:
        """One listen standing into the map and the coverage: the evidence heard now by unfound source id."""
        cfg = self.config
        self.motion.stand(cfg.settle_s)          # odometry tracks the braking, then learns the gyro bias
        pose = self.pose.copy()                   # standing: the pose the block is captured at
        res = self.listener.listen(cfg.listen_s, 0.0, cfg.min_power, pose=tuple(pose))
        self.motion.update_odometry(stationary=True)
        self.finder.spot.add(self.pose, res.evidence)
        return self._believe(res, self.pose, self.clock.now())

    def _heard_driving(self, res: Listen, trajectory: np.ndarray) -> bool:
        """A window heard while driving (``robot.drive_hearing``) into the map, at the pose of its middle, and
        the coverage. The drive goes on while the option it serves is still the one worth most (the current
        target keeps its ``keep_factor``); else it ends here and the next cycle listens standing and decides."""
        pose = np.array(pose_at(trajectory, 0.5 * (trajectory[0, 0] + trajectory[-1, 0])))
        self._believe(res, pose, float(trajectory[-1, 0]), "while driving: ", moving=True)
        o = self._choose()
        return (o.kind, None if o.source is None else o.source.id) == self._doing

    def _believe(self, res: Listen, pose: np.ndarray, now: float, prefix: str = "", moving: bool = False
                 ) -> dict[int, ListenEvidence]:
        """A listen heard at ``pose`` (odometry frame) into the map and the coverage, and its event; returns its
        evidence by unfound source id."""
        heard, cands, ignored = {}, [], list(res.ignored)
        for ev, sid in self.map.update(res.evidence, pose, now, moving):
            s = self.map.source(sid)
            if s.state is SourceState.FOUND:
                ignored.append(f"az {math.degrees(ev.azimuth):+.0f} deg el {math.degrees(ev.elevation):+.0f} deg "
                               f"is found source #{sid}")
                continue
            heard[sid] = ev
            cands.append(HeardCandidate(sid, ev.azimuth, ev.elevation, ev.level_db, ev.speech_fraction,
                                        ev.voice_scan, s.cls.value, s.state.value))
        self.coverage.listened(pose[:2], self.map.interferers())
        data = HeardPayload(res.n_detections, cands, ignored, pose.tolist())
        self._emit(data.decision, prefix + data.describe(), data)
        return heard

    # -- found ----------------------------------------------------------------------
    def _judge(self, heard: dict[int, ListenEvidence], contact: int | None = None
               ) -> list[tuple[MapSource, Assessment]]:
        """P(find) of the sources the found stage judges now (``robot.found.Finder``), most probable first. One
        within ``FIND_RADIUS_M`` that is not found now counts a miss (``robot.pursuit``)."""
        xy = self.pose[:2]
        judged = self.finder.judge(self.map.sources, xy, heard, self.clock.now(),
                                   tuple(tuple(m) for m in self.map.interferers()),
                                   tuple((v.position[0], v.position[1]) for v in self.victims), contact)
        for s, a in judged:
            if a.probability < self.config.p_find and s.distance_to(xy) <= FIND_RADIUS_M:
                self.pursuits.missed(s.id)
            else:
                self.pursuits.moved_away(s.id)
        return judged

    def _declare(self, s: MapSource, a: Assessment) -> None:
        now = self.clock.now()
        self.map.set_state(s.id, SourceState.FOUND, now)
        self.pursuits.found(s.id)
        f = FoundPayload((float(s.position[0]), float(s.position[1])), float(np.clip(s.position[2], 0.0, 2.0)), s.id,
                         a.describe(self.finder.model.weights), a.criterion, s.horizontal_sigma_m, s.victim_probability)
        self.victims.append(FoundVictim(f.position, now, f.criterion, f.height, f.victim_probability, s.id, f.cue))
        if self.target == s.id:
            self.target, self.plan = None, None
        self.state = RescueState.FOUND
        self._emit(Decision.VICTIM_FOUND, f"victim #{len(self.victims)} (source #{s.id}) at ({f.position[0]:.2f}, "
                                          f"{f.position[1]:.2f}) m +- {f.sigma_m:.2f} m: {f.criterion}", f)
        if self.config.max_victims is not None and len(self.victims) >= self.config.max_victims:
            self._finish(Decision.ALL_FOUND, f"found {len(self.victims)} victim(s) = max_victims")

    # -- acting -----------------------------------------------------------------------
    def _act(self, o: Option) -> None:
        s = o.source
        self._doing = (o.kind, None if s is None else s.id)
        if o.kind is OptionKind.APPROACH:
            self._set_target(s, o.plan)
            az, el = self.mount.bearing_to(self.pose, s.position)
            self._emit(Decision.TARGET, f"approach #{s.id}: {o.why}; {o.value * 60:.2f} victims/min",
                       TargetPayload(s.id, s.position.tolist(), s.horizontal_sigma_m, s.victim_probability, az, el,
                                     o.plan.length, o.plan.waypoints.tolist()))
            self._follow(o.plan.waypoints, RescueState.APPROACH, Decision.DRIVE, s)
        elif o.kind is OptionKind.TRIANGULATE:
            self._set_target(s, None)
            if self.pursuits.stepped_across(s.id, self.clock.now()):
                self._emit(Decision.NO_TARGET, f"source #{s.id} still +- {s.horizontal_sigma_m:.2f} m after "
                                               f"{self.pursuits.config.max_steps_across} steps across its bearing: "
                                               "set aside a while", SourcePayload(s.id))
                return
            self._follow(o.plan.waypoints, RescueState.APPROACH, Decision.DRIVE, s, f"triangulate #{s.id}: {o.why}")
        elif o.kind is OptionKind.EXPLORE:
            self._set_target(None, None)
            self._follow(o.plan.waypoints, RescueState.EXPLORE, Decision.EXPLORE, None, f"explore: {o.why}")
        elif o.kind is OptionKind.LISTEN:
            self._emit(Decision.NO_TARGET, f"listen again here: {o.why}")
        else:
            self._set_target(None, None)
            self._emit(Decision.NO_TARGET, o.why)
            self.state = RescueState.RECOVER
            if self.recovery.clear():
                self.pursuits.release_all()
            else:
                self.recovery.escape("no reachable place worth a listen")

    def _set_target(self, s: MapSource | None, plan: Plan | None) -> None:
        if self.target is not None and (s is None or s.id != self.target):
            try:
                self.map.set_state(self.target, SourceState.UNVISITED)
            except KeyError:
                pass
        self.target, self.plan = (None, None) if s is None else (s.id, plan)
        if s is not None:
            self.map.set_state(s.id, SourceState.APPROACHING)

    def _follow(self, waypoints: np.ndarray, state: RescueState, decision: Decision, target: MapSource | None,
                prefix: str = "") -> None:
        """Drive along ``waypoints`` (world m), at most ``step_m`` in all."""
        legs, total = path_start(self.pose[:2], waypoints, self.config.step_m)
        if total < 0.02:
            self._emit(Decision.NO_TARGET, f"{prefix or 'at the goal'}: nothing to drive; listen again")
            return
        self.state = state
        goal = legs[-1]
        self._emit(decision, f"{prefix + ': ' if prefix else ''}{total:.2f} m toward ({goal[0]:.2f}, {goal[1]:.2f})",
                   DrivePayload(total, [float(goal[0]), float(goal[1])], [leg.tolist() for leg in legs]))
        if self.drive_hearing is not None:
            self.drive_hearing.start()   # a window heard on the way may end the drive: it changed what is worth most
        try:
            self.motion.follow(legs, getattr(self.drive_hearing, "pace", None), self.grid.mark_path)
        except Blocked as b:
            self._blocked(b, target)

    def _blocked(self, b: Blocked, target: MapSource | None) -> None:
        self.contacts[b.kind] += 1
        if b.kind is ContactKind.FAULT:
            return  # the mission is over (_check_faults finished it)
        if target is not None:
            if b.kind in (ContactKind.BUMPER, ContactKind.RANGE):
                # A touch at her estimate is a cue (a victim under a slab is touched, not reached): judged now.
                s, a = next(((s, a) for s, a in self._judge({}, contact=target.id) if s.id == target.id),
                            (None, None))
                if a is not None and a.probability >= self.config.p_find:
                    self._declare(s, a)
                    if not self.done and b.kind is ContactKind.BUMPER:
                        self.recovery.back_off(b.heading, "clear the bumper after touching the victim")
                    return
            self.pursuits.contact(target.id, self.clock.now())
        if b.kind is ContactKind.RANGE:
            self._scans(self.pose, b.status, force=True)   # the reading that stopped the move goes into the grid
            seen = [round(r, 2) if math.isfinite(r) else None for r in b.status.ranges or ()]
            self._emit(Decision.OBSTACLE, "range sensors see an obstacle in the way: replan", ObstaclePayload(seen))
            return
        self.state = RescueState.RECOVER
        self.recovery.after_contact(b, "while moving")

