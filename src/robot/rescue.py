"""The rescue behaviour: listen, map, plan, move; repeat until every victim heard is found.

One cycle walks the data path, each stage in its own module:

* **listen** standing still (``robot.listening``): fresh audio, SRP-PHAT detections, the VAD on a beam
  toward each -> evidence in the ARRAY frame;
* **map** (``robot.sound_map``): the evidence with the pose of the listen -> world-frame sources
  (position + covariance from bearings triangulated across poses, victim/interferer/unknown, state);
* **found?** the current target, or any unfound source heard now, is declared found when
  (1) its bearing is steeper than ``found_elevation_deg`` below the horizon (the array is
  ``ArrayMount.height_m`` up: at 30 deg a mouth on the floor is ~0.35 m away), or (2) steeper than
  ``corroborated_elevation_deg`` and its level rose ``level_rise_db`` above the faintest listen of it, or
  (3) the map puts it within ``cue_distance_m`` of the robot with a horizontal 1-sigma under
  ``cue_sigma_m``, the bearing now points ``reach_elevation_deg`` down, meets a mouth ``mouth_height_m`` up no
  more than ``short_estimate_m`` beyond the estimate, and the level rose (supporting cues);
  (1)-(3) only when the bearing heard now is a strong SRP-PHAT peak (``found_min_power``: direct sound),
  or (4) the bumper fires (or the range sensors stop the move before an obstacle) while driving at it with
  its estimate within ``bump_found_range_m`` and ``bump_ahead_deg`` of the motion, a voice was heard from it,
  it was heard within ``bump_heard_within_s`` and its last bearing pointed ``supporting_elevation_deg`` down
  (a victim under a slab cannot be reached).
  A steep bearing no louder than a shallow one heard from the same spot in its direction is an echo, no cue.
  A voiced bearing steep enough for (1) that began a source of its own (one listen) is listened to again where
  the robot stands (criteria 1-2 need two listens of a source).
  The reported position is the map's estimate (for a steep bearing that joined a source mapped farther than
  ``found_exclusion_m``, where that bearing meets the floor); a found source stays found (never declared again).
  At an estimate where the source is heard level (``refute_after_listens``), the close listens refute the far
  ones that placed it there: the source is re-estimated from them alone, once;
* **plan** (``robot.planner``): the most useful unfound victim (P(victim), recency, path length; interferers
  never) and a path to it around the obstacles learned by touch (``robot.occupancy``); none mapped ->
  explore where a listen would hear most of the floor not yet heard (``robot.coverage``: listens so far, a
  mapped machine's masking, the search area), away from found victims (after ``explore_after_silent``
  silent listens when nothing is mapped, at once when only interferers are);
* **move** (``robot.motion``): translate (the base is holonomic, the array omnidirectional: no turning) at
  most ``step_m`` along the path, then listen again. A contact (bumper, stall, gyro-detected slip) is
  mapped, the robot backs off and the next cycle replans around it. When the learned obstacles close every
  way, those marked by a single contact are forgotten (clearing recovery) and the robot replans. "stuck" only
  when backing off and a short move in each of eight directions all fail (when all of them stalled without a
  bumper press, again after turning in place: wedged on debris).

Frames: evidence in the array frame (axes the robot's, azimuth CCW from forward); poses, map and grid in
the odometry frame (``start_pose`` sets it, e.g. to the world start pose in simulation). The drive is
stopped at the end of every step and on any exception.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, fields
from typing import ClassVar
from collections import Counter

import numpy as np

# The behaviour's vocabulary (robot.events), importable from here too.
from robot.events import (FINAL, ContactPayload, Decision, DriveFaultPayload, DrivePayload, ErrorPayload,
                          FindCriterion, FinishPayload, FoundPayload, HeardCandidate, HeardPayload, ObstaclePayload,
                          Payload, RecoverPayload, RejectedPayload, RescueEvent, RescueState, SourcePayload,
                          TargetPayload, TimeUpPayload)
from robot.coverage import CoverageConfig, ListeningCoverage
from robot.hal import AudioSource, Clock, DriveBase, DriveStatus, EndOfAudio
from robot.kinematics import OmniDriveParams
from robot.listening import ListenEvidence, Listener
from robot.mount import ArrayMount
from robot.motion import Blocked, ContactKind, Motion, MotionConfig
from robot.occupancy import MapMemoryError, OccupancyConfig, OccupancyGrid
from robot.odometry import GyroFusionConfig, Odometry, TravelConfig, wrap_angle
from robot.planner import Plan, Planner, PlannerConfig
from robot.protocol import FAULT_NAMES
from robot.ranging import RangeLayout, ray_ends
from robot.sound_map import DISTINCT_POSES_M, MapSource, SoundMap, SoundMapConfig, SourceClass, SourceState

log = logging.getLogger(__name__)

#: Range readings go into the grid once per 5 cm of travel or 10 deg of turn (control ticks are 1.25 cm apart).
SCAN_SPACING_M = 0.05
SCAN_TURN = math.radians(10.0)


@dataclass(frozen=True)
class RescueConfig:
    """Parameters of the behaviour's decisions (SI units; ``*_deg`` in degrees). Motion, map, planner and grid
    have their own configs (``[motion]``, ``[sound_map]``, ``[planner]``, ``[occupancy]`` in a scenario)."""

    # listening
    listen_s: float = 1.0                  # audio per localization (s)
    settle_s: float = 0.3                  # wait after stopping before listening (s): motor noise, sway
    min_power: float = 0.0                 # ignore detections with a lower normalised SRP power
    voice_threshold: float = 0.1           # VAD speech-frame fraction of a beam counted as voice (robot.listening;
    #                                        robot.vad.CHUNK_SPEECH_FRACTION = 0.2 separates dry 1 s chunks;
    #                                        reverberant beams of callers 2-4 m away have fewer)
    voice_scan_deg: float = 0.0            # > 0: a listen whose strongest detection is no voice is also scanned for
    #                                        one, beams this far apart in azimuth (robot.listening.Listener: hears a
    #                                        caller beside a louder machine in 31 of 70 listens instead of 15). Off:
    #                                        in closed loop its gains and losses over the shipped scenarios stayed
    #                                        within the runs' chance, and each scan costs 24 beams of VAD
    require_voice: bool = False            # approach only sources classified victim (not unclassified ones)
    # found
    found_elevation_deg: float = 30.0      # criterion 1: bearing steeper than this below horizontal
    corroborated_elevation_deg: float = 20.0  # criterion 2: this steep (mouth within ~0.55 m) ...
    level_rise_db: float = 9.0             # ... and the level rose this much above the faintest listen of it
    found_distance_m: float = 0.45         # at the estimate: this close (success radius in the shipped scenarios is
    #                                        0.75 m: margin for a 0.3 m estimate error) ...
    found_sigma_m: float = 0.3             # ... with its horizontal 1-sigma below this, the robot stops approaching and
    #                                        waits for a found cue (or rejects a reflection). 0.6 m instead (criterion
    #                                        3 too): light rubble seeds 0-15 at 180 s, 46 vs 47 of 48, SPL 0.536 vs 0.557
    cue_distance_m: float = 0.6            # criterion 3 (with the supporting cues below): the map estimate this close
    cue_sigma_m: float = 0.4               # ... and its 1-sigma this small. Measured on main, light rubble seeds 0-15:
    #                                        the listens inside the 0.75 m success radius before the find that heard
    #                                        the caller >= 15 deg down had her estimate 0.3-0.7 m away at 1-sigma
    #                                        0.06-0.39 m while the robot was 0.36-0.66 m from her; at 0.45 m / 0.3 m it
    #                                        drove on (median find 0.31 m from her; 33 m of the 47 legs' 180 m were
    #                                        driven inside the success radius). Seeds 0-15 against main: light rubble
    #                                        (180 s) SPL 0.573 vs 0.557, 47 vs 47 of 48; generator_louder SPL 0.559 vs
    #                                        0.512; half_buried_slab 20 vs 20 of 32; false founds equal. 0.7 m: light
    #                                        rubble SPL 0.570, half_buried_slab 19 of 32 (a late find lost)
    reach_elevation_deg: float = 15.0      # ... and heard now this far below horizontal: a mouth 0.2 m below the
    #                                        array within 0.75 m (the success radius). Was 10 deg (within 1.1 m):
    #                                        on the 7 finds by this criterion in 32 runs (main, seeds 0-15) the
    #                                        range from the elevation matched the robot's true distance (0.70 vs
    #                                        0.71 m, 1.03 vs 1.05 m, 0.87 vs 0.81 m, 0.45-0.58 vs 0.32-0.51 m);
    #                                        the two heard at -11 and -13 deg were false founds 1.05 and 0.81 m
    #                                        from the caller behind the slab (half_buried_slab seeds 1, 3)
    echo_azimuth_deg: float = 30.0         # a steep bearing heard from the spot where a shallower one (within
    #                                        reach_elevation_deg of the horizon), at least as loud, was heard this close
    #                                        in azimuth is an echo, no found cue. Measured, light rubble and half_buried
    #                                        seeds 0-15, three versions: 16 such pairs in one listen; the 12 heard
    #                                        0.99-1.6 m from the nearest caller (3 false founds among them) had the
    #                                        steep one 0.6-4.9 dB weaker, the 3 heard 0.4 m from her 20-26 dB louder,
    #                                        one 0.75 m away 4.4 dB weaker (a 4th false found had its partner one
    #                                        listen earlier from the same spot)
    supporting_elevation_deg: float = 10.0  # a bearing this far below horizontal points down at a mouth on the floor
    #                                        within ~1.1 m of the 0.3 m high array (bump criterion 4); one at its
    #                                        estimate heard shallower is farther away (refute_after_listens) ...
    supporting_rise_db: float = 3.0        # ... and louder than its faintest listen (a mirror image beyond a wall
    #                                        triangulates tightly too: measured, 2 false finds in light rubble)
    found_min_power: float = 0.075         # criteria 1-3 need the bearing heard now at this normalised SRP-PHAT peak
    #                                        power or more: within reach a mouth is inside the critical distance
    #                                        (~0.75 m at RT60 0.6 s in these rooms), its direct sound dominates.
    #                                        Measured (84 stored runs, all scenarios): callers' true bearings
    #                                        within 0.5 m had power 0.10 (5th pct) / 0.24 (median), wrong ones
    #                                        0.07 (median); no true find of ~150 below 0.083; the false found
    #                                        3.9 m behind the partition, heard through the gap, 0.061
    bump_found_range_m: float = 0.7        # criterion 4: bump while driving at a target estimated this close: inside
    #                                        the 0.75 m success radius (at 0.8 m an estimate 0.79 m ahead declared
    #                                        a caller behind a slab from 0.82 m), yet above 0.65 m (a caller behind
    #                                        a block, bumped with her 0.65 m away, is a true find)
    bump_ahead_deg: float = 35.0           # ... and this close to the direction of motion
    bump_heard_within_s: float = 10.0      # ... and heard this recently (2-3 listen cycles: a caller is heard in most;
    #                                        a mirror image beyond a wall, unheard for 25 s, was "found" by bumping
    #                                        into the wall: light_rubble_three seed 6)
    found_exclusion_m: float = 1.1         # a source this close to a found victim is that victim: a reflection of
    #                                        a found caller 1.06 m from her was declared a second victim
    #                                        (half_buried_slab); seeds 0-15 against 0.8: light rubble 41 vs 40 of 48,
    #                                        half_buried false founds 0.44 vs 0.56 per run, the rest equal. Two
    #                                        victims within 1.1 m are reported as one (rescuers search around it)
    max_contacts_per_target: int = 3       # contacts while pursuing one source before it is set aside a while
    max_baseline_steps: int = 4            # steps across one source's bearing that leave it untriangulated before it
    #                                        is set aside a while (not heard again from the new poses: a reflection,
    #                                        a caller gone quiet; measured, dense_pump seed 1 stepped to and fro
    #                                        across a pump reflection's bearing for 100 s)
    machine_radius_m: float = 1.0          # within this of a rejected interferer, only a voice declares a victim
    reject_after_listens: int = 4          # listens of an interferer from close up before it is rejected (a caller
    #                                        calls in ~40 % of 1 s listens in the shipped scenarios: 4 silent ones
    #                                        in a row happen to 13 % of callers, who stay on the map as unknown)
    refute_after_listens: int = 2          # listens at a source's estimate that hear it shallower than
    #                                        supporting_elevation_deg (a mouth on the floor beyond ~1.1 m) or more
    #                                        than the map's inlier_deg off the estimate (pointing past it) before
    #                                        the estimate is dropped and the source re-estimated from these listens
    #                                        alone (measured on main, light rubble and half_buried seeds 0-15: of 75
    #                                        listens at an estimate that heard its source without a found cue, 69
    #                                        heard it shallower than 10 deg, 66 of them at estimates > 0.75 m from
    #                                        every caller; in light rubble seed 0 two callers' rays crossing beside
    #                                        the robot had triangulated into a ghost, rejected after 11 listens with
    #                                        a caller's rays in it)
    mouth_height_m: float = 0.1            # a caller's mouth above the floor (lying, half buried), for the range a
    #                                        bearing heard now gives: (array height - this) / tan(depression)
    short_estimate_m: float = 0.35         # that range farther than the map estimate by more than this: the estimate
    #                                        is short of her (the listens that placed it came around rubble), no
    #                                        criterion 3 (she is found by a steeper bearing farther on, or the estimate
    #                                        is rejected as a reflection). Measured (seeds 0-15, five scenarios, 22
    #                                        finds by criterion 3): the two false ones (half_buried_slab seeds 4, 5,
    #                                        0.7-0.8 m from the caller behind the slab) were 0.40-0.47 m short, every
    #                                        true one 0.29 m or less. Counting such a bearing as heard level too (to
    #                                        re-estimate the source) lost light rubble seed 6 a victim (Haswell)
    max_victims: int | None = None         # stop after finding this many (None: keep searching)
    # moving
    step_m: float = 0.6                    # longest move between two listens
    wedged_turn_deg: float = 45.0          # turn in place when every escape move stalled without a bumper press
    #                                        (half the 120 deg wheel spacing: each wheel meets the debris anew;
    #                                        measured, light rubble seed 0 ended "stuck" on a 15 mm debris plate)
    baseline_step_m: float = 0.4           # sideways step to triangulate a source known along one line only
    explore_after_silent: int = 3          # silent listens with nothing mapped before exploring
    escape_rounds: int = 2                 # rounds of eight escape moves before "stuck" (see _escape)
    fatal_faults: tuple[str, ...] = ("encoder_error",)  # drive faults that end the mission

    #: Fields that no longer exist (robot.config_values.field_values): ignored with a warning, or refused where
    #: the value now belongs elsewhere (the text says where).
    RETIRED: ClassVar[dict[str, str]] = {
        "min_step_m": "no decision read it",
        "array_height_m": "MOVED: the array's height is robot.mount.ArrayMount.height_m (ssl-robot: --set "
                          "mount.height_m=...; in simulation the robot model's cube height, set by the simulator)",
    }

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float) and not (math.isfinite(v) and v >= 0):
                raise ValueError(f"RescueConfig.{f.name}: expected a finite number >= 0, got {v}")
        for name in ("listen_s", "step_m", "found_distance_m", "found_sigma_m",
                     "cue_distance_m", "cue_sigma_m",
                     "bump_heard_within_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"RescueConfig.{name}: expected > 0, got {getattr(self, name)}")
        if not 0 <= self.found_min_power < 1:
            raise ValueError(f"RescueConfig.found_min_power: expected 0 <= power < 1, got {self.found_min_power}")
        if not 0 < self.found_elevation_deg < 90 or not 0 < self.corroborated_elevation_deg < 90:
            raise ValueError("RescueConfig.found_elevation_deg / corroborated_elevation_deg: expected 0 < deg < 90")
        if not self.reach_elevation_deg < 90:
            raise ValueError(f"RescueConfig.reach_elevation_deg: expected 0 <= deg < 90, got {self.reach_elevation_deg}")
        if not 0 <= self.voice_threshold <= 1:
            raise ValueError(f"RescueConfig.voice_threshold: expected 0..1, got {self.voice_threshold}")
        if not 0 <= self.voice_scan_deg <= 90:
            raise ValueError(f"RescueConfig.voice_scan_deg: expected 0 (off) .. 90 deg, got {self.voice_scan_deg}")
        if not (isinstance(self.fatal_faults, tuple) and set(self.fatal_faults) <= set(FAULT_NAMES.values())):
            raise ValueError(f"RescueConfig.fatal_faults: expected drive fault names out of "
                             f"{sorted(FAULT_NAMES.values())} (an empty list for none), got {self.fatal_faults!r}")
        for name in ("explore_after_silent", "max_contacts_per_target", "max_baseline_steps", "reject_after_listens",
                     "refute_after_listens", "escape_rounds"):
            if getattr(self, name) < 1:
                raise ValueError(f"RescueConfig.{name}: expected an integer >= 1, got {getattr(self, name)}")
        if self.max_victims is not None and self.max_victims < 1:
            raise ValueError(f"RescueConfig.max_victims: expected None or >= 1, got {self.max_victims}")


@dataclass(frozen=True)
class FoundVictim:
    """A victim declared found: the map's estimated ``position`` (x, y) and ``height`` (m) in the odometry frame."""

    position: tuple[float, float]
    time: float
    criterion: str            # the cue in words, with the measured values
    height: float
    voice: float = 0.0        # P(victim) of the map source when declared
    source_id: int = -1
    cue: FindCriterion | None = None   # which cue (None: declared by a caller of ``_declare_found`` without one)


