"""The old hand-made voice-likeness score (band ratio + pitch periodicity), kept as the baseline
that ``benchmarks/bench_voice.py`` measures the VAD (``robot.vad``) against: on real recordings it
calls 61 % of non-speech 1 s chunks voice, so the behaviour no longer uses it.

The score is a heuristic prior for choosing which source to approach, not a
speech detector: it rewards energy in the telephone voice band and a periodic
waveform with a period in the human pitch range (70-400 Hz) after low-passing
at 1 kHz. Broadband noise (rubble, wind, motors) scores low; a tonal alarm in
the pitch range or a hum with strong 300-3400 Hz harmonics can score high.
With the 15 cm cube the beam is broad below ~1 kHz, so a strong second source
leaks into the beam; the score describes the beam's mixture.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft
from numpy.lib.stride_tricks import sliding_window_view
from scipy import signal

from robot.hal import as_float_audio

@dataclass(frozen=True)
class VoiceScore:
    """``band_ratio``: 300-3400 Hz energy over 100 Hz-min(8 kHz, fs/2) energy; ``periodicity``:
    normalised autocorrelation peak at pitch lags (0..1) of the 80-1000 Hz band; ``score``:
    combined, 0 (noise) .. 1 (voice)."""

    band_ratio: float
    periodicity: float
    score: float


def voice_likeness(x: np.ndarray, fs: float, frame_s: float = 0.04) -> VoiceScore:
    """Score a mono signal (float or int16) for being a human voice; see the module docstring."""
    x = as_float_audio(np.asarray(x)).ravel()
    if x.size < int(2 * frame_s * fs) or not np.any(x):
        return VoiceScore(0.0, 0.0, 0.0)
    x = x - x.mean()
    f, pxx = signal.welch(x, fs, nperseg=min(1024, x.size))
    total = pxx[(f >= 100) & (f <= min(8000.0, fs / 2))].sum()
    band = pxx[(f >= 300) & (f <= 3400)].sum()
    band_ratio = float(band / total) if total > 0 else 0.0
    low_fraction = float(pxx[(f >= 80) & (f <= 1000)].sum() / total) if total > 0 else 0.0

    # Pitch periodicity: per frame, the normalised (bias-corrected) autocorrelation peak at lags of
    # 2.5-14 ms, on the signal band-passed to 80-1000 Hz (fundamental and first formant) so that tones
    # and hiss above do not count; it only counts as much as that band carries energy.
    low = signal.sosfiltfilt(signal.butter(4, (80.0, min(1000.0, 0.45 * fs)), "bandpass", fs=fs, output="sos"), x)
    n = int(frame_s * fs)
    frames = sliding_window_view(low, n)[:: n // 2]
    frames = frames - frames.mean(axis=1, keepdims=True)
    energy = np.einsum("ij,ij->i", frames, frames)
    active = energy >= 0.25 * energy.max()
    nfft = scipy.fft.next_fast_len(2 * n, real=True)
    ac = scipy.fft.irfft(np.abs(scipy.fft.rfft(frames[active] * np.hanning(n), nfft, axis=-1)) ** 2, nfft)[:, :n]
    lo, hi = int(fs / 400.0), min(int(fs / 70.0), n // 2)
    win_ac = np.correlate(np.hanning(n), np.hanning(n), "full")[n - 1:]  # bias of the tapered frame
    norm = ac[:, lo:hi] / np.maximum(ac[:, :1], 1e-30) / (win_ac[lo:hi] / win_ac[0])
    peaks = np.sort(norm.max(axis=1))[::-1]
    periodicity = float(np.clip(np.mean(peaks[: max(1, len(peaks) // 2)]), 0.0, 1.0))

    # Both cues are needed (geometric mean): voice band energy, and pitch periodicity in a band that
    # holds at least ~15 % of the energy (voiced speech: fundamental + F1).
    b = np.clip((band_ratio - 0.45) / 0.35, 0, 1)
    p = np.clip((periodicity - 0.3) / 0.4, 0, 1) * np.clip(low_fraction / 0.15, 0, 1)
    score = np.sqrt(b * p)
    return VoiceScore(band_ratio, periodicity, float(score))
