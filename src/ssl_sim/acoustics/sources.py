"""Sound sources placed in the world: victims (voice/knocks), interferers (generator, pump, talker)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ssl_sim.world import VictimSite

from .signals import SignalStream, generator_noise, pump_noise
from .voices import SPEAKERS, victim_voice

SOURCE_KINDS = ("victim", "interferer", "talker")
#: The paper's test source level (dB SPL at 1 m).
PAPER_LEVEL_DB_SPL = 62.5


@dataclass(frozen=True)
class SoundSource:
    """An omnidirectional point source.

    ``position``: world frame (m). ``level_db_spl``: sound pressure level at 1 m in free field
    while the source sounds (its signal is unit RMS while active). ``buried``: 0 free .. 1 fully
    covered; covering is modelled as a broadband loss of ``15 * buried`` dB and a low-pass whose
    2nd-order cut-off falls from 4 kHz (free) to 400 Hz (fully covered) - an engineering model
    of sound leaking through debris, not derived from first principles.
    """

    position: tuple[float, float, float]
    signal: SignalStream
    level_db_spl: float = PAPER_LEVEL_DB_SPL
    buried: float = 0.0
    kind: str = "victim"
    name: str = ""

    def __post_init__(self) -> None:
        pos = np.asarray(self.position, float)
        if pos.shape != (3,) or not np.all(np.isfinite(pos)):
            raise ValueError(f"SoundSource.position: expected 3 finite world coordinates (m), got {self.position!r}")
        object.__setattr__(self, "position", tuple(float(v) for v in pos))
        if not np.isfinite(self.level_db_spl) or not -20.0 <= self.level_db_spl <= 150.0:
            raise ValueError(f"SoundSource.level_db_spl: expected a level in [-20, 150] dB SPL at 1 m, got {self.level_db_spl}")
        if not 0.0 <= self.buried <= 1.0:
            raise ValueError(f"SoundSource.buried: expected a fraction in [0, 1], got {self.buried}")
        if self.kind not in SOURCE_KINDS:
            raise ValueError(f"SoundSource.kind: expected one of {SOURCE_KINDS}, got {self.kind!r}")
        if not isinstance(self.signal, SignalStream):
            raise ValueError(f"SoundSource.signal: expected a SignalStream, got {type(self.signal).__name__}")

    @property
    def pressure_at_1m(self) -> float:
        """RMS pressure (Pa) at 1 m in free field while active."""
        return 20e-6 * 10 ** (self.level_db_spl / 20)

    def burial_response(self, freqs_hz: np.ndarray) -> np.ndarray | None:
        """Zero-phase magnitude response of the covering (None if not buried)."""
        if self.buried <= 0:
            return None
        fc = 4000.0 * (1 - self.buried) + 400.0 * self.buried
        return 10 ** (-15.0 * self.buried / 20) / np.sqrt(1 + (np.asarray(freqs_hz) / fc) ** 4)


_SPEAKER_CYCLE = ("male", "female", "male_low", "female_high", "child", "elderly_male", "male_high", "female_low")


def victim_source(site: VictimSite, index: int = 0, seed: int = 0, fs: int = 16000, sound: str = "calls",
                  level_db_spl: float = PAPER_LEVEL_DB_SPL, speaker: str | None = None) -> SoundSource:
    """A victim at a World site, with a distinct seeded voice per ``index`` (speakers cycle through sexes/pitches)."""
    spk = speaker or _SPEAKER_CYCLE[index % len(_SPEAKER_CYCLE)]
    if spk not in SPEAKERS:
        raise ValueError(f"speaker: expected one of {sorted(SPEAKERS)}, got {spk!r}")
    voice = victim_voice(sound, spk, seed=seed, fs=fs, stream=1000 + index)
    return SoundSource(site.position, voice, level_db_spl, site.buried, "victim", f"victim{index}:{spk}")


def noise_source(position, kind: str = "generator", level_db_spl: float = 75.0, seed: int = 0, fs: int = 16000) -> SoundSource:
    """A machine interferer at ``position``: ``generator`` (engine harmonics) or ``pump`` (motor hum + flow)."""
    if kind == "generator":
        sig = generator_noise(fs, seed)
    elif kind == "pump":
        sig = pump_noise(fs, seed)
    else:
        raise ValueError(f"noise source kind: expected 'generator' or 'pump', got {kind!r}")
    return SoundSource(tuple(position), sig, level_db_spl, 0.0, "interferer", kind)
