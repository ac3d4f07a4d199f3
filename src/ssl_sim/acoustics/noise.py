"""Ambient background noise as a diffuse sound field at the microphones.

Independent noise per microphone is mixed, frequency by frequency, so that the
inter-microphone coherence is the diffuse-field ``sinc(k d)`` (strongly coherent at low frequencies across a 15 cm cube,
incoherent at high frequencies), which is what makes background noise hard for GCC-PHAT.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft

from .rir import diffuse_mixing
from .signals import TimeKeyedNoise, _spectrum_fir

P_REF = 20e-6  # Pa


@dataclass(frozen=True)
class AmbientNoise:
    """Diffuse background noise: broadband (unweighted) sound pressure level ``level_db_spl`` at
    the microphones, spectrum ``white|pink|brown|hvac|speech``."""

    level_db_spl: float = 30.0
    spectrum: str = "hvac"

    def __post_init__(self) -> None:
        if not np.isfinite(self.level_db_spl) or not -40.0 <= self.level_db_spl <= 140.0:
            raise ValueError(f"AmbientNoise.level_db_spl: expected a level in [-40, 140] dB SPL, got {self.level_db_spl}")
        try:
            _spectrum_fir(self.spectrum, 16000, n_taps=33)
        except ValueError as exc:
            raise ValueError(f"AmbientNoise.{exc}") from None


class DiffuseNoiseField:
    """Renders :class:`AmbientNoise` as pressure (Pa) at microphones for absolute sample ranges:
    time-keyed independent white noise per microphone, mixed per frequency to diffuse-field
    coherence (:func:`~.rir.diffuse_mixing`) and shaped to the spectrum."""

    _PAD = 128  # samples of margin: the coherence-mixing filters are short (array aperture / c + sinc tails)

    def __init__(self, ambient: AmbientNoise, fs: int, seed: int, c: float = 343.0) -> None:
        self.ambient, self.fs, self.c = ambient, int(fs), float(c)
        self.seed = int(seed)
        h = _spectrum_fir(ambient.spectrum, self.fs)
        self.h = h / np.sqrt(np.sum(h**2))
        self.p_rms = P_REF * 10 ** (ambient.level_db_spl / 20)
        self._noise: dict[int, TimeKeyedNoise] = {}
        self._mix: tuple[int, np.ndarray, np.ndarray] | None = None

    def render(self, mics: np.ndarray, n0: int, n: int) -> np.ndarray:
        """Pressure (n_mics, n) Pa at microphones ``mics`` (n_mics, 3) world m, samples ``n0 ..``."""
        mics = np.asarray(mics, float)
        n_mics = mics.shape[0]
        noise = self._noise.get(n_mics)
        if noise is None:
            noise = self._noise[n_mics] = TimeKeyedNoise(self.seed, stream=0xD1FF, channels=n_mics)
        k = self.h.size - 1
        pad = self._PAD
        length = n + 2 * pad + k
        w = noise.samples(n0 - pad - k, length)  # (M, length)
        n_fft = sfft.next_fast_len(length)
        freqs = np.fft.rfftfreq(n_fft, 1.0 / self.fs)
        d = np.linalg.norm(mics[:, None] - mics[None], axis=-1)
        mix = None
        if self._mix is not None:  # rigid array: same mixing at every pose (distances within 2 mm)
            nf, dk, m = self._mix
            if nf == n_fft and dk.shape == d.shape and np.allclose(dk, d, atol=2e-3):
                mix = m
        if mix is None:
            mix = diffuse_mixing(freqs, mics, self.c) * sfft.rfft(self.h, n_fft)[:, None, None]
            self._mix = (n_fft, d, mix)
        spec = np.einsum("fij,jf->if", mix, sfft.rfft(w, n_fft, axis=1))
        y = sfft.irfft(spec, n_fft, axis=1)
        return self.p_rms * y[:, pad + k: pad + k + n]
