"""Delay-and-sum beamforming toward directions in the array frame: the one beamformer of the project.

Delay-and-sum (``delay_and_sum``, ``beam_signal``) serves the Localizer (beam level of a detection)
and the rescue behaviour (a beam over a listen window); ``robot.hearing`` listens to each tracked
source continuously through ``MpdrBeamformer`` on a streaming STFT (``StftStream``, ``OverlapAdd``).
Frames: array frame, +x forward, +y left, +z up; directions are unit vectors toward the source.
"""
from __future__ import annotations

import numpy as np
import scipy.fft

from ssl_core.srp import SOUND_SPEED

FULL_SCALE_SINE_MS = 0.5  # mean square of a full-scale sine: 0 dBFS


def arrival_times(positions: np.ndarray, direction: np.ndarray, sound_speed: float = SOUND_SPEED,
                  radius: float | None = None) -> np.ndarray:
    """Arrival time (s) of a wave from unit ``direction`` at each microphone (``positions`` (n_mics, 3) m),
    relative to the array centre for a far-field plane wave, or the travel time from a source at
    ``radius`` m (near field) -> (n_mics,) or (n_directions, n_mics) for (n_directions, 3) directions."""
    u = np.asarray(direction, float)
    pos = np.asarray(positions, float)
    if radius is None:
        return -(u @ pos.T) / sound_speed
    return np.linalg.norm(radius * u[..., None, :] - pos, axis=-1) / sound_speed


def delay_and_sum(spec: np.ndarray, freqs_hz: np.ndarray, arrival_s: np.ndarray) -> np.ndarray:
    """Beam spectrum: each channel of ``spec`` (n_mics, ..., n_bins) advanced by its ``arrival_s``
    (n_mics,) at ``freqs_hz`` (n_bins,) and averaged over microphones -> (..., n_bins)."""
    steer = np.exp(2j * np.pi * np.outer(arrival_s, freqs_hz))
    steer = steer.reshape(steer.shape[0], *([1] * (spec.ndim - 2)), steer.shape[1])
    return (spec * steer).mean(axis=0)


def beam_signal(samples: np.ndarray, positions: np.ndarray, direction: np.ndarray, fs: float,
                sound_speed: float = SOUND_SPEED) -> np.ndarray:
    """Far-field delay-and-sum beam of a whole float signal ``samples`` (n_mics, n) toward unit
    ``direction`` -> (n,) (frequency-domain fractional delays over the whole signal)."""
    x = np.asarray(samples, float)
    if x.ndim != 2 or x.shape[0] != len(positions):
        raise ValueError(f"samples: expected ({len(positions)}, n) for {len(positions)} microphones, got {x.shape}")
    n = x.shape[1]
    nfft = scipy.fft.next_fast_len(n, real=True)
    f = np.fft.rfftfreq(nfft, 1.0 / fs)
    beam = delay_and_sum(scipy.fft.rfft(x, nfft, axis=-1), f, arrival_times(positions, direction, sound_speed))
    return scipy.fft.irfft(beam, nfft)[:n]


