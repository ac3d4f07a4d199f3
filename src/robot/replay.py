"""Replay backends: a recorded multichannel WAV as the audio source and a
dry-run drive that only logs commands and integrates ideal odometry.

Together they run the rescue behaviour on a recording without motors (and,
with a ``ManualClock``, faster than real time).
"""
from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from math import gcd
from pathlib import Path

import numpy as np
from scipy.io import wavfile

from robot.hal import AudioBlock, AudioSource, Clock, DriveBase, DriveStatus, EndOfAudio, WheelOdometry
from robot.kinematics import OmniDriveParams, forward_kinematics, twist_to_wheels

log = logging.getLogger(__name__)


def _to_block_dtype(x: np.ndarray) -> np.ndarray:
    """int16 stays int16; other PCM widths and floats become float64 in [-1, 1)."""
    if x.dtype == np.int16:
        return np.array(x, dtype=np.int16)
    if x.dtype == np.int32:  # 32-bit PCM, and 24-bit PCM which scipy left-justifies into int32
        return x.astype(np.float64) / 2.0**31
    if x.dtype == np.uint8:
        return (x.astype(np.float64) - 128.0) / 128.0
    if x.dtype in (np.float32, np.float64):
        return x.astype(np.float64)
    raise ValueError(f"unsupported WAV sample type {x.dtype}; expected int16, int32, uint8 or float")


