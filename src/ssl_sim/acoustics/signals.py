"""Time-keyed source signals: any block ``[n0, n0 + n)`` of a stream can be rendered on
its own and is identical however the timeline is cut into blocks.

That is what lets the acoustic simulator serve consecutive listen steps of a
continuing voice without seams, and reproduce a block exactly from ``(seed, t)``.
Sample indices are absolute (sample 0 = simulation time 0; negative indices are
valid and give the stream's past). Levels: every stream is scaled to **unit RMS
while active** (for intermittent streams, over each event), so a source's
``level_db_spl`` fixes its sound pressure while it sounds.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from collections import OrderedDict
from typing import Callable

import numpy as np
from scipy import signal as sps

# Offsets keep seeds non-negative for negative chunk/period indices.
_INDEX_OFFSET = 1 << 40


def _rng(seed: int, stream: int, index: int) -> np.random.Generator:
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, int(stream) & 0xFFFFFFFF, int(index) + _INDEX_OFFSET])


class TimeKeyedNoise:
    """Standard-normal white noise as a function of absolute sample index.

    Samples are produced in chunks of ``chunk`` samples, chunk ``k`` drawn from an RNG
    seeded by ``(seed, stream, k)``; ``channels`` independent channels per stream.
    """

    def __init__(self, seed: int, stream: int = 0, channels: int = 1, chunk: int = 8192,
                 loop_chunks: int | None = None) -> None:
        self.seed, self.stream, self.channels, self.chunk = int(seed), int(stream), int(channels), int(chunk)
        if loop_chunks is not None and not 1 <= loop_chunks <= 64:
            raise ValueError(f"loop_chunks: expected None or 1..64 (the cache), got {loop_chunks}")
        self.loop_chunks = loop_chunks  # repeat every loop_chunks chunks (cheap noise: all cached)
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()

    def _chunk(self, k: int) -> np.ndarray:
        if self.loop_chunks is not None:
            k = k % self.loop_chunks
        c = self._cache.get(k)
        if c is None:
            c = _rng(self.seed, self.stream, k).standard_normal((self.channels, self.chunk))
            self._cache[k] = c
            if len(self._cache) > 64:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(k)
        return c

    def samples(self, n0: int, n: int) -> np.ndarray:
        """Noise for samples ``n0 .. n0 + n - 1``, shape (channels, n)."""
        n0, n = int(n0), int(n)
        k0, k1 = n0 // self.chunk, (n0 + n - 1) // self.chunk if n > 0 else n0 // self.chunk
        if n <= 0:
            return np.zeros((self.channels, 0))
        return _piece_together(self._chunk, k0, k1, n0 - k0 * self.chunk, n, self.chunk, self.channels)


def _piece_together(chunk: Callable[[int], np.ndarray], k0: int, k1: int, start: int, n: int, size: int,
                    channels: int) -> np.ndarray:
    """Samples ``start .. start + n - 1`` of chunks ``k0 .. k1`` (each (channels, size), from ``chunk(k)``)
    laid end to end -> a new (channels, n) array: only the samples asked for are copied (joining whole chunks
    first copied up to 2 x 8192 samples a channel to keep a quarter-second block)."""
    out = np.empty((channels, n))
    pos = 0
    for k in range(k0, k1 + 1):
        a = start if k == k0 else 0
        b = min(size, start + n - (k - k0) * size)
        out[:, pos:pos + b - a] = chunk(k)[:, a:b]
        pos += b - a
    return out


class SignalStream(ABC):
    """A mono source signal defined for every absolute sample index at rate ``fs`` (Hz)."""

    fs: int

    @abstractmethod
    def render(self, n0: int, n: int) -> np.ndarray:
        """Samples ``n0 .. n0 + n - 1`` (float64, shape (n,)), unit RMS while active."""

    def render_time(self, t0: float, duration_s: float) -> np.ndarray:
        """Convenience: the block starting at ``t0`` seconds lasting ``duration_s``."""
        return self.render(int(round(t0 * self.fs)), int(round(duration_s * self.fs)))


def unit_rms(x: np.ndarray, floor_db: float = -50.0) -> np.ndarray:
    """Scale ``x`` to unit RMS measured over its active part (samples in 10 ms frames within ``floor_db`` of the loudest frame)."""
    x = np.asarray(x, float)
    if x.size == 0 or not np.any(x):
        return x.copy()
    frame = 160
    n_fr = max(1, x.size // frame)
    e = np.mean(x[: n_fr * frame].reshape(n_fr, -1) ** 2, axis=1) if x.size >= frame else np.array([np.mean(x**2)])
    active = e >= e.max() * 10 ** (floor_db / 10)
    return x / np.sqrt(np.mean(e[active]))


class EventStream(SignalStream):
    """Intermittent events (calls, moans, knocks): time is cut into periods of ``period_s``;
    period ``k`` holds at most one event, drawn by ``make_event(rng)`` from an RNG seeded
    by ``(seed, stream, k)`` and placed at a random onset inside the period (events longer
    than the period are truncated with a fade). With probability ``1 - p_event`` a period is silent.

    Each event is normalised to unit RMS over its active part (see ``unit_rms``).
    """

    def __init__(self, make_event: Callable[[np.random.Generator], np.ndarray], fs: int, period_s: float,
                 seed: int, stream: int = 0, p_event: float = 1.0) -> None:
        if period_s <= 0:
            raise ValueError(f"period_s: expected > 0 s, got {period_s}")
        if not 0.0 <= p_event <= 1.0:
            raise ValueError(f"p_event: expected a probability in [0, 1], got {p_event}")
        self.make_event, self.fs, self.seed, self.stream, self.p_event = make_event, int(fs), int(seed), int(stream), float(p_event)
        self.period = int(round(period_s * fs))
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()

    def period_signal(self, k: int) -> np.ndarray:
        """The full content of period ``k`` (length ``period``)."""
        out = self._cache.get(k)
        if out is not None:
            self._cache.move_to_end(k)
            return out
        rng = _rng(self.seed, self.stream, k)
        out = np.zeros(self.period)
        if rng.random() < self.p_event:
            ev = unit_rms(np.asarray(self.make_event(rng), float))
            if ev.size > self.period:
                ev = ev[: self.period].copy()
                fade = min(160, ev.size)
                ev[-fade:] *= np.linspace(1.0, 0.0, fade)
            onset = int(rng.integers(0, self.period - ev.size + 1))
            out[onset:onset + ev.size] = ev
        self._cache[k] = out
        if len(self._cache) > 16:
            self._cache.popitem(last=False)
        return out

    def render(self, n0: int, n: int) -> np.ndarray:
        n0, n = int(n0), int(n)
        if n <= 0:
            return np.zeros(0)
        k0, k1 = n0 // self.period, (n0 + n - 1) // self.period
        seg = np.concatenate([self.period_signal(k) for k in range(k0, k1 + 1)])
        start = n0 - k0 * self.period
        return seg[start:start + n]


class LoopedSignal(SignalStream):
    """A recorded/pre-rendered signal repeated forever (sample 0 of the recording at n = 0)."""

    def __init__(self, samples: np.ndarray, fs: int, normalise: bool = True) -> None:
        x = np.asarray(samples, float)
        if x.ndim != 1 or x.size == 0:
            raise ValueError(f"samples: expected a non-empty 1-D signal, got shape {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError("samples: contains NaN or inf")
        self.fs = int(fs)
        self.x = unit_rms(x) if normalise else x

    def render(self, n0: int, n: int) -> np.ndarray:
        idx = (int(n0) + np.arange(int(n))) % self.x.size
        return self.x[idx]


def _spectrum_fir(spectrum: str, fs: int, n_taps: int = 513, band_hz: tuple[float, float] | None = None) -> np.ndarray:
    """Linear-phase FIR with magnitude shaped like ``spectrum`` (white, pink, brown, hvac, speech)."""
    f = np.linspace(0, fs / 2, 257)
    fsafe = np.maximum(f, 20.0)
    if spectrum == "white":
        mag = np.ones_like(f)
    elif spectrum == "pink":
        mag = 1 / np.sqrt(fsafe / 100.0)
    elif spectrum == "brown":
        mag = 100.0 / fsafe
    elif spectrum == "hvac":  # pink-ish with a low-frequency rumble and a 4 kHz roll-off
        mag = 1 / np.sqrt(fsafe / 100.0) / np.sqrt(1 + (f / 4000.0) ** 4)
    elif spectrum == "speech":  # long-term average speech spectrum (approx.: peak ~500 Hz, -6 dB/oct above)
        mag = (fsafe / 500.0) / (1 + (fsafe / 500.0) ** 2)
    else:
        raise ValueError(f"spectrum: expected one of white, pink, brown, hvac, speech; got {spectrum!r}")
    if band_hz is not None:
        lo, hi = band_hz
        mag = mag * ((f >= lo) & (f <= hi))
    mag[0] = 0.0
    h = sps.firwin2(n_taps, f / (fs / 2), mag)
    return h


class ShapedNoise(SignalStream):
    """Continuous coloured noise (FIR-shaped time-keyed white noise), optionally amplitude-modulated
    and with added harmonic tones; unit RMS overall.

    ``tones``: (frequency Hz, relative amplitude) pairs, rendered as analytic functions of time
    (continuous across blocks); ``tone_share`` is the fraction of the power in the tones.
    ``am_hz``/``am_depth``: slow amplitude modulation (e.g. a pump's stroke).
    """

    def __init__(self, fs: int, seed: int, spectrum: str = "pink", stream: int = 0,
                 tones: tuple[tuple[float, float], ...] = (), tone_share: float = 0.0,
                 am_hz: float = 0.0, am_depth: float = 0.0, band_hz: tuple[float, float] | None = None) -> None:
        self.fs = int(fs)
        self.h = _spectrum_fir(spectrum, self.fs, band_hz=band_hz)
        self.h /= np.sqrt(np.sum(self.h**2))  # unit-variance output for unit-variance white input
        self.noise = TimeKeyedNoise(seed, stream)
        self.tones = tuple((float(f), float(a)) for f, a in tones)
        if not 0.0 <= tone_share <= 1.0:
            raise ValueError(f"tone_share: expected a fraction in [0, 1], got {tone_share}")
        self.tone_share = tone_share if self.tones else 0.0
        amps = np.array([a for _, a in self.tones]) if self.tones else np.zeros(0)
        self._tone_scale = np.sqrt(self.tone_share / max(np.sum(amps**2) / 2, 1e-30)) if self.tones else 0.0
        self._phases = _rng(seed, stream + 7919, 0).uniform(0, 2 * np.pi, len(self.tones))
        self.am_hz, self.am_depth = float(am_hz), float(am_depth)

    def render(self, n0: int, n: int) -> np.ndarray:
        n0, n = int(n0), int(n)
        m = self.h.size - 1
        w = self.noise.samples(n0 - m, n + m)[0]
        y = np.sqrt(1.0 - self.tone_share) * sps.oaconvolve(w, self.h, mode="valid")
        t = (n0 + np.arange(n)) / self.fs
        for (f, a), ph in zip(self.tones, self._phases):
            y = y + self._tone_scale * a * np.sin(2 * np.pi * f * t + ph)
        if self.am_depth > 0:
            am = 1.0 + self.am_depth * np.sin(2 * np.pi * self.am_hz * t)
            y = y * am / np.sqrt(1.0 + self.am_depth**2 / 2)
        return y


def generator_noise(fs: int, seed: int, firing_hz: float = 25.0) -> ShapedNoise:
    """A small petrol/diesel generator: engine firing harmonics over brown-ish broadband noise."""
    tones = tuple((firing_hz * k, 1.0 / k) for k in range(1, 13))
    return ShapedNoise(fs, seed, spectrum="brown", stream=101, tones=tones, tone_share=0.5, am_hz=firing_hz / 2, am_depth=0.2)


def pump_noise(fs: int, seed: int, mains_hz: float = 50.0) -> ShapedNoise:
    """An electric water pump: motor hum at twice mains and harmonics over band-limited flow noise."""
    tones = tuple((2 * mains_hz * k, 1.0 / k**1.5) for k in range(1, 8))
    return ShapedNoise(fs, seed, spectrum="pink", stream=202, tones=tones, tone_share=0.35,
                       am_hz=1.2, am_depth=0.3, band_hz=(80.0, 5000.0))
