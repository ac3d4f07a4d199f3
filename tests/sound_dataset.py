"""The real-sound data set (ssl_sim/sounds, see its PROVENANCE) cut into labelled 1 s chunks.

Truth is independent of any detector: the chunk's file category (speech/shouts vs the
non-speech categories) plus an energy test for the speech files, so that a 1 s chunk that is
mostly the silence between two prompts is not asked to count as speech.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.io import wavfile

from ssl_sim.acoustics.sound_set import SPEECH_CATEGORIES, sound_files
from ssl_sim.resources import SOUNDS_DIR as DATA

FS = 16000
CHUNK_S, HOP_S = 1.0, 0.5
_FRAME = 512          # 32 ms energy frames for the truth labels
_ACTIVE_DB = 30.0     # a frame is "sounding" within 30 dB of the file's loudest frame
_SPEECH_ACTIVE = 0.5  # a speech chunk needs >= 50 % sounding frames (else it is a pause: unlabelled)


@dataclass(frozen=True)
class Recording:
    split: str
    category: str
    name: str
    samples: np.ndarray   # float, full scale 1, 16 kHz mono
    sex: str

    @property
    def is_speech(self) -> bool:
        return self.category in SPEECH_CATEGORIES


def recordings(split: str) -> list[Recording]:
    """All recordings of ``split`` ('dev' or 'test') listed in PROVENANCE (ssl_sim.acoustics.sound_set)."""
    out = []
    for r in sound_files(split):
        fs, x = wavfile.read(r.path)
        if fs != FS or x.ndim != 1:
            raise ValueError(f"{r.path}: expected 16 kHz mono, got {fs} Hz shape {x.shape}")
        out.append(Recording(split, r.category, r.name, x.astype(np.float64) / 32768.0, r.speaker_sex))
    return out


def chunk_starts(rec: Recording) -> list[int]:
    """Start samples of the labelled 1 s chunks (hop 0.5 s): sounding chunks; for speech, talking ones."""
    x = rec.samples
    n_fr = len(x) // _FRAME
    e = 10 * np.log10((x[: n_fr * _FRAME].reshape(n_fr, _FRAME) ** 2).mean(1) + 1e-12)
    sounding = e >= e.max() - _ACTIVE_DB
    per_chunk = int(CHUNK_S * FS) // _FRAME
    starts = []
    for s in range(0, len(x) - int(CHUNK_S * FS) + 1, int(HOP_S * FS)):
        f0 = s // _FRAME
        frac = sounding[f0: f0 + per_chunk].mean()
        if (frac >= _SPEECH_ACTIVE) if rec.is_speech else (frac > 0):
            starts.append(s)
    return starts


# The five room configurations tried while developing the hearing (all kept): talker, machine (test
# part), their azimuths (deg, array frame); both 2 m from the array centre, at its height.
ROOM_CASES = [("it_carlo", "ore_mine", 30, -50), ("fr_june", "industry_light", 120, 40),
              ("en_librivox", "jackhammer", -100, 0), ("it_carlo", "mill", 170, 90), ("fr_june", "ore_mine", 0, -70)]
# Tuning rooms for the localizer's search beside a machine (never scored in tests): the dev part's talkers
# and machines (with a hammer and an engine: bursty and changing like the jackhammer and the mill), other
# azimuths (65-160 deg apart), the robot elsewhere in the room and another simulation seed;
# room_case(*case, split="dev", robot_xy=DEV_ROBOT_XY, seed=DEV_SEED) (benchmarks/bench_talker_rooms.py).
DEV_ROOM_CASES = [("en_allison", "mining_machinery", 75, -10), ("ru_ivrvoice", "sawmill", -140, 140),
                  ("en_an4", "industry_high", 10, 110), ("en_allison", "power_coal", -30, -120),
                  ("ru_ivrvoice", "industry_high", 160, 60), ("en_an4", "mining_machinery", -80, 80),
                  ("ru_ivrvoice", "blacksmith", 100, 20), ("en_allison", "truck_start", -170, -60)]
DEV_ROBOT_XY, DEV_SEED = (3.2, 2.7), 7


def room_case(talker: str, machine: str, az_t: float, az_m: float, seconds: int = 16, sir_db: float = -6.0,
              rt60_s: float = 0.6, with_talker: bool = True, with_machine: bool = True, split: str = "test",
              robot_xy: tuple[float, float] = (3.5, 3.0), seed: int = 1):
    """The cube array in a 7 x 6 x 3.2 m room of ``rt60_s`` (ssl_sim), a talker (``split`` part, looped) and a
    machine recording ``-sir_db`` dB louder (talker level = RMS while talking, machine = RMS), 2 m away;
    ``with_talker=False``: the machine alone (her direction and talking seconds still returned),
    ``with_machine=False``: the talker alone;
    ``split``: the data set part the recordings come from; ``robot_xy`` (m, room frame) and ``seed``
    (the simulation's) make other rooms of the same kind.
    Returns (int16 (8, n) audio, the two true unit directions (array frame), per 1 s: does she talk?)."""
    from ssl_sim.acoustics import AcousticConfig, AcousticSimulator, RobotPose
    from ssl_sim.acoustics.pose import ArrayMount
    from ssl_sim.acoustics.signals import LoopedSignal
    from ssl_sim.acoustics.sources import SoundSource
    from ssl_sim.world import Room, World

    rec = {r.name: r for r in recordings(split)}
    pose, mount = RobotPose(*robot_xy, yaw=0.0), ArrayMount()
    c = mount.centre_world(pose)
    dirs = [np.array([np.cos(np.deg2rad(a)), np.sin(np.deg2rad(a)), 0.0]) for a in (az_t, az_m)]
    speech = rec[talker].samples
    fr = speech[: len(speech) // _FRAME * _FRAME].reshape(-1, _FRAME)
    e = 10 * np.log10((fr**2).mean(1) + 1e-12)
    talking = e >= e.max() - _ACTIVE_DB
    active_rms = np.sqrt((fr[talking] ** 2).mean())
    srcs = [SoundSource(tuple(c + 2.0 * dirs[0]), LoopedSignal(speech / active_rms, FS, normalise=False), 62.0),
            SoundSource(tuple(c + 2.0 * dirs[1]), LoopedSignal(rec[machine].samples, FS), 62.0 - sir_db)]
    srcs = [s for s, on in zip(srcs, (with_talker, with_machine)) if on]
    sim = AcousticSimulator(World(room=Room((7.0, 6.0, 3.2))), AcousticConfig(rt60_s=rt60_s, seed=seed), srcs)
    x = sim.listen_pose(pose, float(seconds), mount=mount)
    per_s = FS // _FRAME
    she_talks = [bool(talking[np.arange(w * per_s, (w + 1) * per_s) % len(talking)].mean() >= 0.5) for w in range(seconds)]
    return x, dirs, she_talks
