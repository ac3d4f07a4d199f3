"""Hearing while the robot drives: a move's control loop paced by the audio stream, its audio heard in windows.

A drive that listens reads one control tick of audio instead of sleeping (``Motion.translate(pace=...)``). On the
robot the read blocks until the samples are captured, in the simulator it advances the world: either way the
control loop keeps its period and no audio captured while driving is dropped. Every ``window_s`` of audio is one
listen through the listener's own chain (``Listener.hear``: the localizer with the drive's noise suppressed from
the wheels' mean speed over the window, ``ssl_core.ego_noise``; voice evidence; the tracker), at the pose
interpolated at the window's middle: at 0.25 m/s a 1 s window moves the array 0.25 m, so the pose at either end
would be 0.125 m off. Audio left over at the end of a move (less than a window) is not heard.

Frames: poses (x m, y m, yaw rad) in the odometry frame; the listen's evidence in the array frame.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from robot.hal import AudioBlock, Clock
from robot.listening import Listen, Listener
from robot.odometry import pose_at

__all__ = ["DriveHearing", "WindowHandler"]

#: ``on_window(listen, trajectory)``: one window heard while driving; ``trajectory`` (k, 4) rows (time s, x m,
#: y m, yaw rad) over the window. Returns whether the drive goes on (False ends the move).
WindowHandler = Callable[[Listen, np.ndarray], bool]


class DriveHearing:
    """``pace`` for ``Motion.translate``: reads the tick's audio and hears every full ``window_s`` of it.

    ``pose()``: the robot's odometry pose now; ``min_power``: as ``Listener.listen``'s. Call ``start()`` before a
    move (discards audio captured while standing, resets the window)."""

    def __init__(self, listener: Listener, clock: Clock, pose: Callable[[], np.ndarray], window_s: float,
                 min_power: float, on_window: WindowHandler) -> None:
        if not (math.isfinite(window_s) and window_s > 0):
            raise ValueError(f"window_s: expected a finite length > 0 s, got {window_s!r}")
        self.listener, self.clock, self.pose = listener, clock, pose
        self.window_s, self.min_power, self.on_window = float(window_s), float(min_power), on_window
        self.windows = 0                     # windows heard while driving (all moves)
        self.stopped = False                 # the last window heard ended the move (``on_window`` said so)
        self._chunks: list[AudioBlock] = []
        self._rows: list[tuple[float, float, float, float]] = []
        self._wheels: list[np.ndarray] = []

    def start(self) -> None:
        """A move begins: audio captured before it is not part of its windows."""
        self.listener.audio.flush()
        self._chunks, self._rows, self._wheels = [], [], []
        self.stopped = False

    def pace(self, seconds: float) -> bool:
        """Read ``seconds`` of audio (the control tick's wait); False when the window it completed says stop."""
        audio = self.listener.audio
        n = max(1, int(round(seconds * audio.sample_rate)))
        self._row()
        w = self.listener.wheel_speeds()
        t0 = self.clock.now()
        block = audio.read(n)
        lag = n / audio.sample_rate - (self.clock.now() - t0)
        if lag > 1e-9:   # a source that does not let its block's time pass (a file): the tick still takes it
            self.clock.sleep(lag)
        self._chunks.append(block)
        if w is not None:
            self._wheels.append(w)
        got = sum(c.samples.shape[1] for c in self._chunks)
        if got < self.window_s * audio.sample_rate - 0.5:
            return True
        self._row()
        listen = self._hear()
        trajectory = np.array(self._rows)
        self._chunks, self._rows, self._wheels = [], [], []
        self.windows += 1
        self.stopped = not self.on_window(listen, trajectory)
        return not self.stopped

    def _row(self) -> None:
        t = float(self.clock.now())
        if self._rows and t <= self._rows[-1][0]:
            return
        x, y, yaw = (float(v) for v in self.pose())
        self._rows.append((t, x, y, yaw))

    def _hear(self) -> Listen:
        first = self._chunks[0]
        block = AudioBlock(np.concatenate([c.samples for c in self._chunks], axis=1), first.sample_rate,
                           first.timestamp)
        trajectory = np.array(self._rows)     # clock times: the window from its first read to its last
        pose = tuple(pose_at(trajectory, 0.5 * (trajectory[0, 0] + trajectory[-1, 0])))
        wheels = np.mean(self._wheels, axis=0) if self._wheels else None
        return self.listener.hear(block, self.min_power, time=float(trajectory[-1, 0]), pose=pose,
                                  wheel_speeds=wheels)
