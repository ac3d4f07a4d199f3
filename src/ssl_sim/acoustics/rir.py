"""Room impulse responses from image sources, plus a statistical diffuse late tail.

Convention (pyroomacoustics'): a source whose free-field pressure at 1 m is ``s(t)`` gives
``s(t - r/c) / r`` at distance ``r``; an image adds the product of its walls' pressure
reflection factors ``sqrt(1 - alpha)`` per octave band. RIR arrays start ``n_pre`` samples
*before* the emission instant (room for the non-causal half of the fractional-delay
filters and of the zero-phase octave-band weighting).

Early part: exact image sources (pyroomacoustics engine, order N) with windowed-sinc
fractional delays, per octave band, combined with complementary log-frequency band
weights. Late part: the image-source model of order N misses everything after the
first order-(N+1) reflections, so the deficit is filled with a diffuse tail whose
expected energy follows image-source statistics in a room of volume ``V`` with Eyring
decay per band,

    E[h^2(t)] = 4 pi c / (V fs) * exp(-13.8 t / T60_b)     (per sample, 1/r amplitude convention)

(image density ``4 pi (ct)^2 d(ct) / V`` times amplitude ``1/(ct)`` squared). It is built
from decaying noise mixed per frequency to the spatial coherence of a diffuse field across
the array (what GCC-PHAT actually sees), not independent noise per microphone. The tail is faded in
where the early part's smoothed energy falls below the diffuse expectation.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy import fft as sfft

from .materials import OCTAVE_CENTERS_HZ

FRAC_HALF_TAPS = 32  # windowed-sinc half length (samples)


def band_weights(freqs_hz: np.ndarray, centers=OCTAVE_CENTERS_HZ) -> np.ndarray:
    """Complementary octave-band amplitude weights (n_bands, n_freqs): cos^2/sin^2 cross-fades in
    log2-frequency between adjacent centres, summing to 1 at every frequency."""
    f = np.asarray(freqs_hz, float)
    lc = np.log2(np.asarray(centers, float))
    lf = np.log2(np.maximum(f, 1e-3))
    w = np.zeros((len(centers), f.size))
    pos = np.clip(np.interp(lf, lc, np.arange(len(centers))), 0, len(centers) - 1)
    lo = np.floor(pos).astype(int)
    frac = pos - lo
    hi = np.minimum(lo + 1, len(centers) - 1)
    cols = np.arange(f.size)
    w[lo, cols] += np.cos(0.5 * np.pi * frac) ** 2
    w[hi, cols] += np.sin(0.5 * np.pi * frac) ** 2
    return w


@lru_cache(maxsize=32)
def _band_weights_fft(n_fft: int, fs: int) -> np.ndarray:
    """:func:`band_weights` on the rfft bins of ``n_fft`` at ``fs`` (cached: few sizes recur)."""
    return band_weights(np.fft.rfftfreq(n_fft, 1.0 / fs))


def _frac_kernel(delay: np.ndarray, half: int = FRAC_HALF_TAPS) -> tuple[np.ndarray, np.ndarray]:
    """Hann-windowed sinc taps for fractional delays: integer positions (..., 2*half) and weights."""
    fl = np.floor(delay)
    base = fl.astype(np.int64)
    offs, sign, cos_a, sin_a = _frac_taps(half)
    pos = base[..., None] + offs
    # x = offs - frac with frac in [0, 1), so |x| <= half. One sine and one cosine pair per delay instead of
    # per tap: sin(pi (o - f)) = (-1)^(o+1) sin(pi f), cos(pi (o - f) / half) by the angle-difference formula.
    frac = (delay - fl)[..., None]
    x = offs - frac
    zero = x == 0
    # sin(pi f) from the nearer integer: accurate when f is within rounding of 1 as well as of 0 (x = 0: the
    # tap is 1, the division by 1 instead of 0 is discarded).
    sinc = np.where(zero, 1.0, sign * np.sin(np.pi * np.minimum(frac, 1.0 - frac)) / (np.pi * np.where(zero, 1.0, x)))
    b = np.pi * frac / half
    hann = 0.5 + 0.5 * (cos_a * np.cos(b) + sin_a * np.sin(b))
    return pos, sinc * hann


@lru_cache(maxsize=4)
def _frac_taps(half: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Tap offsets ``-half+1 .. half``, the sinc's sign per tap, and cos / sin of the window's tap angle."""
    offs = np.arange(-half + 1, half + 1)
    a = np.pi * offs / half
    out = (offs, np.where(offs % 2, 1.0, -1.0), np.cos(a), np.sin(a))
    for v in out:
        v.flags.writeable = False
    return out


