"""Hardware abstraction layer: the small interfaces the rescue behaviour talks to.

Backends: simulation ones live in ``ssl_sim`` (MuJoCo robot + acoustic
simulation), real ones in ``robot.hardware`` (pyserial drive, USB audio
capture), and file replay in ``robot.replay``. Swapping the backend is the only
difference between a simulated and a real rescue.

Frames: twists are in the robot (body) frame, +x forward, +y left, +z up;
wheel quantities follow ``robot.kinematics`` (wheel order and sign).
"""
from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np


class EndOfAudio(EOFError):
    """A finite audio source (a recording) is exhausted. The one signal that ends a mission as "audio ended": a
    plain ``EOFError`` from elsewhere (a truncated gzip model file) is a failure, never the end of the audio."""


@dataclass(frozen=True)
class AudioBlock:
    """``samples``: (n_channels, n_samples), int16 or float; ``timestamp``: capture time (s) of the first sample."""

    samples: np.ndarray
    sample_rate: int
    timestamp: float


class AudioSource(ABC):
    """A multichannel audio input (e.g. the 8-mic cube array)."""

    @property
    @abstractmethod
    def sample_rate(self) -> int: ...

    @property
    @abstractmethod
    def n_channels(self) -> int: ...

    @abstractmethod
    def read(self, n_samples: int) -> AudioBlock:
        """Block until ``n_samples`` per channel are captured and return them.

        Raises ``EndOfAudio`` (an ``EOFError``) when a finite source (a file) is exhausted."""

    def flush(self) -> None:  # noqa: B027 - optional hook
        """Discard audio captured but not yet read (e.g. recorded while driving).

        A live source buffers continuously; the rescue behaviour calls this
        after stopping so that it listens to fresh, motor-noise-free audio.
        Finite sources (replay) keep their position: default is a no-op."""

    def resync(self, slip_samples: float | None = None) -> None:  # noqa: B027 - optional hook
        """Re-measure the alignment between capture devices now (the microphone health monitor saw them
        slip, by ``slip_samples`` if it measured it: positive = the second device later). Single-device and
        finite sources have nothing to align: default is a no-op."""

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release the device."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass(frozen=True)
class WheelOdometry:
    """Cumulative wheel rotation (rad) and wheel angular speed (rad/s) for the 3 wheels at ``timestamp`` (s)."""

    timestamp: float
    wheel_angles: np.ndarray
    wheel_speeds: np.ndarray


@dataclass(frozen=True)
class DriveStatus:
    """Safety state of the drive base."""

    bumper: bool = False          # a collision/contact is sensed now
    stalled: bool = False         # wheels commanded but not turning
    faults: tuple[str, ...] = field(default_factory=tuple)  # e.g. ("watchdog", "overcurrent")
    yaw_rate: float | None = None  # rad/s about the robot's +z (CCW positive) from a gyro, the mean over the
    #                                drive's last completed gyro window (50 ms); its residual bias is the odometry's
    #                                to learn (robot.odometry); None: no gyro
    ranges: tuple[float, ...] | None = None  # m, one per sensor of ``robot.ranging.RangeLayout``: from the sensor
    #                                along its ray to the first surface, inf when nothing is within its maximum
    #                                range; None: no range sensors

    @property
    def ok(self) -> bool:
        return not (self.bumper or self.stalled or self.faults)


class DriveBase(ABC):
    """The omni-drive base."""

    @abstractmethod
    def set_twist(self, vx: float, vy: float, omega: float) -> None:
        """Command a body twist (m/s, m/s, rad/s, robot frame); held until changed or stopped.

        Hardware backends hold it only while the caller refreshes it (``SerialDrive``: within 0.5 s), so a
        hung control loop stops the robot: call it every control period while moving."""

    @abstractmethod
    def stop(self) -> None:
        """Stop all wheels at once."""

    @abstractmethod
    def odometry(self) -> WheelOdometry: ...

    @abstractmethod
    def status(self) -> DriveStatus: ...

    def close(self) -> None:  # noqa: B027 - optional hook
        """Stop and release the link."""

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class Clock(ABC):
    """Time as the behaviour sees it: wall time on hardware, simulated time in simulation."""

    @abstractmethod
    def now(self) -> float: ...

    @abstractmethod
    def sleep(self, seconds: float) -> None:
        """Let ``seconds`` pass (the drive keeps executing its last command)."""


class WallClock(Clock):
    def now(self) -> float:
        return time.monotonic()

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            time.sleep(seconds)


class ManualClock(Clock):
    """A clock that only moves when told: ``sleep`` advances it at once (replay, tests, dry runs)."""

    def __init__(self, start: float = 0.0) -> None:
        self._t = float(start)

    def now(self) -> float:
        return self._t

    def sleep(self, seconds: float) -> None:
        if seconds > 0:
            self._t += float(seconds)

    def advance(self, seconds: float) -> None:
        """Same as ``sleep``: let ``seconds`` (>= 0) pass."""
        if seconds < 0:
            raise ValueError(f"seconds must be >= 0, got {seconds}")
        self._t += float(seconds)


def as_float_audio(samples: np.ndarray, dtype: type = np.float64) -> np.ndarray:
    """int16 -> float in [-1, 1); float passes through; as ``dtype`` (float64 or float32)."""
    a = np.asarray(samples)
    if a.dtype == np.int16:
        return np.multiply(a, 1 / 32768.0, dtype=dtype)
    return a.astype(dtype, copy=False)