class WavFileSource(AudioSource):
    """Replays a multichannel WAV file block by block.

    ``expected_channels`` / ``expected_rate``: what the caller's array and
    localizer need (e.g. 8 and 16000); a mismatch raises ``ValueError`` at
    open time. ``resample_to``: instead, deliver the file at this rate
    (Hz; ``scipy.signal.resample_poly``'s polyphase filter applied block by
    block on the memory-mapped file, with enough of the neighbouring samples
    that every block equals the same span of the whole file resampled at
    once); the rate of the file must then be at least ``min_rate``.
    Block timestamps are file time, ``start_time + index / fs``
    (s). With a ``clock``, every read lets ``n_samples / fs`` pass on it, as a
    live capture would (a ``WallClock`` then replays in real time, a
    ``ManualClock`` as fast as possible with consistent times).
    """

    def __init__(
        self,
        path: str | Path,
        expected_channels: int | None = None,
        expected_rate: int | None = None,
        clock: Clock | None = None,
        start_time: float = 0.0,
        resample_to: int | None = None,
        min_rate: int = 0,
    ) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise FileNotFoundError(f"replay recording not found: {self.path}")
        try:
            rate, data = wavfile.read(self.path, mmap=True)
        except ValueError:
            try:  # some WAV flavours cannot be memory-mapped (e.g. 24-bit PCM)
                rate, data = wavfile.read(self.path, mmap=False)
            except ValueError as exc:
                raise ValueError(f"replay recording {self.path}: not a readable WAV file ({exc})") from exc
        data = data[:, None] if data.ndim == 1 else data
        n_ch = int(data.shape[1])
        if expected_channels is not None and n_ch != expected_channels:
            raise ValueError(
                f"replay recording {self.path}: has {n_ch} channel(s), expected {expected_channels} "
                "(one per microphone of the array, in the array's microphone order)"
            )
        if expected_rate is not None and int(rate) != int(expected_rate):
            raise ValueError(
                f"replay recording {self.path}: sample rate is {rate} Hz, expected {expected_rate} Hz "
                "(resample it first, e.g. `sox in.wav -r 16000 out.wav`)"
            )
        if int(rate) < min_rate:
            raise ValueError(
                f"replay recording {self.path}: sample rate {rate} Hz is too low, at least {min_rate} Hz is needed "
                "(the localizer's analysis band reaches 6000 Hz)"
            )
        _to_block_dtype(data[:1])  # fail now on unsupported sample types
        self._data = data
        self._file_rate = int(rate)
        self._rate = int(resample_to) if resample_to else int(rate)
        g = gcd(self._rate, self._file_rate)
        self._up, self._down = self._rate // g, self._file_rate // g
        # resample_poly's default filter: 10 zero crossings on each side of the slower rate, in input samples
        self._margin = 10 * max(self._up, self._down) // self._up + self._down + 2
        self._pos = 0
        self._clock = clock
        self.start_time = float(start_time)

    @property
    def sample_rate(self) -> int:
        return self._rate

    @property
    def n_channels(self) -> int:
        return int(self._data.shape[1])

    @property
    def file_rate(self) -> int:
        """Sample rate of the file (Hz); :attr:`sample_rate` is the rate delivered."""
        return self._file_rate

    @property
    def n_samples(self) -> int:
        """Samples per channel in the whole recording, at the rate delivered."""
        return -(-int(self._data.shape[0]) * self._up // self._down)

    @property
    def duration(self) -> float:
        """Length of the recording (s)."""
        return self.n_samples / self._rate

    @property
    def position(self) -> int:
        """Index of the next sample to be read."""
        return self._pos

    def seek(self, seconds: float) -> None:
        """Continue reading at ``seconds`` from the start of the file."""
        idx = int(round(seconds * self._rate))
        if not 0 <= idx <= self.n_samples:
            raise ValueError(f"seconds: expected 0..{self.duration:.3f} s, got {seconds}")
        self._pos = idx

    def read(self, n_samples: int) -> AudioBlock:
        n = int(n_samples)
        if n <= 0 or n != n_samples:
            raise ValueError(f"n_samples: expected a positive integer, got {n_samples!r}")
        left = self.n_samples - self._pos
        if left < n:
            self._pos = self.n_samples
            raise EndOfAudio(f"replay recording {self.path}: end reached ({left} samples left, {n} requested)")
        block = AudioBlock(
            samples=self._samples(self._pos, n),
            sample_rate=self._rate,
            timestamp=self.start_time + self._pos / self._rate,
        )
        self._pos += n
        if self._clock is not None:
            self._clock.sleep(n / self._rate)
        return block

    def _samples(self, pos: int, n: int) -> np.ndarray:
        """Samples ``pos .. pos + n`` (at the delivered rate), (channels, n)."""
        if self._up == self._down:
            return _to_block_dtype(self._data[pos:pos + n].T)
        from scipy.signal import resample_poly

        up, down, total = self._up, self._down, int(self._data.shape[0])
        # input span: starts on a multiple of `down` (so output k of the span is output start * up / down + k
        # of the whole file) a margin before the first input sample needed, ends a margin after the last one
        start = max(0, (pos * down // up - self._margin) // down * down)
        stop = min(total, -(-(pos + n) * down // up) + self._margin)
        x = _to_block_dtype(self._data[start:stop].T)
        y = resample_poly(np.asarray(x, np.float64), up, down, axis=1)
        k = pos - start * up // down
        out = y[:, k:k + n]
        if x.dtype == np.int16:
            return np.clip(np.round(out), -32768, 32767).astype(np.int16)
        return out

    def close(self) -> None:
        self._data = self._data[:0]  # drop the memory map


@dataclass(frozen=True)
class DriveCommand:
    """One command the dry-run drive received: time (s), requested body twist and wheel speeds (rad/s)."""

    time: float
    twist: tuple[float, float, float]
    wheel_speeds: tuple[float, float, float]


class DryRunDrive(DriveBase):
    """A drive that moves nothing: logs each command and integrates ideal wheel odometry.

    The wheels follow the (saturated) command instantly and without slip, so
    ``odometry()`` is what a perfect base would report at ``clock.now()``. It
    never reports a bump or a stall.
    """

    def __init__(self, clock: Clock, params: OmniDriveParams = OmniDriveParams()) -> None:
        self.clock = clock
        self.params = params
        self.commands: list[DriveCommand] = []
        self._angles = np.zeros(3)
        self._speeds = np.zeros(3)
        self._t = clock.now()

    def _advance(self) -> float:
        now = self.clock.now()
        self._angles = self._angles + self._speeds * max(0.0, now - self._t)
        self._t = now
        return now

    def set_twist(self, vx: float, vy: float, omega: float) -> None:
        twist = (float(vx), float(vy), float(omega))
        if not all(math.isfinite(v) for v in twist):
            raise ValueError(f"twist: expected finite (vx m/s, vy m/s, omega rad/s), got {twist}")
        now = self._advance()
        self._speeds = twist_to_wheels(twist, self.params)
        self.commands.append(DriveCommand(now, twist, tuple(float(w) for w in self._speeds)))
        log.info("dry-run drive t=%.2f s: twist vx=%.3f m/s vy=%.3f m/s omega=%.3f rad/s", now, *twist)

    def stop(self) -> None:
        if not self._speeds.any() and self.commands and self.commands[-1].twist == (0.0, 0.0, 0.0):
            return  # already stopped: keep the command log short
        now = self._advance()
        self._speeds = np.zeros(3)
        self.commands.append(DriveCommand(now, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)))
        log.info("dry-run drive t=%.2f s: stop", now)

    @property
    def twist(self) -> np.ndarray:
        """Body twist actually executed (after wheel-speed saturation), robot frame."""
        return forward_kinematics(self._speeds, self.params)

    def odometry(self) -> WheelOdometry:
        now = self._advance()
        return WheelOdometry(now, self._angles.copy(), self._speeds.copy())

    def status(self) -> DriveStatus:
        return DriveStatus()

    def close(self) -> None:
        self.stop()