def early_rir(image_positions: np.ndarray, reflection: np.ndarray, mics: np.ndarray, fs: int, c: float,
              n_pre: int, length: int) -> np.ndarray:
    """Early RIR (n_mics, length) from image sources (n, 3) with band reflection factors (n, n_bands)."""
    n_mics = mics.shape[0]
    out_len = int(length)
    if image_positions.shape[0] == 0:
        return np.zeros((n_mics, out_len))
    dist = np.linalg.norm(image_positions[:, None, :] - mics[None, :, :], axis=-1)  # (n, M)
    delay = dist / c * fs + n_pre
    pos, ker = _frac_kernel(delay)  # (n, M, T)
    valid = (pos >= 0) & (pos < out_len)
    ker = np.where(valid, ker / dist[..., None], 0.0)
    pos = np.where(valid, pos, 0)
    flat_idx = (np.arange(n_mics)[None, :, None] * out_len + pos).ravel()
    refl = np.asarray(reflection, float)
    first = refl[:, :1]
    # np.allclose's test (rtol 1e-5, atol 1e-8) written out for finite factors: a tenth of its cost
    flat_bands = bool(np.all(np.abs(refl - first) <= 1e-8 + 1e-5 * np.abs(first))) if np.all(np.isfinite(refl)) \
        else np.allclose(refl, first)
    if flat_bands:
        wts = (ker * refl[:, :1, None]).ravel()
        return np.bincount(flat_idx, wts, minlength=n_mics * out_len).reshape(n_mics, out_len)
    n_fft = sfft.next_fast_len(out_len + 2 * n_pre)
    bw = _band_weights_fft(n_fft, fs)
    spec = np.zeros((n_mics, n_fft // 2 + 1), complex)
    for b in range(refl.shape[1]):
        wts = (ker * refl[:, b, None, None]).ravel()
        train = np.bincount(flat_idx, wts, minlength=n_mics * out_len).reshape(n_mics, out_len)
        band = sfft.rfft(train, n_fft, axis=1)
        spec += np.multiply(band, bw[b], out=band)
    return sfft.irfft(spec, n_fft, axis=1)[:, :out_len]


#: Inter-microphone distances are rounded to this (m) before they shape anything: poses of one rigid array
#: (distances equal to ~1e-15 m) share one geometry key, and a result depends only on the current array,
#: never on which array was seen first (an earlier 2 mm tolerance reused whatever geometry came first).
#: The value is part of the simulated world: the rounded distances seed the diffuse tail's realisation, so
#: another quantum (1 mm, say) re-draws every run's tail and with it the runs' outcomes.
GEOMETRY_QUANTUM_M = 1e-6


def array_distances(mics: np.ndarray) -> np.ndarray:
    """Inter-microphone distances (M, M) in m, rounded to :data:`GEOMETRY_QUANTUM_M` (a geometry key)."""
    mics = np.asarray(mics, float)
    d = np.linalg.norm(mics[:, None, :] - mics[None, :, :], axis=-1)
    return np.round(d / GEOMETRY_QUANTUM_M) * GEOMETRY_QUANTUM_M


def diffuse_mixing(freqs_hz: np.ndarray, mics: np.ndarray, c: float = 343.0) -> np.ndarray:
    """Mixing matrices ``C(f) = Gamma(f)^(1/2)`` (F, M, M) of the spherically isotropic (diffuse)
    coherence ``Gamma_ij = sin(k d_ij) / (k d_ij)``: ``C(f) z(f)`` turns independent unit-variance
    spectra ``z`` into spectra with diffuse-field coherence (Habets & Gannot 2007). The symmetric
    square root varies smoothly with frequency, so the mixing filters are short (~ aperture / c).
    Depends only on inter-microphone distances (:func:`array_distances`): the same for every pose of a
    rigid array. Cached on the exact (rounded) geometry and frequencies."""
    freqs = np.asarray(freqs_hz, float)
    d = array_distances(mics)
    key = (freqs.size, float(freqs[-1]) if freqs.size else 0.0, freqs.tobytes(), d.tobytes(), float(c))
    mix = _MIXING_CACHE.get(key)
    if mix is None:
        gamma = np.sinc(2.0 * freqs[:, None, None] * d[None] / c)
        w, v = np.linalg.eigh(gamma)
        mix = (v * np.sqrt(np.clip(w, 0.0, None))[:, None, :]) @ np.swapaxes(v, 1, 2)
        _MIXING_CACHE[key] = mix
        while len(_MIXING_CACHE) > 4:
            _MIXING_CACHE.pop(next(iter(_MIXING_CACHE)))
    return mix


# (frequencies, rounded distances, c) -> mixing: the array geometry and block sizes rarely change.
_MIXING_CACHE: dict[tuple, np.ndarray] = {}


class DiffuseTail:
    """The diffuse late tail of one source at a rigid microphone array: (M, length) noise with
    diffuse-field coherence between microphones and per-band Eyring decay, sample 0 = emission.

    The tail is statistically isotropic, so one realisation serves every pose of the array
    (only its fade-in, which depends on the early part, changes with the pose)."""

    def __init__(self, rt60_bands: np.ndarray, volume_m3: float, fs: int, c: float, length: int,
                 rng: np.random.Generator, mics: np.ndarray) -> None:
        self.fs, self.c, self.length = int(fs), float(c), int(length)
        rt = np.asarray(rt60_bands, float)
        n_mics = np.asarray(mics).shape[0]
        n_fft = sfft.next_fast_len(self.length)
        freqs = np.fft.rfftfreq(n_fft, 1.0 / fs)
        spec = sfft.rfft(rng.standard_normal((n_mics, self.length)), n_fft, axis=1)
        spec = np.einsum("fij,jf->if", diffuse_mixing(freqs, mics, c), spec)
        t = np.arange(self.length) / fs
        var0 = 4 * np.pi * c / (volume_m3 * fs)
        bw = band_weights(freqs)
        tail = np.zeros((n_mics, self.length))
        for b in range(len(rt)):
            if rt[b] <= 0:
                continue
            env = np.sqrt(var0) * np.exp(-6.9078 * t / rt[b])  # amplitude; energy falls 60 dB in T60
            tail += sfft.irfft(spec * bw[b], n_fft, axis=1)[:, : self.length] * env
        self.tail = tail
        # Expected energy per sample and microphone (smoothed realisation): the fade-in reference.
        self.expected_energy = _smooth_energy(np.mean(tail**2, axis=0), int(0.01 * fs))


def _smooth_energy(e: np.ndarray, n: int) -> np.ndarray:
    """Centred moving average over ``n`` samples (same length)."""
    n = max(1, int(n))
    size, h = e.size, n // 2
    c = np.concatenate([[0.0], np.cumsum(e)])
    # c[clip(i - h, 0, size)] and c[clip(i - h + n, 0, size)] for i = 0 .. size - 1, as slices.
    lo = np.concatenate([np.full(min(h, size), c[0]), c[: max(0, size - h)]])
    k = min(size + 1, n - h)  # first index of the upper bound
    hi = np.concatenate([c[k: k + size], np.full(max(0, size - (size + 1 - k)), c[size])])
    return (hi - lo) / n


def tail_gain(early: np.ndarray, expected_energy: np.ndarray, start: int, fs: int, smooth_s: float = 0.02) -> np.ndarray:
    """Amplitude gain (length,) of the tail: 0 before ``start`` (first arrival the image-source
    model of the chosen order misses), then ``sqrt(1 - E_early / E_expected)`` of the energies
    smoothed over ``smooth_s``, so early + tail follows the diffuse decay where the early part thins out."""
    length = expected_energy.size
    n_s = max(1, int(smooth_s * fs))
    e_early = np.zeros(length)
    m = min(length, early.shape[1])
    e_early[:m] = np.mean(early[:, :m] ** 2, axis=0)
    e_early = _smooth_energy(e_early, n_s)
    e_exp = _smooth_energy(expected_energy, n_s)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(e_exp > 0, e_early / e_exp, 1.0)
    g = np.sqrt(np.clip(1.0 - ratio, 0.0, 1.0))
    g[: max(0, start)] = 0.0
    g = _smooth_energy(g, n_s // 2)
    g[: max(0, start)] = 0.0
    return g
