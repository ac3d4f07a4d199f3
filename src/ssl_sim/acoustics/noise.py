"""Ambient background noise as a diffuse sound field at the microphones.

Independent noise per microphone is mixed, frequency by frequency, so that the
inter-microphone coherence is the diffuse-field ``sinc(k d)`` (strongly coherent at low frequencies across a 15 cm cube,
incoherent at high frequencies), which is what makes background noise hard for GCC-PHAT.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from scipy import fft as sfft

from .rir import array_distances, diffuse_mixing
from .signals import TimeKeyedNoise, _piece_together, _spectrum_fir

P_REF = 20e-6  # Pa


@dataclass(frozen=True)
class AmbientNoise:
    """Diffuse background noise: broadband (unweighted) sound pressure level ``level_db_spl`` at
    the microphones, spectrum ``white|pink|brown|hvac|speech``."""

    level_db_spl: float = 30.0  # broadband (unweighted) level at the microphones (dB SPL)
    spectrum: str = "hvac"  # white, pink, brown, hvac or speech-shaped

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
    coherence (:func:`~.rir.diffuse_mixing`) and shaped to the spectrum.

    The field is computed in fixed frames aligned to absolute sample indices (overlap-save
    with margins), so any block is identical however the timeline is cut. The mixing depends
    only on inter-microphone distances, so a rigid array hears the same realisation at every
    pose (the field is statistically isotropic and homogeneous).

    ``loop_frames``: if set, the field repeats every ``loop_frames * FRAME`` samples (frame ``k`` is frame
    ``k mod loop_frames``; a discontinuity at each wrap): the frames are then computed once and cached -
    a cheaper field for the environment's fast fidelity, statistically the same."""

    FRAME = 8192
    CACHE = 32  # frames kept
    _PAD = 512  # margin for the (non-causal, decaying) coherence-mixing filters

    def __init__(self, ambient: AmbientNoise, fs: int, seed: int, c: float = 343.0,
                 loop_frames: int | None = None) -> None:
        if loop_frames is not None and not 1 <= loop_frames <= self.CACHE:
            raise ValueError(f"loop_frames: expected None or 1..{self.CACHE}, got {loop_frames}")
        self.ambient, self.fs, self.c = ambient, int(fs), float(c)
        self.loop_frames = loop_frames
        self.seed = int(seed)
        h = _spectrum_fir(ambient.spectrum, self.fs)
        self.h = h / np.sqrt(np.sum(h**2))
        self.p_rms = P_REF * 10 ** (ambient.level_db_spl / 20)
        self._noise: dict[int, TimeKeyedNoise] = {}
        self._geometry: np.ndarray | None = None  # inter-mic distances the cached frames belong to
        self._mix: np.ndarray | None = None
        self._frames: OrderedDict[int, np.ndarray] = OrderedDict()

    def _frame(self, k: int, mics: np.ndarray) -> np.ndarray:
        if self.loop_frames is not None:
            k = k % self.loop_frames
        fr = self._frames.get(k)
        if fr is not None:
            self._frames.move_to_end(k)
            return fr
        n_mics = mics.shape[0]
        noise = self._noise.get(n_mics)
        if noise is None:
            noise = self._noise[n_mics] = TimeKeyedNoise(self.seed, stream=0xD1FF, channels=n_mics)
        taps, pad, F = self.h.size - 1, self._PAD, self.FRAME
        length = F + 2 * pad + taps
        n_fft = sfft.next_fast_len(length)
        if self._mix is None or self._mix.shape[0] != n_fft // 2 + 1:
            freqs = np.fft.rfftfreq(n_fft, 1.0 / self.fs)
            self._mix = diffuse_mixing(freqs, mics, self.c) * sfft.rfft(self.h, n_fft)[:, None, None]
        w = noise.samples(k * F - pad - taps, length)
        y = sfft.irfft(np.einsum("fij,jf->if", self._mix, sfft.rfft(w, n_fft, axis=1)), n_fft, axis=1)
        fr = self.p_rms * y[:, pad + taps: pad + taps + F]
        self._frames[k] = fr
        if len(self._frames) > self.CACHE:
            self._frames.popitem(last=False)
        return fr

    def render(self, mics: np.ndarray, n0: int, n: int) -> np.ndarray:
        """Pressure (n_mics, n) Pa at microphones ``mics`` (n_mics, 3) world m, samples ``n0 ..``."""
        mics = np.asarray(mics, float)
        d = array_distances(mics)  # exact key: the frames depend on this array only, not on earlier ones
        if self._geometry is None or self._geometry.shape != d.shape or not np.array_equal(self._geometry, d):
            self._geometry, self._mix = d, None
            self._frames.clear()
        if n <= 0:
            return np.zeros((mics.shape[0], 0))
        F = self.FRAME
        k0, k1 = n0 // F, (n0 + n - 1) // F
        return _piece_together(lambda k: self._frame(k, mics), k0, k1, n0 - k0 * F, n, F, mics.shape[0])
