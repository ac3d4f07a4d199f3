"""Victim voices for environment episodes: pre-rendered loops, shared by all episodes of a process.

Synthesising a call costs ~15 ms (``ssl_sim.acoustics.voices``), more than a whole fast
environment step, and an episode hears a new one every ~1 s. So each (sound, speaker) pair is
rendered once per process as ``LOOP_PERIODS`` periods of its event stream and looped; an
episode picks a speaker per victim and a random start offset into the loop (from the
environment's seeded RNG), so voices still differ between episodes and victims. A loop is a
whole number of event periods, and events never cross a period boundary, so the loop point is
seamless.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from ssl_sim.acoustics.signals import SignalStream
from ssl_sim.acoustics.sources import SoundSource
from ssl_sim.acoustics.voices import victim_voice
from ssl_sim.world import World

#: Speakers drawn for victims (``ssl_sim.acoustics.SPEAKERS`` keys).
SPEAKERS = ("male", "female", "male_low", "female_high", "child", "elderly_male", "male_high", "female_low")
LOOP_PERIODS = 10
#: (period s, event probability) per sound; "continuous" is near-continuous calling.
_STREAM = {"continuous": (1.2, 1.0), "calls": (2.5, 0.9), "moans": (2.5, 0.9), "shouts": (2.5, 0.9),
           "knocks": (2.5, 0.9), "mixed": (2.5, 0.9)}


@lru_cache(maxsize=64)
def voice_loop(sound: str, speaker: str, fs: int = 16000) -> np.ndarray:
    """``LOOP_PERIODS`` periods of a victim's sound (unit RMS while active), float64 (read-only)."""
    if sound not in _STREAM:
        raise ValueError(f"sound: expected one of {sorted(_STREAM)}, got {sound!r}")
    period, p_event = _STREAM[sound]
    kind = "calls" if sound == "continuous" else sound
    stream = victim_voice(kind, speaker, seed=SPEAKERS.index(speaker), fs=fs, period_s=period, p_event=p_event)
    x = stream.render(0, LOOP_PERIODS * stream.period)
    x.setflags(write=False)
    return x


class LoopOffsetSignal(SignalStream):
    """A looped recording started ``offset`` samples in: sample ``n`` is ``loop[(n + offset) % len]``."""

    def __init__(self, loop: np.ndarray, fs: int, offset: int) -> None:
        self.x, self.fs, self.offset = loop, int(fs), int(offset)

    def render(self, n0: int, n: int) -> np.ndarray:
        return self.x[(int(n0) + self.offset + np.arange(int(n))) % self.x.size]


def episode_victims(world: World, rng: np.random.Generator, sound: str, level_db_spl: float,
                    fs: int = 16000) -> list[SoundSource]:
    """One source per victim site of ``world``: a speaker and loop offset drawn from ``rng``."""
    speakers = rng.permutation(len(SPEAKERS))
    out = []
    for i, site in enumerate(world.victims):
        spk = SPEAKERS[int(speakers[i % len(SPEAKERS)])]
        loop = voice_loop(sound, spk, fs)
        sig = LoopOffsetSignal(loop, fs, int(rng.integers(loop.size)))
        out.append(SoundSource(site.position, sig, level_db_spl, site.buried, "victim", f"victim{i}:{spk}"))
    return out
