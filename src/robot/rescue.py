"""The rescue behaviour: listen, pick a victim, turn and drive toward it, repeat.

The paper's loop (localize, send the loudest source's azimuth to the drive)
made robust for a mission with several victims:

* **listen** standing still (motor noise off, stale audio flushed) for
  ``listen_s`` and localize all sources with the SRP-PHAT localizer;
* **ignore** detections that point at victims already found (their estimated
  positions are kept in the odometry frame; a detection is theirs when both
  its azimuth and its elevation match the bearing and the expected elevation
  of the stored position from the current pose);
* **choose** the target: the highest-energy source (as in the paper), but
  voice sources (``robot.vad`` on a beam toward each) first, and the current target kept
  unless another is ``switch_ratio_db`` louder (no dithering between two voices);
* **found** when the victim is close, by one of three stated criteria:
  (1) the detection's elevation is steeper than ``found_elevation_deg`` below
  the horizon (the array is ``array_height_m`` above the floor and a lying
  victim's mouth ``source_height_m``: at 30 deg the mouth is ~0.35 m away),
  (2) elevation steeper than ``corroborated_elevation_deg`` *and* the level
  rose by ``level_rise_db`` since the target was acquired, or (3) the bumper
  fires while driving at a target that is ahead and close by (1)-(2)'s
  measures (range estimate <= ``bump_found_range_m`` or the level rise).
  A non-voice source that is approached (nothing better was heard) is
  "found" the same way; ``FoundVictim.voice`` tells them apart;
* **turn** toward its azimuth and **drive** a step (shorter when the range
  estimate from the elevation says it is near), with odometry feedback;
* **recover** from a bump (not at a victim) or a wheel stall: back off,
  sidestep (always to the same side, wider on each consecutive recovery, so
  repeated recoveries get around the obstacle; the other side once a sidestep
  is itself blocked) and pass ahead; give up after ``max_recoveries`` in a row;
* **explore** a step after ``explore_after_silent`` silent listens: ahead, or
  away from the nearest found victim, whose calls mask fainter victims.

Frames: detections are in the array frame, whose axes are the robot's
(azimuth CCW from forward); poses and victim positions in the odometry frame
(``start_pose`` sets it, e.g. to the world start pose in simulation).
The drive is stopped at the end of every step and on any exception.
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, fields
from enum import Enum
from typing import Any

import numpy as np

from robot.hal import AudioSource, Clock, DriveBase, DriveStatus, as_float_audio
from robot.kinematics import OmniDriveParams
from robot.odometry import Odometry, wrap_angle
from robot.vad import SileroVad, speech_fraction
from ssl_core.beamform import beam_signal

log = logging.getLogger(__name__)


class RescueState(str, Enum):
    """Phase of the behaviour (the state an event was decided in)."""

    LISTEN = "listen"          # standing, listening, deciding
    TURN = "turn"              # turning in place toward the target
    APPROACH = "approach"      # driving a step toward the target
    FOUND = "found"            # a victim was just declared found
    RECOVER = "recover"        # backing off / sidestepping after a bump or stall
    EXPLORE = "explore"        # moving without a target after silence
    DONE = "done"              # finished: max victims, stuck, audio ended, fatal fault


@dataclass(frozen=True)
class RescueConfig:
    """All parameters of the behaviour (SI units; ``*_deg`` fields in degrees for readability)."""

    # listening
    listen_s: float = 1.0                  # audio per localization (s)
    settle_s: float = 0.3                  # wait after stopping before listening (s): motor noise, sway
    min_power: float = 0.0                 # ignore detections with a lower normalised SRP power
    # choosing
    prefer_voice: bool = True              # voice-like sources before louder non-voice ones
    require_voice: bool = False            # never approach a non-voice source
    voice_threshold: float = 0.2           # VAD speech-frame fraction of the beam counted as voice (>= 0.2 of
                                           # a 1 s chunk: 100 % of speech, 0 % of non-speech chunks, data/sounds test)
    switch_ratio_db: float = 3.0           # another source must be this much louder to replace the target
    track_gate_deg: float = 25.0           # a detection this close to the target's predicted azimuth is it
    # found victims
    array_height_m: float = 0.30           # array centre above the floor
    source_height_m: float = 0.10          # assumed mouth height of a victim lying on the floor
    found_elevation_deg: float = 30.0      # criterion 1: detection steeper than this below horizontal
    corroborated_elevation_deg: float = 20.0  # criterion 2: this steep (mouth within ~0.55 m) ...
    level_rise_db: float = 9.0             # ... and the level rose this much since acquiring the target
    bump_found_range_m: float = 0.8        # criterion 3: bump while the target is estimated this close
    bump_ahead_deg: float = 35.0           # ... and was this close to straight ahead
    exclusion_deg: float = 15.0            # azimuth gate around a found victim's bearing (grows when near)
    exclusion_radius_m: float = 0.4        # a found victim's position uncertainty (m)
    exclusion_elevation_deg: float = 20.0  # elevation gate around its expected elevation
    max_victims: int | None = None         # stop after finding this many (None: keep searching)
    # motion
    control_dt: float = 0.05               # control loop period while moving (s)
    turn_speed: float = 1.2                # max turn rate (rad/s)
    turn_tolerance_deg: float = 6.0        # do not turn for a target this close to straight ahead
    drive_speed: float = 0.25              # m/s
    step_m: float = 0.6                    # longest drive step between two listens
    min_step_m: float = 0.1
    approach_stop_m: float = 0.25          # stop this short of the range estimate
    turn_first: bool = True                # turn to face the target (else translate holonomically)
    # recovery
    backoff_m: float = 0.15
    sidestep_m: float = 0.30               # first sidestep; x2, x3 on the next consecutive recoveries
    pass_m: float = 0.30                   # then ahead this far (past the obstacle's edge); 0 = no
    recover_speed: float = 0.15            # m/s
    max_recoveries: int = 6                # consecutive recoveries before giving up (stuck)
    stall_window_s: float = 0.6            # own stall check: progress over this window ...
    stall_progress_ratio: float = 0.2      # ... below this fraction of the commanded motion = stalled
    motion_timeout_factor: float = 3.0     # a move may take this many times its nominal duration
    fatal_faults: tuple[str, ...] = ("encoder_error",)  # drive faults that end the mission
    # exploring
    explore_after_silent: int = 3          # silent listens in a row before an exploration step
    explore_step_m: float = 0.5

    def __post_init__(self) -> None:
        positive = ("listen_s", "control_dt", "turn_speed", "drive_speed", "step_m", "min_step_m", "recover_speed",
                    "stall_window_s", "motion_timeout_factor", "array_height_m", "exclusion_radius_m")
        for name in positive:
            if not getattr(self, name) > 0:
                raise ValueError(f"RescueConfig.{name}: expected > 0, got {getattr(self, name)}")
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float) and not math.isfinite(v):
                raise ValueError(f"RescueConfig.{f.name}: expected a finite number, got {v}")
            if isinstance(v, float) and v < 0:
                raise ValueError(f"RescueConfig.{f.name}: expected >= 0, got {v}")
        if not 0 < self.found_elevation_deg < 90 or not 0 < self.corroborated_elevation_deg < 90:
            raise ValueError("RescueConfig.found_elevation_deg / corroborated_elevation_deg: expected 0 < deg < 90")
        if not self.source_height_m < self.array_height_m:
            raise ValueError(f"RescueConfig.source_height_m: expected below array_height_m = {self.array_height_m} m, "
                             f"got {self.source_height_m}")
        if not 0 <= self.voice_threshold <= 1:
            raise ValueError(f"RescueConfig.voice_threshold: expected 0..1, got {self.voice_threshold}")
        if self.min_step_m > self.step_m:
            raise ValueError(f"RescueConfig.min_step_m: expected <= step_m = {self.step_m}, got {self.min_step_m}")
        if self.max_recoveries < 1 or self.explore_after_silent < 1:
            raise ValueError("RescueConfig.max_recoveries / explore_after_silent: expected >= 1")
        if self.max_victims is not None and self.max_victims < 1:
            raise ValueError(f"RescueConfig.max_victims: expected None or >= 1, got {self.max_victims}")

    def range_from_elevation(self, elevation: float) -> float | None:
        """Horizontal range (m) to a mouth at ``source_height_m`` seen at ``elevation`` (rad, array frame),
        or None when the detection is not below the horizon enough to tell (> -2 deg)."""
        if elevation > -np.deg2rad(2.0):
            return None
        return (self.array_height_m - self.source_height_m) / math.tan(-elevation)


@dataclass(frozen=True)
class RescueEvent:
    """One decision: ``time`` (s, clock), the ``state`` it was taken in, a short ``decision`` keyword,
    a human-readable ``reason`` and machine-readable ``data`` (SI units, angles in rad)."""

    time: float
    state: RescueState
    decision: str
    reason: str
    data: dict[str, Any] = field(default_factory=dict)

    def __str__(self) -> str:
        return f"[{self.time:8.2f} s] {self.state.value:<8} {self.decision:<13} {self.reason}"


@dataclass(frozen=True)
class Candidate:
    """A detection seen from the robot: array-frame angles (rad), SRP power, energy (dB), voice score."""

    azimuth: float
    elevation: float
    power: float
    energy_db: float
    voice: float
    range_m: float | None       # horizontal range from the elevation (m), None when unknown
    world_bearing: float        # azimuth in the odometry frame (rad)

    def as_data(self) -> dict[str, Any]:
        return {"azimuth": self.azimuth, "elevation": self.elevation, "power": self.power,
                "energy_db": self.energy_db, "voice": self.voice, "range_m": self.range_m}


@dataclass(frozen=True)
class FoundVictim:
    """A victim declared found: estimated ``position`` (x, y) in the odometry frame (m) and the
    estimated ``height`` (m above the floor) of its sound, from the range and the elevation."""

    position: tuple[float, float]
    time: float
    criterion: str
    height: float
    voice: float = 0.0  # voice score of the last detection (0..1): a non-voice source may be "found" too


class _Blocked(Exception):
    """A move ended early: bumper or stall (internal control flow)."""

    def __init__(self, kind: str, status: DriveStatus) -> None:
        super().__init__(kind)
        self.kind = kind
        self.status = status


class RescueBehaviour:
    """The behaviour on any HAL backend; call ``step()`` repeatedly or ``run(max_time)``.

    ``localizer``: an ``ssl_core.localizer.Localizer`` (or anything with
    ``locate(samples) -> result`` whose ``result.detections`` have
    ``azimuth``, ``elevation`` (rad, array frame), ``power`` and optionally
    ``level_db``). Its ``geometry`` (if present) is used to beamform toward each
    detection for the voice score; give ``geometry`` explicitly otherwise.
    """

    def __init__(self, audio: AudioSource, drive: DriveBase, clock: Clock, localizer,
                 config: RescueConfig = RescueConfig(), *, params: OmniDriveParams = OmniDriveParams(),
                 start_pose=(0.0, 0.0, 0.0), geometry=None) -> None:
        self.audio, self.drive, self.clock, self.localizer, self.config = audio, drive, clock, localizer, config
        geometry = geometry if geometry is not None else getattr(localizer, "geometry", None)
        self._mic_positions = None if geometry is None else np.asarray(getattr(geometry, "positions", geometry), float)
        if self._mic_positions is not None and self._mic_positions.shape[0] != audio.n_channels:
            raise ValueError(f"geometry: {self._mic_positions.shape[0]} microphones but the audio source has "
                             f"{audio.n_channels} channels")
        loc_fs = getattr(getattr(localizer, "config", None), "fs", None)
        if loc_fs is not None and int(loc_fs) != audio.sample_rate:
            raise ValueError(f"localizer fs is {loc_fs} Hz but the audio source delivers {audio.sample_rate} Hz")
        self.odometry = Odometry(params, start_pose)
        self._vad: SileroVad | None = None  # created on first use (loads the ONNX model)
        self.state = RescueState.LISTEN
        self.events: list[RescueEvent] = []
        self.victims: list[FoundVictim] = []
        self.target: Candidate | None = None
        self.last_candidates: list[Candidate] = []
        self._target_start_db: float | None = None
        self._silent = 0
        self._recoveries = 0
        self._side = 1.0
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
        except EOFError as exc:
            self._finish("audio_ended", f"audio source exhausted ({exc})")
        except BaseException as exc:
            self._safe_stop()
            self._emit("error", f"{type(exc).__name__}: {exc}; drive stopped", {"exception": type(exc).__name__})
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
                self._emit("time_up", f"mission time of {max_time:g} s used up", {"max_time": max_time})
                out += self._step_events
        finally:
            self._safe_stop()
        return out

    # -- the cycle ----------------------------------------------------------------
    def _cycle(self) -> None:
        if not self._odo_started:
            self._update_odometry()
            self._odo_started = True
        self.state = RescueState.LISTEN
        status = self.drive.status()
        if self._check_faults(status):
            return
        if status.bumper or status.stalled:
            self._recover("bumper pressed" if status.bumper else "wheels stalled", status)
            return
        cands = self._listen()
        if not cands:
            self._silent += 1
            self.target = None
            if self._silent >= self.config.explore_after_silent:
                self._silent = 0
                self._explore()
            return
        self._silent = 0
        target, why = self._choose(cands)
        if target is None:
            self._emit("no_target", why)
            self.target = None
            return
        new = self.target is None or not self._same_source(self.target, target)
        if new:
            self._target_start_db = target.energy_db
        self.target = target
        rise = target.energy_db - self._target_start_db if self._target_start_db is not None else 0.0
        self._emit("target", why, {**target.as_data(), "new": new, "level_rise_db": rise})
        criterion = self._found_criterion(target, rise)
        if criterion:
            self._declare_found(target, criterion)
            return
        self._approach(target, rise)

    def _listen(self) -> list[Candidate]:
        cfg = self.config
        self.drive.stop()
        self.clock.sleep(cfg.settle_s)
        self.audio.flush()
        n = max(1, int(round(cfg.listen_s * self.audio.sample_rate)))
        t0 = self.clock.now()
        block = self.audio.read(n)
        # Listening takes the block's duration of clock time. Live and simulated sources let it pass
        # themselves; for one that does not (a file without a clock) let it pass here, standing still.
        lag = n / self.audio.sample_rate - (self.clock.now() - t0)
        if lag > 1e-9:
            self.clock.sleep(lag)
        result = self.localizer.locate(block.samples)
        self._update_odometry()
        dets = list(getattr(result, "detections", []) or [])
        yaw = float(self.pose[2])
        x = None
        cands: list[Candidate] = []
        ignored = []
        for d in dets:
            power = float(d.power)
            if power < cfg.min_power:
                ignored.append(f"power {power:.2f} < min_power")
                continue
            az, el = float(d.azimuth), float(d.elevation)
            energy = getattr(d, "level_db", None)
            voice = 0.0
            if self._mic_positions is not None:  # listen toward it: voice score (logged even when not preferred)
                x = as_float_audio(block.samples) if x is None else x
                direction = getattr(d, "direction", None)
                if direction is None:
                    direction = [math.cos(az) * math.cos(el), math.sin(az) * math.cos(el), math.sin(el)]
                beam = beam_signal(x, self._mic_positions, direction, self.audio.sample_rate)
                if self._vad is None:
                    self._vad = SileroVad()
                voice = speech_fraction(self._vad.probabilities(beam, self.audio.sample_rate))
                if energy is None:
                    energy = 10 * math.log10(max(float(np.mean(beam**2)), 1e-20))
            if energy is None:
                energy = 10 * math.log10(max(power, 1e-20))
            c = Candidate(az, el, power, float(energy), float(voice), cfg.range_from_elevation(el),
                          float(wrap_angle(yaw + az)))
            owner = self._found_victim_of(c)
            if owner is not None:
                ignored.append(f"az {math.degrees(az):+.0f} deg el {math.degrees(el):+.0f} deg is found victim "
                               f"#{owner + 1}")
                continue
            cands.append(c)
        self.last_candidates = cands
        data = {"n_detections": len(dets), "candidates": [c.as_data() for c in cands], "ignored": ignored,
                "pose": self.pose.tolist()}
        if cands:
            self._emit("heard", f"{len(cands)} candidate source(s)" + (f"; ignored: {'; '.join(ignored)}" if ignored
                                                                        else ""), data)
        else:
            why = "no source detected" if not dets else "only ignored sources: " + "; ".join(ignored)
            self._emit("no_source", f"{why} (silent listen {self._silent + 1}/{cfg.explore_after_silent})", data)
        return cands

    def _choose(self, cands: list[Candidate]) -> tuple[Candidate | None, str]:
        cfg = self.config
        voiced = [c for c in cands if c.voice >= cfg.voice_threshold]
        if cfg.require_voice and not voiced:
            return None, f"no voice-like source (best voice score {max(c.voice for c in cands):.2f} < " \
                         f"{cfg.voice_threshold}); require_voice is set"
        pool = voiced if (cfg.prefer_voice or cfg.require_voice) and voiced else cands
        loudest = max(pool, key=lambda c: c.energy_db)
        kind = "voice-like source" if pool is voiced else "source (none voice-like)"
        rng = f" (~{loudest.range_m:.1f} m)" if loudest.range_m is not None else ""
        why = f"loudest {kind}: az {math.degrees(loudest.azimuth):+.0f} deg, " \
              f"el {math.degrees(loudest.elevation):+.0f} deg{rng}, {loudest.energy_db:.1f} dB, " \
              f"voice {loudest.voice:.2f}"
        skipped = [c for c in cands if c not in pool and c.energy_db > loudest.energy_db]
        if skipped:
            why += f"; skipped {len(skipped)} louder non-voice source(s)"
        if self.target is not None:
            tracked = [c for c in pool if self._same_source(self.target, c)]
            if tracked:
                keep = max(tracked, key=lambda c: c.energy_db)
                if keep is loudest:
                    return keep, "current target is still the " + why
                if loudest.energy_db - keep.energy_db < cfg.switch_ratio_db:
                    return keep, (f"keep current target at az {math.degrees(keep.azimuth):+.0f} deg "
                                  f"({keep.energy_db:.1f} dB): the loudest is only "
                                  f"{loudest.energy_db - keep.energy_db:.1f} dB louder (< {cfg.switch_ratio_db} dB)")
                why = f"switch target: {why}, {loudest.energy_db - keep.energy_db:.1f} dB above the current one"
        return loudest, why

    def _same_source(self, old: Candidate, new: Candidate) -> bool:
        return abs(wrap_angle(new.world_bearing - old.world_bearing)) <= math.radians(self.config.track_gate_deg)

    def _found_criterion(self, t: Candidate, rise: float) -> str | None:
        cfg = self.config
        steep = -math.degrees(t.elevation)
        if steep >= cfg.found_elevation_deg:
            return f"elevation {-steep:.0f} deg is steeper than -{cfg.found_elevation_deg:g} deg"
        if steep >= cfg.corroborated_elevation_deg and rise >= cfg.level_rise_db:
            return (f"elevation {-steep:.0f} deg (< -{cfg.corroborated_elevation_deg:g}) and level rose "
                    f"{rise:.1f} dB (>= {cfg.level_rise_db:g})")
        return None

    def _found_victim_of(self, c: Candidate) -> int | None:
        cfg = self.config
        x, y, yaw = self.pose
        for i, v in enumerate(self.victims):
            dx, dy = v.position[0] - x, v.position[1] - y
            dist = math.hypot(dx, dy)
            bearing = math.atan2(dy, dx) - yaw
            gate = max(math.radians(cfg.exclusion_deg), math.atan2(cfg.exclusion_radius_m, max(dist, 1e-6)))
            expected_el = math.atan2(v.height - cfg.array_height_m, dist)
            if abs(wrap_angle(c.azimuth - bearing)) <= gate and \
                    abs(c.elevation - expected_el) <= math.radians(cfg.exclusion_elevation_deg):
                return i
        return None

    def _declare_found(self, t: Candidate, criterion: str, range_m: float | None = None) -> None:
        cfg = self.config
        r = range_m if range_m is not None else (t.range_m if t.range_m is not None else cfg.approach_stop_m)
        x, y, yaw = self.pose
        # Along the bearing measured in the odometry frame (the robot may have turned since the detection).
        pos = (float(x + r * math.cos(t.world_bearing)), float(y + r * math.sin(t.world_bearing)))
        # Where the sound is vertically (a victim may sit, or call from a hole): keeps the exclusion
        # gate right when the mouth is not at the assumed source_height_m.
        height = float(np.clip(cfg.array_height_m + r * math.tan(t.elevation), 0.0, 2.0))
        self.victims.append(FoundVictim(pos, self.clock.now(), criterion, height, t.voice))
        self.state = RescueState.FOUND
        self._emit("victim_found", f"victim #{len(self.victims)} at ({pos[0]:.2f}, {pos[1]:.2f}) m: {criterion}",
                   {"position": pos, "criterion": criterion, **t.as_data()})
        self.target = None
        self._target_start_db = None
        if cfg.max_victims is not None and len(self.victims) >= cfg.max_victims:
            self._finish("all_found", f"found {len(self.victims)} victim(s) = max_victims")

    # -- acting ---------------------------------------------------------------------
    def _approach(self, t: Candidate, rise: float) -> None:
        cfg = self.config
        heading = t.azimuth
        if cfg.turn_first and abs(t.azimuth) > math.radians(cfg.turn_tolerance_deg):
            self.state = RescueState.TURN
            self._emit("turn", f"turn {math.degrees(t.azimuth):+.0f} deg toward the target", {"angle": t.azimuth})
            yaw_before = float(self.pose[2])
            try:
                self._turn(t.azimuth)
            except _Blocked as b:
                self._blocked(b, t, rise, while_="turning")
                return
            heading = wrap_angle(t.azimuth - (float(self.pose[2]) - yaw_before))  # ~0 unless the turn timed out
        # (within the turn tolerance the omni base simply translates along the azimuth)
        dist = cfg.step_m
        why = f"step of {cfg.step_m:.2f} m"
        if t.range_m is not None and t.range_m - cfg.approach_stop_m < cfg.step_m:
            dist = max(cfg.min_step_m, t.range_m - cfg.approach_stop_m)
            why = f"{dist:.2f} m: target estimated {t.range_m:.2f} m away (stop {cfg.approach_stop_m:g} m short)"
        self.state = RescueState.APPROACH
        self._emit("drive", f"drive {why}", {"distance": dist, "heading": heading})
        try:
            self._translate(heading, dist, cfg.drive_speed)
        except _Blocked as b:
            self._blocked(b, t, rise, while_="driving")
            return
        self._recoveries = 0

    def _blocked(self, b: _Blocked, t: Candidate, rise: float, while_: str) -> None:
        cfg = self.config
        self.drive.stop()
        self._update_odometry()
        if b.kind == "fault":
            return  # the mission is over (_check_faults finished it)
        if b.kind == "bumper":
            ahead = abs(t.azimuth) <= math.radians(cfg.bump_ahead_deg) or while_ == "driving"
            close = (t.range_m is not None and t.range_m <= cfg.bump_found_range_m) or rise >= cfg.level_rise_db
            if ahead and close:
                rng = f"{t.range_m:.2f} m" if t.range_m is not None else "unknown range"
                crit = f"bumped into it while {while_} (target {rng}, level rise {rise:.1f} dB)"
                self._declare_found(t, crit, range_m=0.25)
                if not self.done:
                    self._back_off("clear the bumper after touching the victim")
                return
        self._recover(f"{'bumper pressed' if b.kind == 'bumper' else 'wheels stalled'} while {while_} "
                      "(not at a victim)", b.status)

    def _recover(self, why: str, status: DriveStatus) -> None:
        cfg = self.config
        self._recoveries += 1
        if self._recoveries > cfg.max_recoveries:
            self._finish("stuck", f"{why}; {cfg.max_recoveries} recoveries in a row did not free the robot")
            return
        self.state = RescueState.RECOVER
        side = "left" if self._side > 0 else "right"
        # Wider sidesteps on repeated bumps: the obstacle is wider than the last one.
        sidestep = cfg.sidestep_m * min(self._recoveries, 3)
        self._emit("recover", f"{why}: back off {cfg.backoff_m:g} m, sidestep {side} {sidestep:g} m, pass "
                              f"{cfg.pass_m:g} m ahead (attempt {self._recoveries}/{cfg.max_recoveries})",
                   {"bumper": status.bumper, "stalled": status.stalled, "side": side, "sidestep_m": sidestep})
        self._back_off(why)
        if self.done:
            return
        try:
            self._translate(self._side * math.pi / 2, sidestep, cfg.recover_speed, arm_bumper_on_release=True)
            if cfg.pass_m > 0:
                # Move on past the obstacle's edge before turning back toward the target.
                self._translate(0.0, cfg.pass_m, cfg.recover_speed)
        except _Blocked as b:
            if b.kind == "fault":
                return
            # Keep sidestepping to the same side (around the obstacle) until that side is blocked too.
            self._side = -self._side
            self._emit("recover", f"sidestep/pass {side} blocked ({b.kind}); next time the other side")

    def _back_off(self, why: str) -> None:
        cfg = self.config
        try:
            # The bumper is still pressed at the start: it only counts again once it has been released.
            self._translate(math.pi, cfg.backoff_m, cfg.recover_speed, arm_bumper_on_release=True)
        except _Blocked as b:
            if b.kind != "fault":
                self._emit("recover", f"backing off blocked ({b.kind}) after: {why}")

    def _explore(self) -> None:
        cfg = self.config
        self.state = RescueState.EXPLORE
        heading, why = 0.0, "ahead"
        x, y, yaw = self.pose
        if self.victims:
            # A found victim who keeps calling masks fainter ones (SRP-PHAT reports the dominant source):
            # moving away from the nearest one raises the others relative to it.
            v = min(self.victims, key=lambda v: math.hypot(v.position[0] - x, v.position[1] - y))
            heading = float(wrap_angle(math.atan2(y - v.position[1], x - v.position[0]) - yaw))
            why = f"away from found victim #{self.victims.index(v) + 1} (its calls mask fainter sources)"
        self._emit("explore", f"{cfg.explore_after_silent} silent listens: move {cfg.explore_step_m:g} m {why} "
                              "to hear fainter sources", {"distance": cfg.explore_step_m, "heading": heading})
        try:
            self._translate(heading, cfg.explore_step_m, cfg.drive_speed)
        except _Blocked as b:
            if b.kind != "fault":
                self._recover(f"{'bumper pressed' if b.kind == 'bumper' else 'wheels stalled'} while exploring",
                              b.status)

    # -- motion primitives (odometry feedback) ---------------------------------------
    def _update_odometry(self) -> np.ndarray:
        return self.odometry.update(self.drive.odometry(), self.drive.status().yaw_rate)

    def _check_motion(self, bumper_armed: bool) -> None:
        st = self.drive.status()
        if self._check_faults(st):
            raise _Blocked("fault", st)
        if st.bumper and bumper_armed:
            raise _Blocked("bumper", st)
        if st.stalled:
            raise _Blocked("stall", st)

    def _turn(self, angle: float) -> None:
        cfg = self.config
        yaw0 = float(self._update_odometry()[2])
        t_end = self.clock.now() + cfg.motion_timeout_factor * (abs(angle) / cfg.turn_speed + 0.5)
        watch = _StallWatch(cfg, self.clock.now(), yaw0, rotational=True)
        while True:
            yaw = float(self._update_odometry()[2])
            remaining = angle - (yaw - yaw0)
            if abs(remaining) <= math.radians(1.0) or self.clock.now() >= t_end:
                break
            omega = math.copysign(min(cfg.turn_speed, max(0.25, 2.5 * abs(remaining))), remaining)
            self.drive.set_twist(0.0, 0.0, omega)
            self.clock.sleep(cfg.control_dt)
            self._check_motion(bumper_armed=True)
            watch.check(self.clock.now(), float(self._update_odometry()[2]), abs(omega))
        self.drive.stop()
        self._update_odometry()

    def _translate(self, heading: float, distance: float, speed: float, arm_bumper_on_release: bool = False) -> None:
        """Move ``distance`` m along ``heading`` (rad, robot frame at the start) keeping the yaw."""
        cfg = self.config
        x0, y0, yaw0 = self._update_odometry()
        ux, uy = math.cos(yaw0 + heading), math.sin(yaw0 + heading)
        t_end = self.clock.now() + cfg.motion_timeout_factor * (distance / speed + 0.5)
        armed = not arm_bumper_on_release or not self.drive.status().bumper
        watch = _StallWatch(cfg, self.clock.now(), 0.0, rotational=False)
        while True:
            x, y, yaw = self._update_odometry()
            done = (x - x0) * ux + (y - y0) * uy
            remaining = distance - done
            if remaining <= 0.005 or self.clock.now() >= t_end:
                break
            v = min(speed, max(0.05, 2.0 * remaining))
            rel = heading - (yaw - yaw0)  # hold the start yaw: the direction in the body frame turns back
            self.drive.set_twist(v * math.cos(rel), v * math.sin(rel), -2.0 * (yaw - yaw0))
            self.clock.sleep(cfg.control_dt)
            st = self.drive.status()
            armed = armed or not st.bumper
            self._check_motion(bumper_armed=armed)
            x, y, _ = self._update_odometry()
            watch.check(self.clock.now(), (x - x0) * ux + (y - y0) * uy, v)
        self.drive.stop()
        self._update_odometry()

    # -- bookkeeping ----------------------------------------------------------------
    def _check_faults(self, status: DriveStatus) -> bool:
        faults = tuple(status.faults)
        if faults != self._faults_seen:
            new = sorted(set(faults) - set(self._faults_seen))
            if new:
                self._emit("drive_fault", f"drive reports fault(s) {', '.join(new)}", {"faults": list(faults)})
            self._faults_seen = faults
        fatal = sorted(set(faults) & set(self.config.fatal_faults))
        if fatal:
            self._finish("fault", f"fatal drive fault(s) {', '.join(fatal)}: stopping the mission")
            return True
        return False

    def _finish(self, decision: str, reason: str) -> None:
        self._safe_stop()
        self.state = RescueState.DONE
        self._emit(decision, reason, {"victims": [v.position for v in self.victims]})

    def _safe_stop(self) -> None:
        try:
            self.drive.stop()
        except Exception as exc:  # never mask the original error; the backend's own failsafe must act
            log.error("drive.stop() failed: %s", exc)

    def _emit(self, decision: str, reason: str, data: dict[str, Any] | None = None) -> RescueEvent:
        ev = RescueEvent(self.clock.now(), self.state, decision, reason, dict(data or {}))
        self.events.append(ev)
        self._step_events.append(ev)
        log.info("%s", ev)
        return ev


class _StallWatch:
    """Own stall detection from odometry: too little progress for the commanded motion over a window."""

    def __init__(self, cfg: RescueConfig, t: float, progress: float, rotational: bool) -> None:
        self.cfg, self.t0, self.p0, self.rot = cfg, t, progress, rotational
        self.expected = 0.0
        self.last_t = t

    def check(self, t: float, progress: float, commanded_rate: float) -> None:
        self.expected += commanded_rate * (t - self.last_t)
        self.last_t = t
        if t - self.t0 >= self.cfg.stall_window_s:
            made = abs(progress - self.p0)
            if self.expected > 0 and made < self.cfg.stall_progress_ratio * self.expected:
                raise _Blocked("stall", DriveStatus(stalled=True))
            self.t0, self.p0, self.expected = t, progress, 0.0
