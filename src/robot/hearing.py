"""Voice evidence per tracked source: a beam toward each track, a VAD on each beam, and a
per-track voice probability accumulated over time.

Data path: 8-channel block -> ``ssl_core.beamform.StreamingBeamformer`` (delay-and-sum toward each
track's direction, array frame) -> ``robot.vad.SileroVad`` (one stream per track, batched) ->
a log-odds filter per track id -> ``TrackEvidence``.

The filter (log-odds L of "this source is a human voice", prior L = 0, i.e. P = 0.5):
  * each 32 ms VAD frame of a SOUNDING track (activity >= ``min_activity``) adds ``rise_per_s``
    x 0.032 if the frame is speech (VAD probability >= 0.5), and subtracts ``fall_per_s`` x 0.032 if not;
  * a track that is not sounding (a pause) leaves L unchanged: a victim who pauses stays a victim;
  * L is clipped to +-``max_log_odds`` so that either class can be overturned within seconds.
Why asymmetric: a caller talks in bursts (a call of ~1 s, then silence with the track still
active), so speech frames are rare but decisive, while a machine yields speech frames in 0 % of
its frames on the data set (benchmarks/bench_voice.py); with the defaults a 1 s call of 50 %
speech frames adds +6, a second of non-speech subtracts 1.5, and a machine reaches P < 0.2
from the prior after ~1 s.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import Protocol, Sequence

import numpy as np

from robot.hal import as_float_audio
from robot.vad import SAMPLE_RATE, SPEECH_THRESHOLD, SileroVad, VadStream
from ssl_core.beamform import StreamingBeamformer, level_db


class TrackLike(Protocol):
    """What Hearing needs of a track (``ssl_core.tracking.Track`` has these fields)."""

    id: int
    direction: np.ndarray  # (3,) unit vector, array frame
    activity: float        # 0..1


@dataclass(frozen=True)
class TrackEvidence:
    track_id: int
    direction: np.ndarray          # (3,) unit vector, array frame (the track's)
    time: float                    # s, stream time of the end of the block
    voice_probability: float       # accumulated per-track P(voice) (0..1); a pause keeps it
    level_db: float                # beam level toward the track (dB re full-scale sine)
    activity: float                # the track's activity


@dataclass(frozen=True)
class HearingConfig:
    rise_per_s: float = 12.0       # log-odds per second of speech frames (0.38 per 32 ms frame)
    fall_per_s: float = 1.5        # log-odds lost per second of non-speech frames while sounding
    max_log_odds: float = 6.0      # |L| cap: P in [0.0025, 0.9975]
    min_activity: float = 0.5      # tracks below this activity are pausing: their beam is not classified

    def __post_init__(self) -> None:
        for name in ("rise_per_s", "fall_per_s", "max_log_odds"):
            if not getattr(self, name) > 0:
                raise ValueError(f"HearingConfig.{name}: expected > 0, got {getattr(self, name)}")
        if not 0 <= self.min_activity <= 1:
            raise ValueError(f"HearingConfig.min_activity: expected 0..1, got {self.min_activity}")


class VoiceClass(enum.Enum):
    VOICE = "voice"
    NON_VOICE = "non_voice"
    UNKNOWN = "unknown"


VOICE_MIN_PROBABILITY = 0.8      # log-odds +1.4: e.g. 4 speech frames (0.13 s) from the prior
NON_VOICE_MAX_PROBABILITY = 0.2  # log-odds -1.4: ~1 s of a sounding track without speech from the prior


def classify(evidence: TrackEvidence) -> VoiceClass:
    """VOICE if P(voice) >= 0.8, NON_VOICE if <= 0.2, else UNKNOWN (not heard long enough)."""
    p = evidence.voice_probability
    if p >= VOICE_MIN_PROBABILITY:
        return VoiceClass.VOICE
    if p <= NON_VOICE_MAX_PROBABILITY:
        return VoiceClass.NON_VOICE
    return VoiceClass.UNKNOWN


class Hearing:
    """``update(block, tracks, time)`` per audio block -> one ``TrackEvidence`` per given track.

    ``mic_positions`` (n_mics, 3) m, array frame; ``sample_rate`` must be 16 kHz (the VAD's rate).
    Tracks are matched by id; the state of an id that is no longer given is dropped (track ids are
    never reused).
    """

    def __init__(self, mic_positions: np.ndarray, sample_rate: int = SAMPLE_RATE,
                 config: HearingConfig = HearingConfig(), vad: SileroVad | None = None) -> None:
        if sample_rate != SAMPLE_RATE:
            raise ValueError(f"sample_rate: expected {SAMPLE_RATE} Hz (the VAD's rate), got {sample_rate}")
        self.config = config
        self.beamformer = StreamingBeamformer(mic_positions, sample_rate)
        self.vad = vad or SileroVad()
        self._streams: dict[int, VadStream] = {}
        self._log_odds: dict[int, float] = {}

    def update(self, block: np.ndarray, tracks: Sequence[TrackLike], time: float) -> list[TrackEvidence]:
        cfg = self.config
        x = as_float_audio(block)
        directions = np.array([np.asarray(t.direction, float) for t in tracks]).reshape(-1, 3)
        beams = self.beamformer.process(x, directions)
        ids = [int(t.id) for t in tracks]
        for gone in set(self._streams) - set(ids):
            del self._streams[gone], self._log_odds[gone]
        sounding = [i for i, t in enumerate(tracks) if t.activity >= cfg.min_activity]
        for i in sounding:
            self._streams.setdefault(ids[i], self.vad.new_stream())
        probs = self.vad.process([self._streams[ids[i]] for i in sounding], [beams[i] for i in sounding])
        step_up = cfg.rise_per_s * self.vad.frame_s
        step_down = cfg.fall_per_s * self.vad.frame_s
        for i, p in zip(sounding, probs):
            n_speech = int(np.count_nonzero(p >= SPEECH_THRESHOLD))
            L = self._log_odds.get(ids[i], 0.0) + n_speech * step_up - (len(p) - n_speech) * step_down
            self._log_odds[ids[i]] = float(np.clip(L, -cfg.max_log_odds, cfg.max_log_odds))
        levels = level_db(beams) if len(tracks) else []
        return [TrackEvidence(ids[i], directions[i].copy(), float(time),
                              float(1.0 / (1.0 + np.exp(-self._log_odds.get(ids[i], 0.0)))),
                              float(levels[i]), float(t.activity)) for i, t in enumerate(tracks)]
