"""GCC-PHAT: generalised cross-correlation with phase transform (paper eq. 6).

For microphones i and j with spectra X_i, X_j the PHAT-weighted cross spectrum
is ``X_i conj(X_j) / |X_i conj(X_j)|``; its inverse transform peaks at the lag
``tau_ij = t_i - t_j`` (s), the arrival time at mic i minus that at mic j.
"""
from __future__ import annotations

import numpy as np
import scipy.fft
from numpy.lib.stride_tricks import sliding_window_view

def band_bins(fs: float, nfft: int, band_hz: tuple[float, float] | None) -> np.ndarray:
    """Indices of the rfft bins inside ``band_hz`` (Hz, inclusive); all bins but DC when None."""
    freqs = np.fft.rfftfreq(nfft, 1.0 / fs)
    if band_hz is None:
        return np.arange(1, len(freqs))
    lo, hi = band_hz
    if not 0 <= lo < hi <= fs / 2:
        raise ValueError(f"band_hz must satisfy 0 <= low < high <= fs/2 = {fs / 2:g} Hz, got {band_hz}")
    idx = np.flatnonzero((freqs >= lo) & (freqs <= hi) & (freqs > 0))
    if idx.size < 2:
        raise ValueError(f"band_hz {band_hz} holds fewer than 2 frequency bins at fs={fs:g} Hz, nfft={nfft}")
    return idx


def frame_spectra(x: np.ndarray, frame_size: int, hop: int, window: np.ndarray) -> np.ndarray:
    """Windowed rfft of every complete frame of ``x`` (channels, samples) -> (channels, frames, bins)."""
    if x.shape[-1] < frame_size:
        return np.zeros((x.shape[0], 0, frame_size // 2 + 1), dtype=complex)
    frames = sliding_window_view(x, frame_size, axis=-1)[:, ::hop]
    return scipy.fft.rfft(frames * window, axis=-1)


def phat_cross_spectra(spectra: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """PHAT-weighted cross spectra ``(pairs, ..., bins)`` from channel spectra ``(channels, ..., bins)``."""
    cross = spectra[pairs[:, 0]] * np.conj(spectra[pairs[:, 1]])
    mag = np.abs(cross)
    return cross / np.maximum(mag, np.finfo(mag.dtype).tiny)


def phat_normalise(spectra: np.ndarray) -> np.ndarray:
    """Unit-magnitude spectra ``X / |X|`` (zero bins stay zero)."""
    mag = np.abs(spectra)
    return spectra / np.maximum(mag, np.finfo(mag.dtype).tiny)


def summed_phat_cross_spectra(spectra: np.ndarray, pairs: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """PHAT cross spectra of every pair summed over frames: ``(channels, frames, bins) -> (pairs, bins)``,
    each time-frequency bin optionally weighted by ``weights`` (frames, bins).

    Since ``X_i X_j* / |X_i X_j*| = (X_i/|X_i|)(X_j/|X_j|)*``, normalising the channels first
    and summing over frames as one batched matrix product per bin costs far less than
    forming every pair's per-frame cross spectrum.
    """
    y = phat_normalise(spectra)
    if weights is not None:
        y = y * np.sqrt(weights).astype(y.real.dtype)  # each pair product then carries the weight once
    y = y.transpose(2, 0, 1)  # (bins, channels, frames)
    cov = y @ np.conj(y.transpose(0, 2, 1))  # (bins, channels, channels)
    return cov[:, pairs[:, 0], pairs[:, 1]].T


class LagSteering:
    """GCC at a fixed set of lags straight from band cross spectra, as one real matrix product.

    ``gcc[p, l] = mean_f Re(C[p, f] exp(j w_f tau_l))``: the inverse transform evaluated only at
    the few lags an array of this size can produce (exact, no interpolation, any lag spacing).
    A single perfectly coherent path gives 1 at its lag.
    """

    def __init__(self, omega: np.ndarray, lags: np.ndarray, dtype=np.float32):
        phase = np.outer(omega, lags)  # (bins, lags)
        self.matrix = (np.vstack([np.cos(phase), -np.sin(phase)]) / len(omega)).astype(dtype)

    def __call__(self, cross: np.ndarray) -> np.ndarray:
        """``cross`` (pairs, bins) complex -> (pairs, lags) real."""
        stacked = np.concatenate([cross.real, cross.imag], axis=-1).astype(self.matrix.dtype, copy=False)
        return stacked @ self.matrix


def gcc_phat(
    x1: np.ndarray,
    x2: np.ndarray,
    fs: float,
    max_tau: float | None = None,
    band_hz: tuple[float, float] | None = None,
    upsample: int = 16,
    lag_range: tuple[float, float] | None = None,
) -> tuple[float, np.ndarray, np.ndarray]:
    """Whole-signal GCC-PHAT of two 1-D signals (any lengths).

    Returns ``(tau, lags, cc)``: the delay estimate ``tau = t_1 - t_2`` (s; positive
    when ``x1`` lags ``x2``), the lag axis (s, steps of ``1 / (fs * upsample)``) and the
    correlation, normalised so a perfectly coherent delayed copy peaks at 1. The search
    covers ``lag_range = (lo, hi)`` seconds, or ``+-max_tau``, or every lag.
    """
    x1, x2 = np.asarray(x1, float), np.asarray(x2, float)
    if x1.ndim != 1 or x2.ndim != 1:
        raise ValueError("gcc_phat expects two 1-D signals")
    nfft = int(scipy.fft.next_fast_len(x1.size + x2.size, real=True))
    n_up = nfft * upsample
    if lag_range is None:
        half = (n_up // 2 - 1) if max_tau is None else min(n_up // 2 - 1, int(np.ceil(max_tau * fs * upsample)))
        lo, hi = -half, half
    else:
        lo, hi = int(np.floor(lag_range[0] * fs * upsample)), int(np.ceil(lag_range[1] * fs * upsample))
        if not lo <= hi or hi - lo >= n_up:
            raise ValueError(f"lag_range {lag_range} s must be ordered and shorter than the signals ({nfft / fs:g} s)")
    bins = band_bins(fs, nfft, band_hz)
    cross = phat_cross_spectra(np.stack([scipy.fft.rfft(x1, nfft), scipy.fft.rfft(x2, nfft)]), np.array([[0, 1]]))[0]
    full = np.zeros(n_up // 2 + 1, dtype=complex)
    full[bins] = cross[bins]
    cc = scipy.fft.irfft(full, n=n_up)[np.arange(lo, hi + 1) % n_up] * (n_up / (2.0 * len(bins)))
    lags = np.arange(lo, hi + 1) / (fs * upsample)
    return float(lags[np.argmax(cc)]), lags, cc