class RescueBehaviour:
    """The behaviour on any HAL backend; call ``step()`` repeatedly or ``run(max_time)``.

    ``localizer``: anything with ``locate(samples) -> result`` whose ``result.detections`` have ``azimuth``,
    ``elevation`` (rad, array frame), ``power`` and optionally ``direction``, ``level_db``. Its ``geometry``
    (if present; else give ``geometry``) is used to beamform toward each detection for the VAD; ``speech``
    replaces the VAD (``robot.listening.Listener``).
    """

    def __init__(self, audio: AudioSource, drive: DriveBase, clock: Clock, localizer,
                 config: RescueConfig = RescueConfig(), *, motion: MotionConfig = MotionConfig(),
                 sound_map: SoundMapConfig = SoundMapConfig(), planner: PlannerConfig = PlannerConfig(),
                 occupancy: OccupancyConfig = OccupancyConfig(), params: OmniDriveParams = OmniDriveParams(),
                 gyro: GyroFusionConfig = GyroFusionConfig(), travel: TravelConfig = TravelConfig(),
                 coverage: CoverageConfig = CoverageConfig(), range_layout: RangeLayout = RangeLayout(),
                 mount: ArrayMount = ArrayMount(), start_pose=(0.0, 0.0, 0.0), geometry=None, speech=None) -> None:
        if not config.mouth_height_m < mount.height_m:
            raise ValueError(f"RescueConfig.mouth_height_m: expected below the array (ArrayMount.height_m = "
                             f"{mount.height_m} m), got {config.mouth_height_m}")
        self.audio, self.drive, self.clock, self.localizer, self.config = audio, drive, clock, localizer, config
        self.mount = mount
        geometry = geometry if geometry is not None else getattr(localizer, "geometry", None)
        mics = None if geometry is None else np.asarray(getattr(geometry, "positions", geometry), float)
        if mics is not None and mics.shape[0] != audio.n_channels:
            raise ValueError(f"geometry: {mics.shape[0]} microphones but the audio source has "
                             f"{audio.n_channels} channels")
        loc_fs = getattr(getattr(localizer, "config", None), "fs", None)
        if loc_fs is not None and int(loc_fs) != audio.sample_rate:
            raise ValueError(f"localizer fs is {loc_fs} Hz but the audio source delivers {audio.sample_rate} Hz")
        self.odometry = Odometry(params, start_pose, gyro, travel)
        self.motion = Motion(drive, clock, self.odometry, motion, fatal=self._check_faults, sensed=self._sensed,
                             range_layout=range_layout)
        self.range_layout = range_layout
        self._scan_pose: np.ndarray | None = None   # where the last range reading went into the grid
        self.listener = Listener(audio, clock, localizer, mics, config.voice_threshold, speech, config.voice_scan_deg,
                                 drive=drive)
        if speech is None and mics is not None:
            _ = self.listener.vad   # the model files checked now (robot.vad.ModelError), not at the first listen
        self.map = SoundMap(sound_map, mount)
        self.grid = OccupancyGrid(occupancy, origin=np.asarray(start_pose, float)[:2])
        self.coverage = ListeningCoverage(self.grid.origin, self.grid.n, self.grid.resolution, coverage,
                                          memory_budget_mb=self.grid.coverage_store_mb)
        self.planner = Planner(planner)
        self.state = RescueState.LISTEN
        self.events: list[RescueEvent] = []
        self.victims: list[FoundVictim] = []
        self.target: int | None = None          # map source id being approached
        self.plan: Plan | None = None
        self._silent = 0
        self._close_listens: dict[int, int] = {}
        self._unheard_at: dict[int, int] = {}     # listens at a source's estimate that did not hear it
        self._level_at: dict[int, int] = {}       # listens at a source's estimate that heard it level (far away)
        self._restarted: set[int] = set()         # sources re-estimated from the listens at their old estimate
        self._evidence: list[ListenEvidence] = []  # every bearing heard from the current spot (robot frame)
        self._evidence_at: np.ndarray | None = None  # that spot (world x, y) and the yaw (rad) at it
        self._cue: dict[int, tuple[str, FindCriterion]] = {}   # the found cue a source showed in an earlier
        #                                                         listen (words, kind)
        self._target_contacts: dict[int, int] = {}
        self.contacts: Counter[ContactKind] = Counter()   # every move that ended early, by why (results.json)
        self._baseline_steps: dict[int, int] = {}
        self._side = 1.0                          # alternating side of baseline steps
        self._faults_seen: tuple[str, ...] = ()
        self._step_events: list[RescueEvent] = []
        self._odo_started = False

    # -- public API ---------------------------------------------------------------
    @property
    def pose(self) -> np.ndarray:
        """Robot pose (x m, y m, yaw rad) in the odometry frame."""
        return self.odometry.pose

    @property
    def done(self) -> bool:
        return self.state is RescueState.DONE

    def step(self) -> list[RescueEvent]:
        """One listen/act cycle; returns its events. The drive is stopped when it returns or raises."""
        self._step_events = []
        if self.done:
            return []
        try:
            self._cycle()
        except EndOfAudio as exc:   # the source's own end of stream (any other EOFError, e.g. a model's, fails)
            self._finish(Decision.AUDIO_ENDED, f"audio source exhausted ({exc})")
        except BaseException as exc:
            failed = self._safe_stop()
            outcome = "drive stopped" if failed is None else f"stopping the drive failed too ({failed})"
            self._emit(Decision.ERROR, f"{type(exc).__name__}: {exc}; {outcome}",
                       ErrorPayload(type(exc).__name__, failed is None))
            raise
        finally:
            self._safe_stop()
        return self._step_events

    def run(self, max_time: float) -> list[RescueEvent]:
        """Step until done or ``max_time`` s of clock time have passed; returns this run's events."""
        if not max_time > 0:
            raise ValueError(f"max_time: expected > 0 s, got {max_time}")
        t_end = self.clock.now() + max_time
        out: list[RescueEvent] = []
        try:
            while not self.done and self.clock.now() < t_end:
                out += self.step()
            if not self.done:
                self._step_events = []
                self._emit(Decision.TIME_UP, f"mission time of {max_time:g} s used up", TimeUpPayload(max_time))
                out += self._step_events
        finally:
            self._safe_stop()
        return out

    # -- the cycle ----------------------------------------------------------------
    def _cycle(self) -> None:
        if not self._odo_started:
            self.motion.update_odometry()
            self.grid.mark_free(self.pose[:2])
            self._odo_started = True
        self.state = RescueState.LISTEN
        if not self._keep_on_map():
            return
        status = self.drive.status()
        if self._check_faults(status):
            return
        if status.bumper or status.stalled:
            b = Blocked(ContactKind.BUMPER if status.bumper else ContactKind.STALL, status, float(self.pose[2]))
            self.contacts[b.kind] += 1
            self._recover(b, "at the start of a cycle")
            return
        self.motion.stop()
        heard = self._listen()
        if self._found_check(heard) or self.done:
            return
        if not self._keep_on_map():
            return
        src, plan, why = self.planner.choose_target(self.map.sources, self.grid, self.pose, self.clock.now(),
                                                    self.target, self.coverage.config.area)
        if src is not None and self.config.require_voice and src.cls is not SourceClass.VICTIM:
            src, plan, why = None, None, f"require_voice: {why} is not classified victim"
        if src is None:
            self._no_target(why)
            return
        self._silent = 0
        if self.target != src.id and self.target is not None:
            self._release_target()
        self.target, self.plan = src.id, plan
        self.map.set_state(src.id, SourceState.APPROACHING)
        az, el = self._bearing_to(src.position)
        self._emit(Decision.TARGET, why, TargetPayload(src.id, src.position.tolist(), src.horizontal_sigma_m,
                                                       src.victim_probability, az, el, plan.length,
                                                       plan.waypoints.tolist()))
        self._follow(plan, RescueState.APPROACH, Decision.DRIVE, src)

    def _keep_on_map(self) -> bool:
        """Move the occupancy grid's and the coverage's window (together) when the robot nears its edge; past the
        map's memory budget the mission ends (``FAULT``, the reason names the budget): False then."""
        try:
            if self.grid.follow(self.pose[:2]):
                self.coverage.move_to(self.grid.offset)
        except MapMemoryError as exc:
            self._finish(Decision.FAULT, f"the map reached its memory budget: {exc}")
            return False
        return True

    def _sensed(self, pose: np.ndarray, status: DriveStatus) -> None:
        """Range readings into the occupancy grid: one per ``SCAN_SPACING_M`` of travel or ``SCAN_TURN`` of turn,
        as readings taken from one spot repeat the same error (a tilted ray on the same floor)."""
        if status.ranges is None:
            return
        last = self._scan_pose
        if last is not None and math.hypot(*(pose[:2] - last[:2])) < SCAN_SPACING_M \
                and abs(wrap_angle(pose[2] - last[2])) < SCAN_TURN:
            return
        self._scan_pose = np.array(pose, float)
        self.grid.mark_rays(*ray_ends(self.range_layout, pose, status.ranges))

    def _listen(self) -> list[tuple[ListenEvidence, int]]:
        cfg = self.config
        self.motion.stand(cfg.settle_s)          # settling: odometry tracks the braking, then learns the gyro bias
        res = self.listener.listen(cfg.listen_s, 0.0, cfg.min_power)
        self.motion.update_odometry(stationary=True)
        pose = self.pose
        assoc = self.map.update(res.evidence, pose, self.clock.now())
        self.coverage.listened(pose[:2], self._machines())
        if self._evidence_at is None or math.hypot(*(pose[:2] - self._evidence_at[:2])) > DISTINCT_POSES_M \
                or abs(wrap_angle(pose[2] - self._evidence_at[2])) > math.radians(5.0):
            self._evidence, self._evidence_at = [], pose.copy()
        self._evidence += res.evidence
        cands = []
        ignored = list(res.ignored)
        for ev, sid in assoc:
            s = self.map.source(sid)
            row = HeardCandidate(sid, ev.azimuth, ev.elevation, ev.level_db, ev.speech_fraction, ev.voice_scan,
                                 s.cls.value, s.state.value)
            if s.state is SourceState.FOUND:
                ignored.append(f"az {math.degrees(ev.azimuth):+.0f} deg el {math.degrees(ev.elevation):+.0f} deg "
                               f"is found victim #{self._victim_number(sid)}")
            else:
                cands.append(row)
        data = HeardPayload(res.n_detections, cands, ignored, pose.tolist())
        if cands:
            self._silent = 0
            desc = "; ".join(f"#{c.source} {c.cls} az {math.degrees(c.azimuth):+.0f} deg "
                             f"el {math.degrees(c.elevation):+.0f} deg voice {c.voice:.2f}"
                             + (" (voice scan)" if c.voice_scan else "") for c in cands)
            self._emit(Decision.HEARD, desc + (f"; ignored: {'; '.join(ignored)}" if ignored else ""), data)
        else:
            self._silent += 1
            why = "no source detected" if not res.n_detections else "only ignored sources: " + "; ".join(ignored)
            self._emit(Decision.NO_SOURCE, f"{why} (silent listen {self._silent})", data)
        return [(ev, sid) for ev, sid in assoc if self.map.source(sid).state is not SourceState.FOUND]

    # -- found ----------------------------------------------------------------------
    def _found_check(self, heard: list[tuple[ListenEvidence, int]]) -> bool:
        cfg = self.config
        xy = self.pose[:2]
        heard_by = {sid: ev for ev, sid in heard}
        ids = set(heard_by) | ({self.target} if self.target is not None else set())
        for sid in sorted(ids):
            try:
                s = self.map.source(sid)
            except KeyError:
                continue
            if s.state in (SourceState.FOUND, SourceState.REJECTED) or self._near_found(s.position, s.id):
                continue
            crit, cue = None, None
            ev = heard_by.get(sid)
            # Beside a machine checked from close up only a voice makes a victim: its reflections off nearby
            # rubble arrive steep and loud (dense_pump: a -41 deg bearing 0.4 m from the pump).
            near_machine = s.cls is not SourceClass.VICTIM and self._near_machine(s)
            echo = ev is not None and self._floor_echo(ev)
            # A mouth within reach is inside the room's critical distance: most of its sound arrives as one plane
            # wave, a high SRP-PHAT peak. Sound that came around a wall or from metres away is mostly
            # reverberant, however steep its bearing (measured below, ``found_min_power``).
            coherent = ev is not None and ev.power >= cfg.found_min_power
            if ev is not None and s.n_inliers >= 2 and not near_machine and not echo and coherent:
                steep = -math.degrees(ev.elevation)
                faintest = min((r.level_db for r in s.history), default=ev.level_db)
                rise = ev.level_db - faintest
                if steep >= cfg.found_elevation_deg:
                    crit = f"elevation {-steep:.0f} deg is steeper than -{cfg.found_elevation_deg:g} deg"
                    cue = FindCriterion.STEEP_BEARING
                elif steep >= cfg.corroborated_elevation_deg and rise >= cfg.level_rise_db:
                    crit = (f"elevation {-steep:.0f} deg (< -{cfg.corroborated_elevation_deg:g}) and level rose "
                            f"{rise:.1f} dB (>= {cfg.level_rise_db:g})")
                    cue = FindCriterion.LEVEL_RISE
            # A voiced mouth right below in a bearing that began a source of its own (the caller's map estimate
            # was off): criteria 1-2 need a second listen of it, so take it here rather than step away across
            # the bearing (measured, dense_pump seed 11: heard -35 deg down 0.33 m from her, then left).
            if crit is None and ev is not None and s.n_inliers < 2 and not near_machine and not echo and coherent \
                    and ev.voice_probability >= 0.5 and -math.degrees(ev.elevation) >= cfg.found_elevation_deg \
                    and self._listen_again(s, f"source #{s.id} heard steep ({math.degrees(ev.elevation):+.0f} deg) "
                                              "with voice in one listen only"):
                return True
            d = s.distance_to(xy)
            # The map alone is not enough (a wrong triangulation would declare empty floor): the bearing heard
            # now must point down as a mouth on the floor within reach does (elevation supporting).
            if crit is None and d <= cfg.cue_distance_m and s.horizontal_sigma_m <= cfg.cue_sigma_m \
                    and s.n_inliers >= 3 and s.triangulated and not near_machine and coherent and not echo \
                    and -math.degrees(ev.elevation) >= cfg.reach_elevation_deg \
                    and self._bearing_range(ev, cfg.mouth_height_m) <= d + cfg.short_estimate_m \
                    and ev.level_db - min(r.level_db for r in s.history) >= cfg.supporting_rise_db:
                crit = (f"map estimate {d:.2f} m away (<= {cfg.cue_distance_m:g}), +- "
                        f"{s.horizontal_sigma_m:.2f} m from {s.n_inliers} listens")
                cue = FindCriterion.MAP_ESTIMATE
            reached = d <= cfg.found_distance_m and s.horizontal_sigma_m <= cfg.found_sigma_m and s.triangulated
            if crit is not None:
                crit += f" (SRP power {ev.power:.2f})"
                self._cue[sid] = (crit, cue)
            elif reached and sid in self._cue:
                # It showed a found cue from here before and is silent now: a caller pauses (measured, light rubble
                # seed 7: the caller behind the pillar heard steep and 10-18 dB louder in three listens, then
                # rejected as a reflection on the fourth, in which it did not call).
                earlier, cue = self._cue[sid]
                crit = f"{earlier}, in an earlier listen; map estimate {d:.2f} m away"
            if crit is None and reached and not self._approachable(s):
                # A machine: no elevation cue. Never declared (not approachable: rejected below).
                crit, cue = f"map estimate {d:.2f} m away, +- {s.horizontal_sigma_m:.2f} m", FindCriterion.MAP_ESTIMATE
            elif crit is None and reached:
                # At its estimate and no cue says a mouth is here: listen a few times, then it is a reflection
                # (a mirror image beyond a wall triangulates as tightly as a caller: measured in light rubble).
                # Only a listen that hears it without a cue counts (a caller who pauses says nothing); listens that
                # do not hear it at all end the wait after twice as many (after as many: light rubble seeds 0-15,
                # 180 s, 35 of 48 callers found instead of 40, same session).
                if ev is not None and sid not in self._restarted \
                        and (-math.degrees(ev.elevation) < cfg.supporting_elevation_deg
                             or self._off_estimate_deg(ev, s) > self.map.config.inlier_deg):
                    # Heard level from its estimate, or pointing past it: a mouth there would be heard steeply
                    # (>= 20 deg from 0.45 m) and toward it; this one is farther along this bearing. The close
                    # listens outweigh the far ones that placed it here (two callers' bearings crossing, a
                    # reflection): re-estimate it from them alone, once.
                    n = self._level_at[sid] = self._level_at.get(sid, 0) + 1
                    if n < cfg.refute_after_listens:
                        self._emit(Decision.NO_TARGET, f"at the estimate of source #{s.id} ({d:.2f} m), heard level or"
                                   f" past it ({math.degrees(ev.elevation):+.0f} deg): listen again "
                                   f"({n}/{cfg.refute_after_listens})", SourcePayload(s.id))
                        return True
                    kept = self.map.restart_from(sid, xy)
                    self._restarted.add(sid)
                    for counts in (self._close_listens, self._unheard_at, self._level_at, self._baseline_steps):
                        counts.pop(sid, None)
                    self._emit(Decision.NO_TARGET, f"at the estimate of source #{s.id} ({d:.2f} m), heard level or "
                               f"past it ({math.degrees(ev.elevation):+.0f} deg) in {n} listens: it is farther along "
                               f"that bearing; re-estimated from the {kept} listen(s) heard here", SourcePayload(s.id))
                    continue
                if ev is None:
                    n = self._unheard_at[sid] = self._unheard_at.get(sid, 0) + 1
                    if n < 2 * cfg.reject_after_listens:
                        self._emit(Decision.NO_TARGET, f"at the estimate of source #{s.id} ({d:.2f} m), not heard "
                                   f"in this listen: listen again ({n}/{2 * cfg.reject_after_listens})",
                                   SourcePayload(s.id))
                        return True
                elif self._listen_again(s, f"at the estimate of source #{s.id} ({d:.2f} m), no found cue yet"):
                    return True
                self._reject(s, f"at its estimate ({d:.2f} m) for {self._close_listens.get(sid, 0)} listens that "
                                f"heard it without a found cue and {self._unheard_at.get(sid, 0)} that did not hear it:"
                                " a reflection")
                continue
            if crit is None:
                continue
            voiced = any(r.voice_probability >= 0.5 for r in s.history)
            # Close enough to hear a voice if it had one; a caller pauses, so a few listens first: each listen
            # that hears it without speech lowers P(victim), a pause adds nothing.
            if not voiced and s.cls is not SourceClass.VICTIM and self._listen_again(
                    s, f"at source #{s.id} ({crit}), no voice yet (P(victim) {s.victim_probability:.2f})"):
                return True
            # Never heard with speech from close up (where the beam hears a talking caller in most listens:
            # docs/design/behaviour.md, "The sound map"): only a mouth below the array (a steep bearing, criteria 1-2)
            # makes it a victim (a buried caller the VAD misses, one who knocks); a tight triangulation near
            # rubble alone does not (measured, half_buried_slab seed 1: a voiceless reflection declared by its
            # map estimate, 1.3 m from a victim).
            steep_cue = cue in (FindCriterion.STEEP_BEARING, FindCriterion.LEVEL_RISE)
            if not voiced and not steep_cue:
                self._reject(s, f"reached ({crit}) but no voice heard (P(victim) {s.victim_probability:.2f})")
                continue
            if not self._approachable(s):
                self._reject(s, f"reached ({crit}) but no voice heard (P(victim) {s.victim_probability:.2f}): "
                                "an interferer, not a victim")
                continue
            if steep_cue and d > cfg.found_exclusion_m:
                # A mouth heard right below, but the source this bearing joined is mapped far off: the bearing is
                # another caller's (measured, light rubble seed 9: a caller heard at -36 deg joined the source of
                # one 2.4 m away, was reported there, and that caller was then excluded as found). The steep
                # bearing itself says where she is: where it meets the floor.
                self._cue.pop(sid, None)
                floor = self._floor_point(ev)
                if self._near_found(floor):
                    # ... unless that is beside a victim found already: her own voice, not a second one (measured,
                    # dense_pump seed 7 with min_unknown_listens 2: declared again 0.73 m from a found caller).
                    continue
                s = self.map.source(self.map.add_found(floor, self.clock.now()))
                crit += f"; where this bearing meets the floor (the source it joined is mapped {d:.2f} m away)"
            self._declare_found(s, crit, cue)
            return True
        return False

    def _off_estimate_deg(self, ev: ListenEvidence, s: MapSource) -> float:
        """Angle (deg) between a bearing heard now and the direction from the array to the source's estimate."""
        x, y, yaw = self.pose
        c, si = math.cos(yaw), math.sin(yaw)
        u = np.asarray(ev.direction, float)
        u = np.array([c * u[0] - si * u[1], si * u[0] + c * u[1], u[2]])
        v = s.position - np.array([x, y, self.mount.height_m])
        cos = float(u @ v) / max(float(np.linalg.norm(u) * np.linalg.norm(v)), 1e-12)
        return math.degrees(math.acos(max(-1.0, min(1.0, cos))))

    def _bearing_range(self, ev: ListenEvidence, height_m: float) -> float:
        """Horizontal range (m) at which a bearing heard now meets the height ``height_m`` (m above the floor,
        below the array); inf for a bearing not pointing below the horizon."""
        h = self.mount.height_m - height_m
        return h / math.tan(-ev.elevation) if ev.elevation < 0 else math.inf

    def _floor_point(self, ev: ListenEvidence) -> np.ndarray:
        """Where a bearing heard now (pointing down) meets the map's prior source height: world (x, y, z) m."""
        x, y, yaw = self.pose
        r = self._bearing_range(ev, self.map.config.source_height_m)   # finite: called for steep bearings only
        a = yaw + ev.azimuth
        return np.array([x + r * math.cos(a), y + r * math.sin(a), self.map.config.source_height_m])

    def _floor_echo(self, ev: ListenEvidence) -> bool:
        """A steep bearing no louder than a shallower one (within ``reach_elevation_deg`` of the horizon, above or
        below it) within ``echo_azimuth_deg`` of it, heard from the same spot (in this listen or an earlier one
        from here): an echo of a source beyond reach (off the floor or debris, or an elevation side lobe), no found
        cue. A mouth right below is the loudest sound in its direction. Above the horizon too: a machine standing
        higher than the array has its floor image steep below it (dense_pump seed 3: the pump at +2 deg, 0.9 m
        away, and its image at -37 deg, 3.6 dB weaker, at the same azimuth, declared a victim at 29.85 s)."""
        cfg = self.config
        return any(o is not ev and abs(wrap_angle(o.azimuth - ev.azimuth)) <= math.radians(cfg.echo_azimuth_deg)
                   and ev.elevation < o.elevation and abs(math.degrees(o.elevation)) < cfg.reach_elevation_deg
                   and ev.level_db <= o.level_db for o in self._evidence)

    def _listen_again(self, s: MapSource, why: str) -> bool:
        """Count one more listen at ``s``; True (and a NO_TARGET event) while fewer than ``reject_after_listens``."""
        n = self._close_listens[s.id] = self._close_listens.get(s.id, 0) + 1
        if n < self.config.reject_after_listens:
            self._emit(Decision.NO_TARGET, f"{why}: listen again ({n}/{self.config.reject_after_listens})",
                       SourcePayload(s.id))
            return True
        return False

    def _reject(self, s: MapSource, why: str) -> None:
        """Never a target again (a machine, a reflection)."""
        self.map.set_state(s.id, SourceState.REJECTED, self.clock.now())
        if self.target == s.id:
            self.target, self.plan = None, None
        self._emit(Decision.REJECTED, f"source #{s.id}: {why}", RejectedPayload(s.id, s.position.tolist()))

    def _near_found(self, xy, source_id: int | None = None) -> bool:
        """World point ``xy`` (m) is within ``found_exclusion_m`` of a victim already found other than
        ``source_id``: another bearing of it (a reflection, a second track), never a second victim to declare
        (measured: a duplicate 0.5 m from a found caller)."""
        return any(o.id != source_id and o.state is SourceState.FOUND
                   and o.distance_to(xy) <= self.config.found_exclusion_m for o in self.map.sources)

    def _near_machine(self, s: MapSource) -> bool:
        return any(o.id != s.id and o.state is SourceState.REJECTED
                   and o.distance_to(s.position) <= self.config.machine_radius_m for o in self.map.sources)

    def _approachable(self, s: MapSource) -> bool:
        """May be declared a found victim: classified victim, or (unless ``require_voice``) not yet classified."""
        return s.cls is SourceClass.VICTIM or (not self.config.require_voice and s.cls is SourceClass.UNKNOWN)

    def _declare_found(self, s: MapSource, criterion: str, cue: FindCriterion) -> None:
        cfg = self.config
        self.map.set_state(s.id, SourceState.FOUND, self.clock.now())
        pos = (float(s.position[0]), float(s.position[1]))
        height = float(np.clip(s.position[2], 0.0, 2.0))
        self.victims.append(FoundVictim(pos, self.clock.now(), criterion, height, s.victim_probability, s.id, cue))
        if self.target == s.id:
            self.target, self.plan = None, None
        self.state = RescueState.FOUND
        self._emit(Decision.VICTIM_FOUND, f"victim #{len(self.victims)} (source #{s.id}) at ({pos[0]:.2f}, "
                                          f"{pos[1]:.2f}) m +- {s.horizontal_sigma_m:.2f} m: {criterion}",
                   FoundPayload(pos, height, s.id, criterion, cue, s.horizontal_sigma_m, s.victim_probability))
        if cfg.max_victims is not None and len(self.victims) >= cfg.max_victims:
            self._finish(Decision.ALL_FOUND, f"found {len(self.victims)} victim(s) = max_victims")

    def _victim_number(self, sid: int) -> int:
        return next((i + 1 for i, v in enumerate(self.victims) if v.source_id == sid), 0)

    # -- moving ---------------------------------------------------------------------
    def _no_target(self, why: str) -> None:
        cfg = self.config
        if self.target is not None:
            self._release_target()
        mapped = any(s.state is not SourceState.FOUND and s.n_inliers >= 2 for s in self.map.sources)
        if self._silent < cfg.explore_after_silent and not mapped:
            self._emit(Decision.NO_TARGET, f"{why}; listen again")
            return
        self._silent = 0
        avoid = [s.position[:2] for s in self.map.sources if s.state is SourceState.FOUND]
        plan, how = self.planner.explore_goal(self.grid, self.pose, self.coverage, avoid, self._machines())
        if plan is None:
            self._emit(Decision.NO_TARGET, f"{why}; {how}")
            n = self.grid.forget()
            if n:
                # Learned by touch, the grid can close every way out (contacts placed by drifting odometry,
                # stalls on debris): forget what single contacts marked and replan after the next listen.
                self.planner.clear_unreachable()
                self.state = RescueState.RECOVER
                self._emit(Decision.RECOVER, f"the learned obstacles close every way: {n} cell(s) marked by a single"
                                             " contact forgotten (clearing recovery)", RecoverPayload("clear", n))
                return
            self._escape("no reachable direction to explore")
            return
        self.state = RescueState.EXPLORE
        self._follow(plan, RescueState.EXPLORE, Decision.EXPLORE, None, prefix=f"{why}: explore {how}")

    def _machines(self) -> list[np.ndarray]:
        """World (x, y) of the mapped interferers: their sound masks the callers near them."""
        return [s.position[:2] for s in self.map.sources
                if s.cls is SourceClass.INTERFERER and s.state is not SourceState.FOUND]

    def _release_target(self) -> None:
        try:
            self.map.set_state(self.target, SourceState.UNVISITED)
        except KeyError:
            pass
        self.target, self.plan = None, None

    def _follow(self, plan: Plan, state: RescueState, decision: Decision, target: MapSource | None,
                prefix: str = "") -> None:
        """Drive along the plan's waypoints, at most ``step_m`` in all."""
        cfg = self.config
        x, y, _ = self.pose
        legs, left, here = [], cfg.step_m, np.array([x, y])
        for wp in plan.waypoints:
            d = float(np.hypot(*(wp - here)))
            if d < 1e-3:
                continue
            take = min(d, left)
            legs.append(here + (wp - here) * (take / d))
            left -= take
            here = legs[-1]
            if left <= 1e-3:
                break
        total = cfg.step_m - left
        if total < 0.02 and target is not None and target.horizontal_sigma_m > cfg.found_sigma_m:
            # At the goal but the source's range is still open (heard only along one line): step across the
            # bearing for a baseline that triangulates it.
            n = self._baseline_steps[target.id] = self._baseline_steps.get(target.id, 0) + 1
            if n > cfg.max_baseline_steps:
                self._baseline_steps[target.id] = 0
                self.planner.mark_unreachable(target.id, self.clock.now())
                self._emit(Decision.NO_TARGET, f"source #{target.id} still +- {target.horizontal_sigma_m:.2f} m after "
                                               f"{cfg.max_baseline_steps} steps across its bearing: set aside a while",
                           SourcePayload(target.id))
                return
            bearing = math.atan2(target.position[1] - y, target.position[0] - x)
            side = self._side
            self._side = -self._side
            legs = [np.array([x, y]) + cfg.baseline_step_m * np.array([math.cos(bearing + side * math.pi / 2),
                                                                         math.sin(bearing + side * math.pi / 2)])]
            total = cfg.baseline_step_m
            prefix = f"source #{target.id} +- {target.horizontal_sigma_m:.2f} m: step across its bearing for a baseline"
        elif total < 0.02:
            self._emit(Decision.NO_TARGET, f"{prefix or 'at the goal'}: nothing to drive")
            if target is not None:
                self.planner.mark_unreachable(target.id, self.clock.now())
            return
        self.state = state
        goal = legs[-1]
        self._emit(decision, f"{prefix + ': ' if prefix else ''}{total:.2f} m toward ({goal[0]:.2f}, {goal[1]:.2f})"
                             f" in {len(legs)} leg(s)", DrivePayload(total, [float(goal[0]), float(goal[1])],
                                                                     [leg.tolist() for leg in legs]))
        for leg in legs:
            start = self.pose[:2].copy()
            dx, dy = leg - start
            heading = float(wrap_angle(math.atan2(dy, dx) - self.pose[2]))
            try:
                self.motion.translate(heading, float(np.hypot(dx, dy)), stop_for_ranges=True)
            except Blocked as b:
                self.grid.mark_path(start, self.pose[:2])
                self._blocked(b, target)
                return
            self.grid.mark_path(start, self.pose[:2])

    def _blocked(self, b: Blocked, target: MapSource | None) -> None:
        cfg = self.config
        self.contacts[b.kind] += 1
        if b.kind is ContactKind.FAULT:
            return  # the mission is over (_check_faults finished it)
        if b.kind in (ContactKind.BUMPER, ContactKind.RANGE) and target is not None:
            s = self.map.source(target.id)
            x, y, _ = self.pose
            d = s.distance_to((x, y))
            off = abs(wrap_angle(math.atan2(s.position[1] - y, s.position[0] - x) - b.heading))
            # A touch is no cue that a mouth is there: rubble stands beside machines and mirror images too
            # (measured: dense_pump seed 0 declared the pump found by bumping into the rubble beside it, light
            # rubble seed 7 a caller's reflection 1.8 m from her, heard last at -6 deg). Only a source with a
            # voice heard, last heard pointing down as a mouth on the floor within reach does.
            voiced = s.cls is SourceClass.VICTIM or any(r.voice_probability >= 0.5 for r in s.history)
            down = bool(s.history) and -math.degrees(math.asin(max(-1.0, min(1.0, s.history[-1].direction[2])))) \
                >= cfg.supporting_elevation_deg
            if d <= cfg.bump_found_range_m and off <= math.radians(cfg.bump_ahead_deg) \
                    and s.state is not SourceState.FOUND and self._approachable(s) \
                    and not self._near_found(s.position, s.id) \
                    and s.horizontal_sigma_m <= 2 * cfg.found_sigma_m and voiced and down \
                    and self.clock.now() - s.last_time <= cfg.bump_heard_within_s \
                    and (s.cls is SourceClass.VICTIM or not self._near_machine(s)):
                touch = "bumped into it" if b.kind is ContactKind.BUMPER else "stopped before an obstacle at it"
                self._declare_found(s, f"{touch} while approaching (estimate {d:.2f} m ahead, "
                                       f"{math.degrees(off):.0f} deg off the motion)", FindCriterion.CONTACT)
                if not self.done and b.kind is ContactKind.BUMPER:
                    self._back_off(b.heading, "clear the bumper after touching the victim")
                return
        if target is not None:
            n = self._target_contacts[target.id] = self._target_contacts.get(target.id, 0) + 1
            if n >= cfg.max_contacts_per_target:
                # Walls the robot cannot see: a mirror image beyond a wall draws it along the wall forever.
                self.planner.mark_unreachable(target.id, self.clock.now())
                self._target_contacts[target.id] = 0
        if b.kind is ContactKind.RANGE:
            self._scan_pose = None
            self._sensed(self.pose, b.status)     # the reading that stopped the move goes into the grid
            seen = [round(r, 2) if math.isfinite(r) else None for r in b.status.ranges or ()]
            self._emit(Decision.OBSTACLE, "range sensors see an obstacle in the way: replan", ObstaclePayload(seen))
            return
        self._recover(b, "while moving")

    def _recover(self, b: Blocked, when: str) -> None:
        contact = self.grid.mark_contact(self.pose, b.heading, b.kind)
        if b.kind is ContactKind.BUMPER:
            self.coverage.shadow(contact, b.heading, self.grid.config.contact_width_m)
        self.state = RescueState.RECOVER
        what = {ContactKind.BUMPER: "bumper pressed", ContactKind.STALL: "wheels stalled",
                ContactKind.SLIP: "wheels slipping (gyro)"}[b.kind]
        self._emit(Decision.RECOVER, f"{what} {when}: obstacle mapped at ({contact[0]:.2f}, {contact[1]:.2f}), "
                                     f"back off {self.motion.config.backoff_m:g} m and replan",
                   ContactPayload(b.status.bumper, b.status.stalled, b.kind, contact.tolist()))
        if not self._back_off(b.heading, what):
            self._escape(f"backing off blocked after: {what}")

    def _back_off(self, heading_world: float, why: str) -> bool:
        try:
            self.motion.back_off(heading_world)
            return True
        except Blocked as b:
            self.contacts[b.kind] += 1
            if b.kind is not ContactKind.FAULT:
                self.grid.mark_contact(self.pose, b.heading, b.kind)
                self._emit(Decision.RECOVER, f"backing off blocked ({b.kind}) after: {why}", RecoverPayload(b.kind))
            return False

    def _escape(self, why: str) -> None:
        """Try a short move in eight directions (the four axes, then the diagonals: wedged between debris pieces
        the robot may pass between them), standing ``settle_s`` before each, in ``escape_rounds`` rounds; "stuck"
        only when every one is blocked. A failed push leaves the robot pressed against what it met, and the next
        direction stalls on that friction: measured, dense_pump seed 1 declared stuck at 47 s against a wall with
        the floor free along it (from its final state a move along the wall succeeds). When a whole round stalled
        and none pressed the bumper, the robot is not walled in but wedged, a wheel against a piece of debris: it
        turns in place (the wheels meet the debris at other angles) before the next round."""
        kinds: list[str] = []
        turned = False
        for attempt in range(self.config.escape_rounds):
            if attempt and not any(k.endswith("bumper") for k in kinds):
                turned = True
                try:
                    self.motion.turn(math.radians(self.config.wedged_turn_deg))
                except Blocked as b:
                    self.contacts[b.kind] += 1
                    if b.kind is ContactKind.FAULT:
                        return
            yaw = float(self.pose[2])
            kinds = []
            for k in (0, 2, 4, 6, 1, 3, 5, 7):
                heading = k * math.pi / 4
                self.motion.stand(self.config.settle_s)
                try:
                    self.motion.translate(heading, self.motion.config.backoff_m, self.motion.config.recover_speed,
                                          arm_bumper_on_release=True)
                    self._emit(Decision.RECOVER, f"{why}; freed by moving {math.degrees(heading):.0f} deg "
                                                 f"(robot frame){' after turning in place' if turned else ''}",
                               RecoverPayload("escape"))
                    return
                except Blocked as b:
                    self.contacts[b.kind] += 1
                    if b.kind is ContactKind.FAULT:
                        return
                    kinds.append(f"{math.degrees(heading):.0f} deg: {b.kind}")
                    self.grid.mark_contact(self.pose, yaw + heading, b.kind)
        self._finish(Decision.STUCK, f"{why}; a move in each of eight directions was blocked, "
                                     f"{self.config.escape_rounds} times (last round: {', '.join(kinds)})")

    # -- helpers ----------------------------------------------------------------------
    def _bearing_to(self, position) -> tuple[float, float]:
        """Array-frame azimuth and elevation (rad) of a world point from the current pose."""
        x, y, yaw = self.pose
        dx, dy = position[0] - x, position[1] - y
        dz = position[2] - self.mount.height_m
        return float(wrap_angle(math.atan2(dy, dx) - yaw)), float(math.atan2(dz, math.hypot(dx, dy)))

    def _check_faults(self, status: DriveStatus) -> bool:
        faults = tuple(status.faults)
        if faults != self._faults_seen:
            new = sorted(set(faults) - set(self._faults_seen))
            if new:
                self._emit(Decision.DRIVE_FAULT, f"drive reports fault(s) {', '.join(new)}", DriveFaultPayload(list(faults)))
            self._faults_seen = faults
        fatal = sorted(set(faults) & set(self.config.fatal_faults))
        if fatal:
            self._finish(Decision.FAULT, f"fatal drive fault(s) {', '.join(fatal)}: stopping the mission")
            return True
        return False

    def _finish(self, decision: Decision, reason: str) -> None:
        self._safe_stop()
        self.state = RescueState.DONE
        self._emit(decision, reason, FinishPayload([v.position for v in self.victims]))

    def _safe_stop(self) -> Exception | None:
        """Stop the drive; the exception if that failed (logged, never raised)."""
        try:
            self.drive.stop()
        except Exception as exc:  # never mask the original error; the backend's own failsafe must act
            log.error("drive.stop() failed: %s", exc)
            return exc
        return None

    def _emit(self, decision: Decision, reason: str, data: Payload = Payload()) -> RescueEvent:
        ev = RescueEvent(self.clock.now(), self.state, Decision(decision), reason, data)
        self.events.append(ev)
        self._step_events.append(ev)
        log.info("%s", ev)
        return ev
