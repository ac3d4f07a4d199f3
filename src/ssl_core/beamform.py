"""Delay-and-sum beamforming toward directions in the array frame: the one beamformer of the project.

Used by the Localizer (beam level of a detection), by ``robot.voice.beamform`` (a whole listen
window) and by ``robot.hearing`` (a continuous beam per tracked source, ``StreamingBeamformer``).
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


class StreamingBeamformer:
    """Continuous far-field delay-and-sum beams toward several directions, block by block.

    Overlap-save: each block is transformed with the last ``history`` samples of the previous ones
    in front; every channel is delayed by ``latency - arrival`` (>= 0, so the beam is causal and
    a constant ``latency_s`` late), which wraps circularly only into the history part, discarded.
    Directions may change from block to block (tracks move).
    """

    def __init__(self, positions: np.ndarray, fs: float, sound_speed: float = SOUND_SPEED, history: int = 64):
        self.positions = np.asarray(positions, float)
        if self.positions.ndim != 2 or self.positions.shape[1] != 3:
            raise ValueError(f"positions: expected (n_mics, 3) m, got shape {self.positions.shape}")
        self.fs = float(fs)
        self.sound_speed = float(sound_speed)
        self.latency_s = float(np.linalg.norm(self.positions, axis=1).max() / sound_speed)
        if history < 2 * self.latency_s * fs + 1:
            raise ValueError(f"history: expected >= {int(2 * self.latency_s * fs) + 1} samples for this aperture, got {history}")
        self._hist = np.zeros((len(self.positions), history))

    def process(self, block: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """``block`` (n_mics, n) float; ``directions`` (k, 3) unit vectors -> beams (k, n)."""
        x = np.asarray(block, float)
        if x.ndim != 2 or x.shape[0] != len(self.positions):
            raise ValueError(f"block: expected ({len(self.positions)}, n), got {x.shape}")
        d = np.atleast_2d(np.asarray(directions, float))
        h = self._hist.shape[1]
        full = np.concatenate([self._hist, x], axis=1)
        self._hist = full[:, -h:]
        if len(d) == 0:
            return np.zeros((0, x.shape[1]))
        nfft = scipy.fft.next_fast_len(full.shape[1], real=True)
        f = np.fft.rfftfreq(nfft, 1.0 / self.fs)
        spec = scipy.fft.rfft(full, nfft, axis=-1)                                # (mics, bins)
        delay = self.latency_s - arrival_times(self.positions, d, self.sound_speed)  # (k, mics) >= 0
        beams = np.einsum("mf,kmf->kf", spec, np.exp(-2j * np.pi * delay[:, :, None] * f)) / len(self.positions)
        return scipy.fft.irfft(beams, nfft, axis=-1)[:, h:full.shape[1]]


def level_db(x: np.ndarray, axis: int = -1) -> np.ndarray:
    """Level (dB re a full-scale sine) of float signals along ``axis``."""
    ms = np.mean(np.square(x), axis=axis)
    return 10 * np.log10(np.maximum(ms, 1e-30) / FULL_SCALE_SINE_MS)
