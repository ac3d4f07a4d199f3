"""One listen standing still: fresh audio, localized sources, and voice evidence toward each of them.

This is the hearing stage of the rescue data path (hearing -> sound map -> planner -> behaviour -> motion)
fed by per-window detections: each detection of the listen becomes one ``ListenEvidence`` (array frame,
``track_id`` None) whose ``voice_probability`` comes from the speech the Silero VAD hears in the beam toward
it (``robot.hearing.speech_fractions``: the MPDR + noise suppression chain of ``robot.hearing``, each speech
frame credited to the beam that owns it). The sound map accumulates these per source over listens, which is what a
tracker + ``robot.hearing.Hearing`` would do per track; a tracker can replace the per-window detections
without changing the map's interface (``robot.sound_map.BearingEvidence``).

Per-listen voice probability: ``VOICE_P`` when the beam's speech-frame fraction reaches ``voice_threshold``,
else ``NON_VOICE_P``. Asymmetric, as in ``robot.hearing``: speech frames are rare but decisive (the VAD
calls no 1 s chunk of the data set's non-speech test part speech; the pump of dense_pump gave 0 speech frames
in 29 of 29 listens), while a listen without speech is weak evidence (a caller pauses; and with the
delay-and-sum beam used before, callers 2-4 m away in the light rubble gave speech frames in 0-12 % of their
listens, with this chain a talking caller's beam in 84 %: docs/design/behaviour.md, "The sound map").
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Protocol, Sequence

import numpy as np

from robot.hal import AudioBlock, AudioSource, Clock, as_float_audio
from robot.hearing import VAD_RATE, speech_fractions, voice_scan
from robot.vad import SileroVad, check_model
from ssl_core.beamform import beam_signal
from ssl_core.grid import direction_from_angles

__all__ = ["ListenEvidence", "Listen", "Listener", "VOICE_P", "NON_VOICE_P"]

VOICE_P = 0.9          # a listen whose beam is speech (log-odds +2.2)
NON_VOICE_P = 0.42     # a listen whose beam is not (log-odds -0.32: seven of them undo one with speech)


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
    the drive's noise (``Localizer.ego_noise``); standing still (speeds below its ``min_speed``) nothing changes."""

    def __init__(self, audio: AudioSource, clock: Clock, localizer: Any, mic_positions: np.ndarray | None,
                 voice_threshold: float = 0.2, speech=None, voice_scan_deg: float = 0.0, drive=None) -> None:
        self.audio, self.clock, self.localizer = audio, clock, localizer
        self.drive = drive
        self.mic_positions = mic_positions
        self.voice_threshold = voice_threshold
        self.speech = speech
        self.voice_scan_deg = voice_scan_deg
        self._vad: SileroVad | None = None   # on first use (``check_model``: shared, checked)

    def listen(self, seconds: float, settle_s: float, min_power: float) -> Listen:
        self.clock.sleep(settle_s)
        self.audio.flush()
        n = max(1, int(round(seconds * self.audio.sample_rate)))
        t0 = self.clock.now()
        wheels = self._wheel_speeds()
        block = self.audio.read(n)
        # Listening takes the block's duration of clock time. Live and simulated sources let it pass
        # themselves; for one that does not (a file without a clock) let it pass here, standing still.
        lag = n / self.audio.sample_rate - (self.clock.now() - t0)
        if lag > 1e-9:
            self.clock.sleep(lag)
        if wheels is None:
            result = self.localizer.locate(block.samples)
        else:  # the drive's noise is suppressed from the wheel speeds (mean of the readings around the block)
            result = self.localizer.locate(block.samples, wheel_speeds=0.5 * (wheels + self._wheel_speeds()))
        dets: list[Detection] = list(getattr(result, "detections", []) or [])
        heard = self._evidence(block, dets, self.clock.now(), min_power)
        # The strongest source is no voice (or none is heard): a voice may be hiding beside it.
        if not heard[0] or heard[0][0].speech_fraction < self.voice_threshold:
            extra = self._scanned(block, result, dets)
            if extra:
                # all beams again, together: which beam owns the speech depends on every beam heard with it
                scanned = self._evidence(block, dets + extra, self.clock.now(), min_power, extra)
                # kept only if its beam owns the voice it was added for (else a detection beside it does)
                if len(scanned[0]) > len(heard[0]) and scanned[0][-1].speech_fraction >= self.voice_threshold:
                    heard = scanned
        return Listen(block, *heard)

    def _wheel_speeds(self) -> np.ndarray | None:
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
