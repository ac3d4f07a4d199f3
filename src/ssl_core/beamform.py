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

    def __init__(self, n_channels: int) -> None:
        self._pending = np.zeros((n_channels, self.HOP))  # input not yet in a whole frame

    def analyse(self, block: np.ndarray) -> np.ndarray:
        """``block`` (n_channels, n) float -> spectra (n_channels, n_frames, FRAME // 2 + 1) of the frames
        completed by it (any block length; n_frames may be 0)."""
        buf = np.concatenate([self._pending, np.asarray(block, float)], axis=1)
        n = (buf.shape[1] - self.FRAME) // self.HOP + 1 if buf.shape[1] >= self.FRAME else 0
        self._pending = buf[:, n * self.HOP:]
        if n == 0:
            return np.zeros((buf.shape[0], 0, self.FRAME // 2 + 1), complex)
        frames = np.lib.stride_tricks.sliding_window_view(buf, self.FRAME, axis=1)[:, :: self.HOP][:, :n]
        return scipy.fft.rfft(frames * self.WINDOW, axis=-1)

    @classmethod
    def mean_square(cls, spec: np.ndarray) -> np.ndarray:
        """Mean square (per sample) of the signal behind one-sided frame spectra (..., n_frames, bins),
        averaged over frames (Parseval with the window's energy)."""
        p = np.abs(spec) ** 2
        total = 2 * p.sum(axis=-1) - p[..., 0] - p[..., -1]
        return total.mean(axis=-1) / (cls.FRAME * np.sum(cls.WINDOW**2)) if spec.shape[-2] else np.zeros(spec.shape[:-2])


class OverlapAdd:
    """Inverse of one channel of ``StftStream``: frame spectra in, HOP samples per frame out."""

    def __init__(self) -> None:
        self._tail = np.zeros(StftStream.HOP)

    def synthesise(self, spec: np.ndarray) -> np.ndarray:
        """``spec`` (n_frames, bins) -> (n_frames * HOP,) samples."""
        if len(spec) == 0:
            return np.zeros(0)
        h = StftStream.HOP
        y = scipy.fft.irfft(spec, StftStream.FRAME, axis=-1) * StftStream.WINDOW
        heads = y[:, :h].copy()
        heads[0] += self._tail
        heads[1:] += y[:-1, h:]
        self._tail = y[-1, h:].copy()
        return heads.ravel()


class MpdrBeamformer:
    """Minimum-power distortionless-response beams on STFT frames (far field, array frame).

    Per bin, ``w = R^-1 a / (a^H R^-1 a)`` with ``a`` the plane-wave steering vector toward the
    direction and ``R`` the recursively averaged covariance of the microphone spectra (time constant
    ``memory_s``) plus diagonal loading ``loading`` x its mean diagonal: unit gain toward the track,
    least power from everything else. Measured on the 15 cm cube in a room of RT60 0.6 s (talker and a
    machine 2 m away, 60-110 degrees apart): Silero VAD finds speech in the talker's beam in more 1 s
    windows than with delay-and-sum and less of her in the machine's beam (README, "Telling a victim
    from a machine"); loading 0.1 of the tried 0.001 / 0.01 / 0.1 held the talker best.
    """

    def __init__(self, positions: np.ndarray, fs: float, memory_s: float = 3.0, loading: float = 0.1,
                 update_s: float = 0.25, sound_speed: float = SOUND_SPEED) -> None:
        self.positions = np.asarray(positions, float)
        if self.positions.ndim != 2 or self.positions.shape[1] != 3:
            raise ValueError(f"positions: expected (n_mics, 3) m, got shape {self.positions.shape}")
        for name, v in (("memory_s", memory_s), ("loading", loading), ("update_s", update_s)):
            if not v > 0:
                raise ValueError(f"{name}: expected > 0, got {v}")
        self.freqs = np.fft.rfftfreq(StftStream.FRAME, 1.0 / fs)
        self.sound_speed = sound_speed
        self.loading = loading
        self._forget = float(np.exp(-StftStream.HOP / fs / memory_s))
        # the inverse covariance is refreshed every update_s (it changes over memory_s, not per frame)
        self._update_frames = max(1, int(round(update_s * fs / StftStream.HOP)))
        m = len(self.positions)
        self._cov = np.zeros((len(self.freqs), m, m), complex)
        self._weight = 0.0       # total weight in _cov (bias correction while it fills)
        self._inv = None         # loaded inverse covariance (bins, m, m)
        self._since = 0          # frames since _inv was computed

    def process(self, spec: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """``spec`` (n_mics, n_frames, bins) from ``StftStream``; ``directions`` (k, 3) -> beams (k, n_frames, bins)."""
        d = np.atleast_2d(np.asarray(directions, float))
        n = spec.shape[1]
        if n:
            s = spec.transpose(2, 0, 1)                                        # (bins, mics, frames)
            decay = (1 - self._forget) * self._forget ** np.arange(n - 1, -1, -1)
            self._cov = self._forget**n * self._cov + (s * decay) @ s.conj().transpose(0, 2, 1)
            self._weight = self._forget**n * self._weight + (1 - self._forget**n)
            self._since += n
        if len(d) == 0 or n == 0:
            return np.zeros((len(d), n, spec.shape[2]), complex)
        if self._inv is None or self._since >= self._update_frames:
            m = len(self.positions)
            cov = self._cov / max(self._weight, 1e-12)
            load = self.loading * np.real(np.trace(cov, axis1=1, axis2=2)) / m + 1e-20
            self._inv = np.linalg.inv(cov + load[:, None, None] * np.eye(m))
            self._since = 0
        steer = np.exp(-2j * np.pi * self.freqs[:, None, None] * arrival_times(self.positions, d, self.sound_speed).T[None])
        ri_a = self._inv @ steer                                                # (bins, mics, k)
        w = ri_a / np.einsum("fmk,fmk->fk", steer.conj(), ri_a)[:, None, :]
        return (w.conj().transpose(0, 2, 1) @ spec.transpose(2, 0, 1)).transpose(1, 2, 0)  # (k, frames, bins)


def level_db(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """Level (dB re a full-scale sine) of float signals along ``axis``."""
    ms = np.mean(np.square(x), axis=axis)
    return 10 * np.log10(np.maximum(ms, 1e-30) / FULL_SCALE_SINE_MS)
