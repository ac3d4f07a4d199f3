"""One listen standing still: fresh audio, localized sources, tracked across listens, and voice evidence.

This is the hearing stage of the rescue data path (hearing -> sound map -> planner -> behaviour -> motion), one
chain per listen: localizer (``locate`` over the block: array frame) -> streaming tracker
(``ssl_core.tracking.Tracker``, one update per listen) -> voice evidence per detection and per track ->
``ListenEvidence`` for the sound map (``robot.sound_map.BearingEvidence``).

Tracking across listens. Each listen's detections are one tracker update at the block's end time. Given the
robot's pose at each listen (``listen(..., pose=(x, y, yaw))``, world/odometry frame), the tracker is told the
motion since the previous listen: the yaw change as a rotation of the array frame and the array centre's
displacement (the array sits on the robot's vertical axis, ``robot.mount``) in the current array frame, each
track's source re-aimed from the new centre at its assumed range (``source_range_m``). A source keeps its track
id while the robot turns and drives between listens, and the sound map prefers the source that id fed
(``SoundMap._associate``). A listen without a pose leaves the motion unknown: the tracker starts over, and ids
hold within that listen only. Every detection becomes evidence; ``track_id`` is the id of the track it updated or
started (None only if the tracker calls it neither, or its track is still tentative under a config that
confirms late). ``LISTEN_TRACKER`` is the default tracker configuration (why each value: there).

Per-listen voice probability: ``VOICE_P`` when the beam's speech-frame fraction reaches ``voice_threshold``,
else ``NON_VOICE_P``, from the speech the Silero VAD hears in the beam toward the detection
(``robot.hearing.speech_fractions``: the MPDR + noise suppression chain of ``robot.hearing``, each speech frame
credited to the beam that owns it). Both are likelihood ratios measured on the benchmark's train split (see
``VOICE_P``): speech frames are rare but decisive (a machine's or an echo's beam has some in 7 % of listens), while
a listen without speech is weak evidence (a caller pauses: her beam has none in 56 % of her listens).
Per-track voice probability (``track_voice_probability``, ``Listener.track_voice``): the same per-listen
log-odds summed over the listens of one track id (prior 0.5), clipped to +-``MAX_TRACK_LOG_ODDS``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Protocol, Sequence

import numpy as np

from robot.hal import AudioBlock, AudioSource, Clock, as_float_audio
from robot.hearing import VAD_RATE, speech_fractions, voice_scan
from robot.vad import SileroVad, check_model
from ssl_core.beamform import beam_signal
from ssl_core.grid import direction_from_angles
from ssl_core.tracking import Tracker, TrackerConfig

__all__ = ["ListenEvidence", "Listen", "Listener", "TrackVoice", "LISTEN_TRACKER", "VOICE_P", "NON_VOICE_P",
           "MAX_TRACK_LOG_ODDS"]

# Likelihood ratios of one listen, measured on train scenarios 0-47 (tools/fit_voice_evidence.py, rows in
# experiments/results/voice_evidence/): a bearing within 10 deg of a calling victim has speech in its beam in 44 %
# of listens, one toward anything else (a machine, an echo, a lobe) in 6.6 %. Log-odds +1.91 [1.62, 2.23] with
# speech, -0.52 [-0.71, -0.35] without (95 % over scenarios), as probabilities from the prior 0.5:
VOICE_P = 0.87         # a listen whose beam is speech (log-odds +1.9)
NON_VOICE_P = 0.37     # a listen whose beam is not (log-odds -0.5: about four of them undo one with speech)
# Cap of a track's summed voice log-odds, the sound map's (SoundMapConfig.max_log_odds): four listens with speech
# (+7.6) or twelve without (-6.2) reach it, and either class can still be overturned by a few listens.
MAX_TRACK_LOG_ODDS = 6.0

# The tracker between listens: one update per 1 s listen, listens 3-7 s apart (a 2-6 s drive between them).
# Fields left at TrackerConfig's defaults (measurement_sigma, power model, p_track/p_new/p_false, activity filter,
# history) are per-detection models that hold for a listen's pooled detections too (a pooled mode is no less
# accurate than one window's peak); the activity filter is not read here.
LISTEN_TRACKER = TrackerConfig(
    # Sources in a rescue stand still (a trapped caller, a machine); the robot's own motion is removed by the
    # rotation/translation given per listen. What is left between listens is the odometry's yaw error and the
    # parallax error of the assumed range (a 0.5 m step across a source at 1 m instead of the assumed 2 m: up to
    # 14 deg; at 4 m 7 deg). 0.5 deg/s^2 with a 1 s velocity memory lets a track born at 3 deg coast to a
    # direction sigma of 3.3 / 5.1 / 9.5 deg after 2 / 4 / 6 s (the detection's 1.7-7.5 deg added in the gate):
    # the tracker's gate (~3 sigma for strong detections) takes these errors and stays well inside the 90 deg
    # between two sources a turn swaps (tests/test_hearing_stage.py). The tracker's default (10 deg/s^2, 3 s: a
    # walking talker over 128 ms windows) coasts to 80 deg after 4 s, a gate that takes any detection.
    acceleration_sigma_deg=0.5,
    speed_memory_s=1.0,        # a velocity fitted to bearings seconds apart is odometry and parallax error
    initial_speed_sigma_deg=1.0,
    # Every detection not explained by a track starts one: a listen's detection is already a mode of the
    # block's windows seen in at least two of them (Localizer.locate: the false-alarm control), and the map
    # needs an id on every bearing to tie the next listen's bearing to it. The tracker's default (0.9) starts
    # none below power 0.064, above the median power of a talker at SNR 5 dB (0.058, TrackerConfig).
    theta_new=0.0,
    # Confirmed at its first detection for the same reason: with 3 of 8 windows a track would only get an id at
    # its third listen (10-20 s), and the first listens' evidence none. The sound map accumulates its own
    # evidence per source (listens, inliers, voice), which is what decides what to approach.
    confirm_hits=1,
    confirm_windows=1,
    # Deleted after 15 s without a detection: a source missed in one or two listens (a caller's pause, a
    # drive of up to 6 s) keeps its id; longer, its coasted direction (sigma ~56 deg at 15 s) no longer means
    # much, and a new id costs only the map's looser gate.
    silence_s=15.0,
)


class Detection(Protocol):
    """What the listener needs of a localizer detection (``ssl_core.localizer.Detection`` has it)."""

    azimuth: float     # rad, array frame
    elevation: float   # rad
    power: float


@dataclass(frozen=True)
class ListenEvidence:
    """One detection of one listen as map evidence (``robot.sound_map.BearingEvidence``)."""

    track_id: int | None
    direction: np.ndarray          # (3,) unit vector, array frame
    time: float                    # s, end of the block
    voice_probability: float
    level_db: float                # beam level (dB re full-scale sine), or 10 lg SRP power without geometry
    activity: float
    power: float                   # normalised SRP-PHAT peak power of the detection (0..1): how much of the
                                   # sound arrives as one plane wave (a mouth within the critical distance: high)
    speech_fraction: float = 0.0   # VAD frames called speech in the beam (0..1)
    voice_scan: bool = False       # added by the voice scan (``Listener``), not a peak of the SRP-PHAT search
    track_voice_probability: float | None = None   # P(voice) of its track over its listens so far (this one
    #                                                included); None given: this listen's voice_probability

    def __post_init__(self) -> None:
        if self.track_voice_probability is None:
            object.__setattr__(self, "track_voice_probability", float(self.voice_probability))

    @property
    def azimuth(self) -> float:
        return float(math.atan2(self.direction[1], self.direction[0]))

    @property
    def elevation(self) -> float:
        return float(math.asin(max(-1.0, min(1.0, self.direction[2]))))


@dataclass(frozen=True)
class Listen:
    block: AudioBlock
    evidence: list[ListenEvidence]
    n_detections: int
    ignored: list[str] = field(default_factory=list)


class TrackVoice:
    """Voice log-odds per track id, summed over listens (prior 0.5, clipped to +-``max_log_odds``)."""

    def __init__(self, max_log_odds: float = MAX_TRACK_LOG_ODDS) -> None:
        if not (math.isfinite(max_log_odds) and max_log_odds > 0):
            raise ValueError(f"max_log_odds={max_log_odds!r}: expected a finite number > 0")
        self.max_log_odds = float(max_log_odds)
        self._log_odds: dict[int, float] = {}

    def add(self, track_id: int, voice_probability: float) -> float:
        """Fold in one listen's ``voice_probability`` (0..1) for ``track_id``; returns the track's probability."""
        p = min(max(float(voice_probability), 1e-6), 1 - 1e-6)
        lo = self._log_odds.get(int(track_id), 0.0) + math.log(p / (1 - p))
        self._log_odds[int(track_id)] = min(max(lo, -self.max_log_odds), self.max_log_odds)
        return self.probability(track_id)

    def probability(self, track_id: int) -> float:
        if int(track_id) not in self._log_odds:
            raise KeyError(f"track_id={track_id}: no voice evidence for this track (none heard, or deleted)")
        return 1.0 / (1.0 + math.exp(-self._log_odds[int(track_id)]))

    def keep(self, track_ids) -> None:
        """Forget the tracks not in ``track_ids`` (the tracker deleted them; ids are never reused)."""
        live = {int(t) for t in track_ids}
        self._log_odds = {k: v for k, v in self._log_odds.items() if k in live}


class Listener:
    """``listen(seconds, settle_s, min_power)`` -> ``Listen``. ``mic_positions`` (n, 3) m, array frame (None:
    no beam, no voice evidence). ``speech`` replaces the VAD: ``speech(samples, detection, direction)`` -> the
    speech-frame fraction (0..1) toward that detection (replayed annotations, tests).

    ``voice_scan_deg`` > 0: when the strongest detection of a listen carries no voice (or nothing is detected),
    the listen is also scanned for one (``robot.hearing.voice_scan``: beams every that many degrees of azimuth,
    heard by the VAD). A voice heard where no detection lies within that angle of azimuth adds the SRP-PHAT peak
    of that azimuth sector (``Localizer.peak_in_sector``: its elevation, power, significance >= the localizer's
    ``min_significance``) as a detection, kept only if its beam then owns the speech (``speech_fractions``'s
    owner rule; else the voice was a detection's beside it). Beside a louder machine the talker is often no peak
    of the map at all: in the five real-recording rooms of tests/test_hearing.py (a machine 6 dB louder) a voiced
    detection pointed at her in 31 of 70 listens instead of 15.

    ``drive``: the ``DriveBase`` whose wheel speeds (read around the block) go to the localizer when it suppresses
    the drive's noise (``Localizer.ego_noise``); standing still (speeds below its ``min_speed``) nothing changes.

    ``tracker``: the ``TrackerConfig`` of the tracker across listens (None: ``LISTEN_TRACKER``);
    ``source_range_m``: the range (m) a new track's source is assumed at when the robot's translation re-aims it
    (the tracker's ``source_range``). ``track_voice(track_id)``: the track's voice probability over its listens."""

    def __init__(self, audio: AudioSource, clock: Clock, localizer: Any, mic_positions,
                 voice_threshold: float = 0.2, speech=None, voice_scan_deg: float = 0.0, drive=None,
                 tracker: TrackerConfig | None = None, source_range_m: float = 2.0) -> None:
        self.audio, self.clock, self.localizer = audio, clock, localizer
        self.drive = drive
        if mic_positions is not None:
            mic_positions = np.asarray(getattr(mic_positions, "positions", mic_positions), float)
            if mic_positions.ndim != 2 or mic_positions.shape[0] != audio.n_channels:
                raise ValueError(f"geometry: {mic_positions.shape[0]} microphones but the audio source has "
                                 f"{audio.n_channels} channels")
        loc_fs = getattr(getattr(localizer, "config", None), "fs", None)
        if loc_fs is not None and int(loc_fs) != audio.sample_rate:
            raise ValueError(f"localizer fs is {loc_fs} Hz but the audio source delivers {audio.sample_rate} Hz")
        self.mic_positions = mic_positions
        self.voice_threshold = voice_threshold
        self.speech = speech
        self.voice_scan_deg = voice_scan_deg
        if tracker is not None and not isinstance(tracker, TrackerConfig):
            raise ValueError(f"tracker: expected a ssl_core.tracking.TrackerConfig or None, got {tracker!r}")
        if not (isinstance(source_range_m, (int, float)) and math.isfinite(source_range_m) and source_range_m > 0):
            raise ValueError(f"source_range_m={source_range_m!r}: expected a finite range > 0 m")
        self.tracker = Tracker(LISTEN_TRACKER if tracker is None else tracker)
        self.source_range_m = float(source_range_m)
        self.voice = TrackVoice()
        self._last_pose: tuple[float, float, float] | None = None
        self._vad: SileroVad | None = None   # on first use (``check_model``: shared, checked)

    def track_voice(self, track_id: int) -> float:
        """P(voice) of a live track over all its listens (KeyError for an id never heard or deleted)."""
        return self.voice.probability(track_id)

    def listen(self, seconds: float, settle_s: float, min_power: float, *,
               pose: tuple[float, float, float] | None = None) -> Listen:
        """Listen ``seconds`` s after ``settle_s`` s; detections below ``min_power`` are ignored. ``pose``: the
        robot's (x m, y m, yaw rad) in the world/odometry frame while the block is captured (standing still):
        with the previous listen's pose it gives the tracker the motion between them. None: the motion is
        unknown and the tracker starts over, so track ids then hold within one listen only (a robot that
        stands still passes its constant pose)."""
        motion = self._motion(pose)
        self.clock.sleep(settle_s)
        self.audio.flush()
        n = max(1, int(round(seconds * self.audio.sample_rate)))
        t0 = self.clock.now()
        wheels = self.wheel_speeds()
        block = self.audio.read(n)
        # Listening takes the block's duration of clock time. Live and simulated sources let it pass
        # themselves; for one that does not (a file without a clock) let it pass here, standing still.
        lag = n / self.audio.sample_rate - (self.clock.now() - t0)
        if lag > 1e-9:
            self.clock.sleep(lag)
        if wheels is not None:   # the mean of the readings around the block
            wheels = 0.5 * (wheels + self.wheel_speeds())
        return self._hear(block, min_power, motion, wheels, self.clock.now())

    def hear(self, block: AudioBlock, min_power: float, *, time: float, pose: tuple[float, float, float] | None,
             wheel_speeds=None) -> Listen:
        """A block captured elsewhere (while driving: ``robot.drive_hearing``) through the same chain as
        ``listen``: ``time`` is the clock's time (s) at the block's end, ``pose`` the robot's (x m, y m, yaw rad)
        at its middle (the tracker's motion since the previous listen); ``wheel_speeds`` (3,) rad/s the wheels'
        mean speed over the block, for the localizer's ego-noise suppression (None: not suppressed)."""
        w = None if wheel_speeds is None else np.asarray(wheel_speeds, float)
        return self._hear(block, min_power, self._motion(pose), w, float(time))

    def _hear(self, block: AudioBlock, min_power: float, motion, wheels, time: float) -> Listen:
        if wheels is None:
            result = self.localizer.locate(block.samples)
        else:  # the drive's noise is suppressed from the wheel speeds
            result = self.localizer.locate(block.samples, wheel_speeds=wheels)
        dets: list[Detection] = list(getattr(result, "detections", []) or [])
        heard = self._evidence(block, dets, time, min_power)
        # The strongest source is no voice (or none is heard): a voice may be hiding beside it.
        if not heard[0] or heard[0][0].speech_fraction < self.voice_threshold:
            extra = self._scanned(block, result, dets)
            if extra:
                # all beams again, together: which beam owns the speech depends on every beam heard with it
                scanned = self._evidence(block, dets + extra, time, min_power, extra)
                # kept only if its beam owns the voice it was added for (else a detection beside it does)
                if len(scanned[0]) > len(heard[0]) and scanned[0][-1].speech_fraction >= self.voice_threshold:
                    heard = scanned
        evidence, n_detections, ignored = heard
        return Listen(block, self._tracked(evidence, motion, time), n_detections, ignored)

    def _motion(self, pose) -> tuple[np.ndarray | None, np.ndarray | None]:
        """(rotation, translation) of the array frame since the previous listen, for ``Tracker.update``: the
        rotation maps the previous array frame's vectors into this one (``Rz(-dyaw)``), the translation is the
        array centre's displacement in this array frame (the array is level, on the robot's vertical axis).
        (None, None) for the first listen with a pose. Without a pose the motion since the last listen is
        unknown (the robot may have turned): the tracker starts over (ids keep counting up, so the sound map
        ties no new bearing to an old source by its id) rather than carry ids onto whatever now lies where a
        source was."""
        if pose is None:
            self.tracker.reset()
            self.voice.keep(())
            self._last_pose = None
            return None, None
        try:
            x, y, yaw = (float(v) for v in pose)
        except (TypeError, ValueError):
            raise ValueError(f"pose: expected (x m, y m, yaw rad), got {pose!r}") from None
        if not all(map(math.isfinite, (x, y, yaw))):
            raise ValueError(f"pose: expected finite (x m, y m, yaw rad), got {pose!r}")
        last, self._last_pose = self._last_pose, (x, y, yaw)
        if last is None:
            return None, None
        c, s = math.cos(yaw - last[2]), math.sin(yaw - last[2])
        rotation = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])          # Rz(-dyaw)
        dx, dy = x - last[0], y - last[1]
        cy, sy = math.cos(yaw), math.sin(yaw)
        translation = np.array([cy * dx + sy * dy, -sy * dx + cy * dy, 0.0])     # Rz(-yaw) (dx, dy, 0)
        return rotation, translation

    def _tracked(self, evidence: list[ListenEvidence], motion, time: float) -> list[ListenEvidence]:
        """The listen's evidence as one tracker update (every listen, also one without detections: tracks coast),
        each piece with its track's id and that track's accumulated voice probability."""
        rotation, translation = motion
        self.tracker.update(evidence, time, rotation=rotation, translation=translation,
                            source_range=self.source_range_m)
        ids = self.tracker.detection_ids()
        self.voice.keep(t.id for t in self.tracker.tracks())
        out = []
        for ev, tid in zip(evidence, ids):
            if tid is None:
                out.append(ev)
                continue
            out.append(replace(ev, track_id=int(tid),
                               track_voice_probability=self.voice.add(tid, ev.voice_probability)))
        return out

    def wheel_speeds(self) -> np.ndarray | None:
        """The wheels' speeds (3,) rad/s from ``drive``, only when the localizer suppresses the drive's noise
        (``Localizer.ego_noise``); None otherwise (the drive is then not asked at all)."""
        if self.drive is None or getattr(self.localizer, "ego_noise", None) is None:
            return None
        return np.asarray(self.drive.odometry().wheel_speeds, float)

    @property
    def vad(self) -> SileroVad:
        if self._vad is None:
            self._vad = check_model(VAD_RATE)   # loaded and run on silence once per process and file state
        return self._vad

    def _scanned(self, block: AudioBlock, result: Any, dets: Sequence[Detection]) -> list[Detection]:
        """The voice scan's detection (at most one; ``voice_scan_deg``), if no detection covers its azimuth."""
        sector = getattr(self.localizer, "peak_in_sector", None)
        if self.voice_scan_deg <= 0 or self.mic_positions is None or self.speech is not None or sector is None:
            return []
        az = voice_scan(block.samples, self.mic_positions, self.vad, self.audio.sample_rate, self.voice_scan_deg)
        half = math.radians(self.voice_scan_deg)
        if az is None or any(abs(math.remainder(d.azimuth - az, 2 * math.pi)) <= half for d in dets):
            return []
        peak = sector(result, az, half, block.samples)
        min_z = getattr(getattr(self.localizer, "config", None), "min_significance", 0.0)
        return [] if peak is None or not peak.significance >= min_z else [peak]

    def _evidence(self, block: AudioBlock, dets: Sequence[Detection], time: float, min_power: float,
                  scanned: Sequence[Detection] = ()) -> tuple[list[ListenEvidence], int, list[str]]:
        kept, ignored = [], []
        for d in dets:
            power = float(d.power)
            if power < min_power:
                ignored.append(f"power {power:.2f} < min_power")
                continue
            direction = getattr(d, "direction", None)
            u = np.asarray(direction if direction is not None else direction_from_angles(d.azimuth, d.elevation),
                           float)
            kept.append((d, u / np.linalg.norm(u)))
        fracs = np.zeros(len(kept))
        x = None
        if self.speech is not None:
            fracs = np.array([float(self.speech(block.samples, d, u)) for d, u in kept])
        elif self.mic_positions is not None and kept:
            x = as_float_audio(block.samples)
            fracs = speech_fractions(x, self.mic_positions, np.array([u for _, u in kept]), self.vad,
                                     self.audio.sample_rate)
        out = []
        for (d, u), frac in zip(kept, fracs):
            level = getattr(d, "level_db", None)
            if level is None and x is not None:
                level = 10 * math.log10(max(float(np.mean(beam_signal(x, self.mic_positions, u,
                                                                      self.audio.sample_rate)**2)), 1e-20))
            if level is None:
                level = 10 * math.log10(max(float(d.power), 1e-20))
            p = VOICE_P if frac >= self.voice_threshold else NON_VOICE_P
            out.append(ListenEvidence(None, u, float(time), p, float(level), activity=1.0,   # detected: sounding
                                      power=float(d.power), speech_fraction=float(frac),
                                      voice_scan=any(d is e for e in scanned)))
        return out, len(dets), ignored
