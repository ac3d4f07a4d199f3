"""Test signals with independent truth: exact fractional delays and speech-like sources."""
from __future__ import annotations

import numpy as np
from scipy import signal

C = 343.0


def speech_like(n: int, fs: int, seed: int, f0: float = 140.0) -> np.ndarray:
    """A voiced, formant-filtered pulse train with jittered pitch and syllabic bursts (unit RMS)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / fs
    f0_t = f0 * (1 + 0.15 * np.sin(2 * np.pi * 0.7 * t + rng.uniform(0, 6)) + 0.02 * rng.standard_normal(n).cumsum() / np.sqrt(n))
    phase = np.cumsum(f0_t) / fs
    pulses = np.diff(np.floor(phase), prepend=0.0)
    src = pulses + 0.05 * rng.standard_normal(n)  # voiced excitation plus breath noise
    x = src
    for fc, bw in ((rng.uniform(500, 800), 90), (rng.uniform(1100, 1800), 110), (rng.uniform(2300, 2900), 160)):
        r = np.exp(-np.pi * bw / fs)
        a = [1, -2 * r * np.cos(2 * np.pi * fc / fs), r * r]
        x = x + 0.6 * signal.lfilter([1 - r], a, src)
    env = 0.2 + np.clip(np.sin(2 * np.pi * 3.5 * t + rng.uniform(0, 6)), 0, None)  # ~3.5 syllables/s
    x = signal.lfilter([1, -0.95], [1], x * env)
    return x / np.sqrt(np.mean(x**2))


def delay_signals(s: np.ndarray, delays: np.ndarray, fs: int) -> np.ndarray:
    """Exact (band-limited, circular) fractional delays of ``s`` by ``delays`` (s) -> (len(delays), n)."""
    n = s.size
    f = np.fft.rfftfreq(n, 1 / fs)
    return np.fft.irfft(np.fft.rfft(s)[None] * np.exp(-2j * np.pi * f[None] * np.asarray(delays)[:, None]), n)


def plane_wave(mics: np.ndarray, direction: np.ndarray, s: np.ndarray, fs: int) -> np.ndarray:
    """Far-field plane wave from unit ``direction`` (array frame) at microphones ``mics`` (m)."""
    return delay_signals(s, -(mics @ direction) / C, fs)


def point_source(mics: np.ndarray, position: np.ndarray, s: np.ndarray, fs: int) -> np.ndarray:
    """Spherical wave from ``position`` (m): exact delays and 1/r amplitude."""
    r = np.linalg.norm(mics - position, axis=1)
    return delay_signals(s, r / C, fs) / r[:, None]


def room_talker(mics: np.ndarray, direction: np.ndarray, seconds: float, fs: int, seed: int, rt60_s: float = 0.4,
                snr_db: float = 20.0, distance_m: float = 1.5) -> np.ndarray:
    """(n_mics, n) recording of a ``speech_like`` talker ``distance_m`` away along unit ``direction`` (array
    frame) from an array with microphones ``mics`` (m, array frame) in a 6 x 5 x 3 m pyroomacoustics room of
    ``rt60_s``; scaled to -20 dBFS rms, white sensor noise ``snr_db`` below that."""
    import pyroomacoustics as pra

    room_dim = np.array([6.0, 5.0, 3.0])
    e_abs, max_order = pra.inverse_sabine(rt60_s, room_dim)
    centre = np.array([2.6, 2.2, 1.2])
    room = pra.ShoeBox(room_dim, fs=fs, materials=pra.Material(e_abs), max_order=min(max_order, 12))
    n = int(seconds * fs)
    room.add_source(centre + distance_m * np.asarray(direction), signal=speech_like(n, fs, seed=seed))
    room.add_microphone_array((centre + mics).T)
    room.simulate()
    x = room.mic_array.signals[:, :n]
    x = 0.1 * x / np.sqrt(np.mean(x**2))
    return x + np.random.default_rng(seed).standard_normal(x.shape) * 0.1 / 10 ** (snr_db / 20)
