"""Voice evidence per tracked source: a beam toward each track, a VAD on each beam, and a
per-track voice probability accumulated over time.

Data path: 8-channel block -> streaming STFT (float32) -> ``ssl_core.beamform.MpdrBeamformer`` (one
beam per track toward its direction, array frame, bins below 4 kHz) -> stationary-noise suppression per
beam (the bin weights of ``ssl_core.noise.NoiseFloor``) -> inverse STFT at 8 kHz -> automatic gain ->
``robot.vad.SileroVad`` at 8 kHz (one stream per track, batched) -> a log-odds filter per track id ->
``TrackEvidence``.

Cost: the chain listens ``vad_on_s`` = 0.5 s in every ``vad_period_s`` = 1 s (all tracks at once;
in between it only keeps the last samples and the evidence is held; the MPDR covariance, noise floors
and gain follow listening time). Four tracks cost
6.0-6.4 ms of CPU per second of audio on one core (25-26 ms before: 16 kHz, every block); Silero alone is
2.6-2.9 ms of it. Listening less (1 s in 2, 0.5 in 1.5, 0.4 in 1) or refreshing the MPDR less often
lost windows in the room cases of tests/test_hearing.py (README, "Cost").

Why this front end (``benchmarks/bench_voice.py``, five rooms of RT60 0.6 s with a talker and a real
machine recording 6 dB louder, both 2 m away): Silero hears her in 26 % of her talking seconds at one
microphone, 56 % in the delay-and-sum beam, 99 % in the MPDR beam (it cancels the machine) and 100 %
with the noise suppression after it; in the hardest case the suppression keeps her track VOICE in
all windows where MPDR alone gives 64 %. Why the gain: Silero misses quiet speech (it found no
speech frames in beams at -50 dB re full scale).

The filter (log-odds L of "this source is a human voice", prior L = 0, i.e. P = 0.5):
  * each 32 ms VAD frame of a track adds ``rise_per_s`` x 0.032 if the frame is speech (VAD probability
    >= 0.5); each non-speech frame of a SOUNDING track (activity >= ``min_activity``) subtracts
    ``fall_per_s`` x 0.032;
    speech heard in several beams in the same block counts only for the beam with the largest share
    of its power above its noise floor (the talker's own; a talker leaking into a machine's beam);
  * a track that is not sounding (a pause) loses nothing: a victim who pauses stays a victim. Its beam
    is still heard: a talker beside a louder machine is detected in few windows, so her track's
    activity is often below 0.5 while she talks; when only sounding tracks were heard, her speech went
    to the machine's beam (real-chain room cases of tests/test_hearing.py at -6 dB SIR: her track VOICE
    in 16 % of her talking seconds, the machine NON_VOICE in 74 %; hearing every track: 33 % / 81 %);
  * L is clipped to +-``max_log_odds`` so that either class can be overturned within seconds.
Why asymmetric: a caller talks in bursts (a call of ~1 s, then silence with the track still
active), so speech frames are rare but decisive, while a machine yields speech frames in 0 % of
its frames on the data set (benchmarks/bench_voice.py); with the defaults a 1 s call of 50 %
speech frames adds +6, a second of non-speech subtracts 1.5, and a machine reaches P < 0.2
from the prior after ~1 s.
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from robot.hal import as_float_audio
from robot.vad import SAMPLE_RATE, SPEECH_THRESHOLD, SileroVad, VadStream
from ssl_core.beamform import FULL_SCALE_SINE_MS, MpdrBeamformer, OverlapAdd, StftStream, level_db
from ssl_core.noise import NoiseFloor
from ssl_core.tracking import Track

VAD_RATE = 8000  # Hz: the beams are formed below 4 kHz and heard by Silero at 8 kHz (README, "Cost")


@dataclass(frozen=True)
class TrackEvidence:
    track_id: int
    direction: np.ndarray          # (3,) unit vector, array frame (the track's)
    time: float                    # s, stream time of the end of the block
    voice_probability: float       # accumulated per-track P(voice) (0..1); a pause keeps it
    level_db: float                # beam level toward the track below 4 kHz (dB re full-scale sine), last listened block
    activity: float                # the track's activity


@dataclass(frozen=True)
class HearingConfig:
    rise_per_s: float = 12.0       # log-odds per second of speech frames (0.38 per 32 ms frame)
    fall_per_s: float = 1.5        # log-odds lost per second of non-speech frames while sounding
    max_log_odds: float = 6.0      # |L| cap: P in [0.0025, 0.9975]
    min_activity: float = 0.5      # tracks below this activity are pausing: their silence lowers nothing
    vad_level_db: float = -20.0    # automatic gain: the denoised beam is scaled toward this slow level
    max_gain_db: float = 60.0      # for the VAD
    level_tau_s: float = 2.0       # time constant of that slow level
    noise_memory_s: float = 3.0    # the noise floor's minimum-statistics memory, in listening time (speech
                                   # pauses within 3 s)
    noise_min_gain: float = 0.3    # noise suppression's lowest bin gain (-10 dB; 0.1 measured worse: musical
                                   # noise made Silero hear speech in a machine's beam)
    vad_on_s: float = 0.5          # the chain listens vad_on_s in every vad_period_s (all tracks at once):
    vad_period_s: float = 1.0      # half the cost. Room cases (README, "Cost"): 0.5 s in 1 s as good as
                                   # continuous; 1 s in 2 s, 0.4 in 1, 0.5 in 1.5 or 0.5 in 2 fall short
    beam_update_s: float = 0.5     # MPDR inverse covariance (and weights) refreshed every 0.5 s of listening
                                   # (1 s lost windows in the room cases; README, "Cost")

    def __post_init__(self) -> None:
        for name in ("rise_per_s", "fall_per_s", "max_log_odds"):
            if not getattr(self, name) > 0:
                raise ValueError(f"HearingConfig.{name}: expected > 0, got {getattr(self, name)}")
        if not 0 <= self.noise_min_gain <= 1:
            raise ValueError(f"HearingConfig.noise_min_gain: expected 0..1, got {self.noise_min_gain}")
        if not self.max_gain_db >= 0:
            raise ValueError(f"HearingConfig.max_gain_db: expected >= 0 dB, got {self.max_gain_db}")
        for name in ("level_tau_s", "noise_memory_s", "vad_on_s", "beam_update_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"HearingConfig.{name}: expected > 0, got {getattr(self, name)}")
        if not self.vad_period_s >= self.vad_on_s:
            raise ValueError(f"HearingConfig.vad_period_s: expected >= vad_on_s ({self.vad_on_s}), got {self.vad_period_s}")
        if not 0 <= self.min_activity <= 1:
            raise ValueError(f"HearingConfig.min_activity: expected 0..1, got {self.min_activity}")


def listen_beams(x: np.ndarray, mic_positions: np.ndarray, directions: np.ndarray,
                 config: HearingConfig = HearingConfig(), chunks: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """The front end of ``Hearing`` on one standing listen (not a stream): 16 kHz audio ``x`` (n_mics, n) ->
    ``(beams, excess)``: one beam per direction ((k, 3) unit vectors, array frame) at ``VAD_RATE``, (k, n // 2),
    for the VAD, and per beam the share of its power above its noise floor (k,) (speech heard in several
    beams is the talker's in the beam with the largest share, as in ``Hearing.update``).

    MPDR beams below 4 kHz (covariance over this listen), stationary-noise suppression per beam (floor: the
    least mean power of ``chunks`` equal parts of the listen, as ``NoiseFloor``'s minimum statistics over
    its memory) with the lowest bin gain ``noise_min_gain``, then each beam scaled toward ``vad_level_db``
    (at most ``max_gain_db``). Measured on a 30 s recording in dense_pump, 0.9 m from the mid-room caller
    and 4.2 m from the pump (1 s listens, Silero, a listen counts as voice at >= 0.1 speech frames): her
    beam was voice in 5 of 13 of her sounding seconds with this front end, in none with the plain
    delay-and-sum beam (none either with delay-and-sum and the gain, or MPDR and the gain without the
    suppression; 3 of 13 with delay-and-sum and the suppression); the pump's beam in 1 of 30 (0 of 30)."""
    positions = np.asarray(mic_positions, float)
    d = np.atleast_2d(np.asarray(directions, float))
    spec = StftStream(len(positions), np.float32).analyse(np.asarray(x, np.float32))
    n_frames = spec.shape[1]
    if not len(d) or n_frames == 0:
        return np.zeros((len(d), 0)), np.zeros(len(d))
    listen_s = x.shape[-1] / SAMPLE_RATE
    beams = MpdrBeamformer(positions, SAMPLE_RATE, memory_s=max(listen_s, 0.1), update_s=max(listen_s, 0.1),
                           max_freq_hz=VAD_RATE / 2).process(spec, d)               # (k, frames, bins)
    power = beams.real**2 + beams.imag**2
    parts = np.array_split(np.arange(n_frames), min(chunks, n_frames))
    floors = np.min([power[:, part].mean(axis=1) for part in parts], axis=0)       # (k, bins)
    weights = NoiseFloor(1).gains(power, floors[:, None])
    excess = (power * weights).sum(axis=(1, 2)) / np.maximum(power.sum(axis=(1, 2)), 1e-30)
    decimation = SAMPLE_RATE // VAD_RATE
    clean = OverlapAdd.synthesise_all([OverlapAdd(decimation) for _ in d], beams * np.maximum(weights,
                                                                                     config.noise_min_gain))
    gain_db = np.minimum(config.vad_level_db - level_db(clean, axis=-1), config.max_gain_db)
    return clean * 10 ** (gain_db[:, None] / 20), excess


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

    ``mic_positions`` (n_mics, 3) m, array frame; ``sample_rate`` must be 16 kHz (the microphones').
    ``tracks``: the ``ssl_core.tracking.Tracker``'s tracks (only ``id``, ``direction`` and ``activity``
    are used). Tracks are matched by id; the state of an id that is no longer given is dropped (track
    ids are never reused). ``vad``: an 8 kHz ``SileroVad`` (the beams are formed below 4 kHz and
    synthesised at 8 kHz).
    """

    def __init__(self, mic_positions: np.ndarray, sample_rate: int = SAMPLE_RATE,
                 config: HearingConfig = HearingConfig(), vad: SileroVad | None = None) -> None:
        if sample_rate != SAMPLE_RATE:
            raise ValueError(f"sample_rate: expected {SAMPLE_RATE} Hz, got {sample_rate}")
        self.config = config
        positions = np.asarray(mic_positions, float)
        # single precision from the STFT to the VAD (which takes float32): half the memory traffic
        self._stft = StftStream(len(positions), np.float32)
        self.vad = vad or SileroVad(sample_rate=VAD_RATE)
        if self.vad.sample_rate != VAD_RATE:
            raise ValueError(f"vad: expected a SileroVad at {VAD_RATE} Hz, got {self.vad.sample_rate} Hz")
        self._decimation = sample_rate // VAD_RATE
        self.beamformer = MpdrBeamformer(positions, sample_rate, update_s=config.beam_update_s,
                                         max_freq_hz=VAD_RATE / 2)
        self._state: dict[int, _TrackState] = {}
        self._samples = 0          # stream samples before this block (for the listening duty cycle)
        self._period = max(1, round(config.vad_period_s * sample_rate))   # listening cycle, samples
        self._on = max(1, round(config.vad_on_s * sample_rate))
        self._shares: dict[int, float] = {}   # _heard_share per block length
        self._gap = False          # blocks were skipped since the last listening block
        self._level: dict[int, float] = {}   # beam level (dB) per track id, last listening block

    def update(self, block: np.ndarray, tracks: Sequence[Track], time: float) -> list[TrackEvidence]:
        cfg = self.config
        x = as_float_audio(block)
        # The whole chain listens in the first vad_on_s of every vad_period_s (stream time), to all tracks
        # at once; in between it only keeps the last samples, and evidence keeps the last listened values.
        listening = self._samples % self._period < self._on
        self._samples += x.shape[-1]
        ids = [int(t.id) for t in tracks]
        for gone in set(self._state) - set(ids):
            del self._state[gone]
        for gone in set(self._level) - set(ids):
            del self._level[gone]
        if not listening:
            self._stft.skip(x)
            self._gap = True
            return self._evidence(tracks, ids, time)
        if self._gap:   # a new listening burst: the beams fade in, the VAD starts a new frame
            for st in self._state.values():
                st.synthesis.reset()
                st.vad.pending = st.vad.pending[:0]
            self._gap = False
        dt = x.shape[-1] / SAMPLE_RATE
        directions = np.array([np.asarray(t.direction, float) for t in tracks]).reshape(-1, 3)
        beams = self.beamformer.process(self._stft.analyse(x), directions)        # (k, frames, bins < 4 kHz)
        if beams.shape[1]:
            levels = 10 * np.log10(np.maximum(StftStream.mean_square(beams), 1e-30) / FULL_SCALE_SINE_MS)
            self._level.update(zip(ids, levels.tolist()))
        if not tracks or not beams.shape[1]:
            return self._evidence(tracks, ids, time)
        memory = max(1, int(round(cfg.noise_memory_s / max(dt, StftStream.HOP / SAMPLE_RATE))))
        states = []
        for i in ids:
            if i not in self._state:
                self._state[i] = _TrackState(self.vad.new_stream(), NoiseFloor(memory), OverlapAdd(self._decimation))
            states.append(self._state[i])
        power = beams.real**2 + beams.imag**2
        floors = np.stack([st.noise.update(p) for st, p in zip(states, power)])   # (k, bins)
        weights = states[0].noise.gains(power, floors[:, None])
        # share of each beam's power above its noise floor (an SNR: the talker's own beam, whose MPDR
        # cancels the machine, has more of it than the machine's beam she leaks into)
        excess = (power * weights).sum(axis=(1, 2)) / np.maximum(power.sum(axis=(1, 2)), 1e-30)
        clean = OverlapAdd.synthesise_all([st.synthesis for st in states],
                                          beams * np.maximum(weights, cfg.noise_min_gain))
        follow = 1 - math.exp(-dt / cfg.level_tau_s)
        for st, lvl, row in zip(states, level_db(clean, axis=-1).tolist(), clean):
            st.slow_db = lvl if st.slow_db is None else st.slow_db + (lvl - st.slow_db) * follow
            row *= 10 ** (min(cfg.vad_level_db - st.slow_db, cfg.max_gain_db) / 20)
        probs = self.vad.process([st.vad for st in states], list(clean))
        # Speech heard in several beams at once goes to the beam in which the largest share of the power
        # stands above its noise floor: a talker leaks into a machine's beam (Silero hears speech far
        # below the noise), but there the machine dominates.
        n_speech = [int(np.count_nonzero(p >= SPEECH_THRESHOLD)) for p in probs]
        talking = [j for j, n in enumerate(n_speech) if n]
        owner = max(talking, key=lambda j: excess[j], default=None)
        # each frame heard stands for the frames not heard beside it
        scale = self.vad.frame_s / self._heard_share(x.shape[-1])
        step_up, step_down = cfg.rise_per_s * scale, cfg.fall_per_s * scale
        for j, (st, p, t) in enumerate(zip(states, probs, tracks)):
            up = n_speech[j] * step_up if j == owner else 0.0
            # a pausing track's beam is heard (it may own speech) but its silence is no evidence
            down = (len(p) - n_speech[j]) * step_down if t.activity >= cfg.min_activity else 0.0
            st.log_odds = min(max(st.log_odds + up - down, -cfg.max_log_odds), cfg.max_log_odds)
        return self._evidence(tracks, ids, time)

    def _heard_share(self, block: int) -> float:
        """Share of blocks of ``block`` samples that start inside the listening time, over a whole cycle
        (0.5 for 100 ms blocks and the default 0.5 s in 1 s; 1 for blocks as long as the period)."""
        if block not in self._shares:
            starts = np.arange(self._period // math.gcd(block, self._period)) * block
            self._shares[block] = float(np.mean(starts % self._period < self._on))
        return self._shares[block]

    def _evidence(self, tracks: Sequence[Track], ids: list[int], time: float) -> list[TrackEvidence]:
        return [TrackEvidence(i, np.array(t.direction, float), float(time), self.voice_probability(i),
                              self._level.get(i, -math.inf), float(t.activity)) for i, t in zip(ids, tracks)]

    def voice_probability(self, track_id: int) -> float:
        """Accumulated P(voice) of a track (0.5 for a track never heard)."""
        st = self._state.get(track_id)
        return 1.0 / (1.0 + math.exp(-st.log_odds)) if st is not None else 0.5


@dataclass
class _TrackState:
    vad: VadStream
    noise: NoiseFloor
    synthesis: OverlapAdd
    log_odds: float = 0.0
    slow_db: float | None = None   # slow level of the denoised beam, for the VAD's automatic gain