class StftStream:
    """Streaming STFT of a multichannel signal: 512-sample sqrt-Hann frames, hop 256 (analysis x synthesis
    windows sum to one, so ``OverlapAdd`` of unmodified frames gives the input back, one hop late)."""

    FRAME, HOP = 512, 256
    WINDOW = np.sqrt(np.hanning(FRAME + 1)[:-1])
    _WINDOW_ENERGY = float(np.sum(WINDOW**2))

    def __init__(self, n_channels: int, dtype: type = np.float64) -> None:
        """``dtype``: float64, or float32 for half the memory traffic (spectra then complex64)."""
        self.dtype = np.dtype(dtype)
        if self.dtype not in (np.float32, np.float64):
            raise ValueError(f"dtype: expected float32 or float64, got {self.dtype}")
        self._pending = np.zeros((n_channels, self.HOP), self.dtype)  # input not yet in a whole frame
        self._window = self.WINDOW.astype(self.dtype)

    def analyse(self, block: np.ndarray) -> np.ndarray:
        """``block`` (n_channels, n) float -> spectra (n_channels, n_frames, FRAME // 2 + 1) of the frames
        completed by it (any block length; n_frames may be 0)."""
        buf = np.concatenate([self._pending, block], axis=1, dtype=self.dtype)
        n = (buf.shape[1] - self.FRAME) // self.HOP + 1 if buf.shape[1] >= self.FRAME else 0
        self._pending = buf[:, n * self.HOP:]
        if n == 0:
            return np.zeros((buf.shape[0], 0, self.FRAME // 2 + 1), np.result_type(self.dtype, np.complex64))
        # frames as a view: (channels, n, FRAME) with hop HOP (what sliding_window_view gives, without its checks)
        step = buf.strides[1]
        frames = np.lib.stride_tricks.as_strided(buf, (buf.shape[0], n, self.FRAME),
                                                 (buf.strides[0], self.HOP * step, step), writeable=False)
        return scipy.fft.rfft(frames * self._window, axis=-1)

    def skip(self, block: np.ndarray) -> None:
        """Pass over ``block`` (n_channels, n) without analysing it: the next frame starts HOP samples
        before its end."""
        block = np.asarray(block)
        if block.shape[1] >= self.HOP:
            self._pending = np.array(block[:, block.shape[1] - self.HOP:], self.dtype)
        else:
            self._pending = np.concatenate([self._pending, block], axis=1, dtype=self.dtype)[:, block.shape[1]:]

    @classmethod
    def mean_square(cls, spec: np.ndarray) -> np.ndarray:
        """Mean square (per sample) of the signal behind one-sided frame spectra (..., n_frames, bins),
        averaged over frames (Parseval with the window's energy). ``bins`` may be the first bins only
        (a band from 0 Hz below Nyquist, e.g. ``MpdrBeamformer(max_freq_hz=...)``): then the mean square
        of that band."""
        return cls.power_mean_square(spec.real**2 + spec.imag**2)

    @classmethod
    def power_mean_square(cls, power: np.ndarray) -> np.ndarray:
        """``mean_square`` from the bins' power ``|spec|**2`` (..., n_frames, bins)."""
        p = power
        total = 2 * p.sum(axis=-1) - p[..., 0]
        if p.shape[-1] == cls.FRAME // 2 + 1:
            total -= p[..., -1]  # the Nyquist bin, like 0 Hz, has no mirror
        return total.mean(axis=-1) / (cls.FRAME * cls._WINDOW_ENERGY) if p.shape[-2] else np.zeros(p.shape[:-2])


class OverlapAdd:
    """Inverse of one channel of ``StftStream``: frame spectra in, HOP / ``decimation`` samples per frame out.

    With ``decimation`` d > 1 the output is the signal at ``fs / d`` (every d-th sample of the full-rate
    output): the spectra must be zero at and above ``fs / (2 d)``, i.e. give at most ``FRAME // (2 d)``
    bins (the rest are taken as zero). Exact, not an approximation: a frame band-limited below the new
    Nyquist, sampled at every d-th point, is the d-times shorter inverse FFT of the same bins over d
    (the windowed frames then add up like the full-rate ones).
    """

    def __init__(self, decimation: int = 1) -> None:
        if decimation not in (1, 2, 4):
            raise ValueError(f"decimation: expected 1, 2 or 4, got {decimation}")
        self.decimation = decimation
        self._n = StftStream.FRAME // decimation
        self._hop = StftStream.HOP // decimation
        self._window = StftStream.WINDOW[::decimation] / decimation
        self._tail = np.zeros(self._hop)

    def synthesise(self, spec: np.ndarray) -> np.ndarray:
        """``spec`` (n_frames, bins) -> (n_frames * HOP // decimation,) samples."""
        return self.synthesise_all([self], spec[None])[0]

    def reset(self) -> None:
        """Forget the previous frame (after a gap in the frames: the next output fades in over one hop)."""
        self._tail = np.zeros(self._hop)

    @staticmethod
    def synthesise_all(synths: list[OverlapAdd], spec: np.ndarray) -> np.ndarray:
        """One inverse FFT for several streams of equal ``decimation``: ``spec`` (k, n_frames, bins), row i
        continuing ``synths[i]`` -> (k, n_frames * HOP // decimation) samples."""
        if not synths or spec.shape[1] == 0:
            return np.zeros((len(synths), 0))
        first = synths[0]
        if first.decimation > 1 and spec.shape[-1] > first._n // 2:
            raise ValueError(f"spec: expected at most {first._n // 2} bins (below fs / {2 * first.decimation}) "
                             f"for decimation {first.decimation}, got {spec.shape[-1]}")
        h = first._hop
        y = scipy.fft.irfft(spec, first._n, axis=-1)                          # (k, frames, n)
        y *= first._window
        heads = y[:, :, :h].copy()
        heads[:, 1:] += y[:, :-1, h:]
        for i, o in enumerate(synths):
            heads[i, 0] += o._tail
            o._tail = y[i, -1, h:].copy()
        return heads.reshape(len(synths), -1)


class MpdrBeamformer:
    """Minimum-power distortionless-response beams on STFT frames (far field, array frame).

    Per bin, ``w = R^-1 a / (a^H R^-1 a)`` with ``a`` the plane-wave steering vector toward the
    direction and ``R`` the recursively averaged covariance of the microphone spectra (time constant
    ``memory_s``) plus diagonal loading ``loading`` x its mean diagonal: unit gain toward the track,
    least power from everything else. Measured on the 15 cm cube in a room of RT60 0.6 s (talker and a
    machine 2 m away, 60-110 degrees apart): Silero VAD finds speech in the talker's beam in more 1 s
    windows than with delay-and-sum and less of her in the machine's beam (docs/design/voice.md, "Telling a victim
    from a machine"); loading 0.1 of the tried 0.001 / 0.01 / 0.1 held the talker best.

    ``max_freq_hz``: beam only the bins below it (``process`` returns those bins); the covariance,
    its inverse and the weights shrink with them (0-4 kHz: half the bins, half the cost).
    The loaded inverse is refreshed every ``update_s`` (R changes over ``memory_s``, not per frame) and
    the weights only then or when a direction moves by more than ``steer_tolerance_rad`` (0.5 deg moves
    a delay across the 15 cm cube's 0.21 m diagonal by <= 5.3 us: <= 0.13 rad of phase at 4 kHz).
    """

    def __init__(self, positions: np.ndarray, fs: float, memory_s: float = 3.0, loading: float = 0.1,
                 update_s: float = 0.25, sound_speed: float = SOUND_SPEED, max_freq_hz: float | None = None,
                 steer_tolerance_rad: float = np.deg2rad(0.5)) -> None:
        self.positions = np.asarray(positions, float)
        if self.positions.ndim != 2 or self.positions.shape[1] != 3:
            raise ValueError(f"positions: expected (n_mics, 3) m, got shape {self.positions.shape}")
        for name, v in (("memory_s", memory_s), ("loading", loading), ("update_s", update_s)):
            if not v > 0:
                raise ValueError(f"{name}: expected > 0, got {v}")
        if not steer_tolerance_rad >= 0:
            raise ValueError(f"steer_tolerance_rad: expected >= 0, got {steer_tolerance_rad}")
        freqs = np.fft.rfftfreq(StftStream.FRAME, 1.0 / fs)
        if max_freq_hz is not None:
            if not 0 < max_freq_hz <= fs / 2:
                raise ValueError(f"max_freq_hz: expected in (0, {fs / 2}] Hz, got {max_freq_hz}")
            freqs = freqs[freqs < max_freq_hz]
        self.freqs = freqs
        self.sound_speed = sound_speed
        self.loading = loading
        self._forget = float(np.exp(-StftStream.HOP / fs / memory_s))
        self._update_frames = max(1, int(round(update_s * fs / StftStream.HOP)))
        self._cos_tolerance = float(np.cos(steer_tolerance_rad))
        self._cov: np.ndarray | None = None   # (bins, m, m), in the spectra's precision (first process)
        self._weight = 0.0       # total weight in _cov (bias correction while it fills)
        self._inv = None         # loaded inverse covariance (bins, m, m)
        self._since = 0          # frames since _inv was computed
        self._w_h = None         # conjugated weights (bins, k, m) for _w_dirs
        self._w_dirs = np.zeros((0, 3))
        self._decays: dict[tuple[int, np.dtype], np.ndarray] = {}

    def _decay(self, n: int, dtype: np.dtype) -> np.ndarray:
        """Weights in R of n new frames, oldest first."""
        if (n, dtype) not in self._decays:
            self._decays[n, dtype] = ((1 - self._forget) * self._forget ** np.arange(n - 1, -1, -1)).astype(dtype)
        return self._decays[n, dtype]

    def process(self, spec: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """``spec`` (n_mics, n_frames, bins) from ``StftStream``; ``directions`` (k, 3) -> beams
        (k, n_frames, len(self.freqs))."""
        d = np.atleast_2d(np.asarray(directions, float))
        n = spec.shape[1]
        nb = len(self.freqs)
        if self._cov is None or self._cov.dtype != spec.dtype:
            self._cov, self._weight, self._inv = np.zeros((nb, len(self.positions), len(self.positions)), spec.dtype), 0.0, None
        if n == 0:
            return np.zeros((len(d), n, nb), spec.dtype)
        # (using every other frame only, which do not overlap, halved this but measurably weakened the
        # machine's cancellation in the room cases of tests/test_hearing.py)
        s = np.ascontiguousarray(spec[:, :, :nb].transpose(2, 0, 1))      # (bins, mics, frames)
        self._cov *= self._forget**n
        self._cov += (s * self._decay(n, s.real.dtype)) @ s.conj().transpose(0, 2, 1)
        self._weight = self._forget**n * self._weight + (1 - self._forget**n)
        self._since += n
        if len(d) == 0:
            return np.zeros((0, n, nb), spec.dtype)
        if self._inv is None or self._since >= self._update_frames:
            m = len(self.positions)
            cov = self._cov / max(self._weight, 1e-12)
            load = self.loading * np.real(np.trace(cov, axis1=1, axis2=2)) / m + 1e-20
            self._inv = np.linalg.inv(cov + (load[:, None, None] * np.eye(m)).astype(cov.dtype))
            self._since = 0
            self._w_h = None
        if (self._w_h is None or d.shape != self._w_dirs.shape
                or np.min(np.sum(d * self._w_dirs, axis=1)) < self._cos_tolerance):
            # exp(-2 pi i f t) as cos and sin of a real phase in the spectra's precision: numpy's complex exp
            # took 72 us (complex128) or 150 us (complex64) per refresh for 4 beams, cos + sin 12
            phase = (2 * np.pi * self.freqs[:, None, None]
                     * arrival_times(self.positions, d, self.sound_speed).T[None]).astype(spec.real.dtype)
            steer = np.empty(phase.shape, spec.dtype)
            steer.real, steer.imag = np.cos(phase), -np.sin(phase)
            ri_a = self._inv @ steer
            w = ri_a / np.einsum("fmk,fmk->fk", steer.conj(), ri_a)[:, None, :]
            self._w_h, self._w_dirs = np.ascontiguousarray(w.conj().transpose(0, 2, 1)), d.copy()
        return (self._w_h @ s).transpose(1, 2, 0)  # (k, frames, bins)


def level_db(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """Level (dB re a full-scale sine) of float signals along ``axis``."""
    ms = np.mean(np.square(x), axis=axis)
    return 10 * np.log10(np.maximum(ms, 1e-30) / FULL_SCALE_SINE_MS)
