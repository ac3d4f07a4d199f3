"""Stationary-noise suppression for SRP-PHAT: a per-bin noise floor by minimum statistics.

PHAT gives every time-frequency bin the same weight, so a steady broadband
noise (a pump, a generator) that fills every bin all the time outweighs an
intermittent voice that fills few. Weighting each bin by how far its power
stands above the noise floor, ``w = clip(1 - g N / P, 0, 1)``, keeps the voice
bins and silences the steady ones. The floor ``N`` is the minimum, over the last
few seconds, of the per-chunk mean of the channel-averaged power, corrected for
the minimum's downward bias (Martin's minimum statistics, simplified): speech has
gaps within a second or two, steady noise does not.
"""
from __future__ import annotations

import numpy as np


class NoiseFloor:
    """Tracks a per-bin noise floor over chunks of frames and turns band power into bin weights."""

    def __init__(self, memory_chunks: int, over_subtraction: float = 3.0, bias: float = 1.5):
        if memory_chunks < 1:
            raise ValueError(f"noise floor memory must be >= 1 chunk, got {memory_chunks}")
        # bias: the minimum of ~10 chunk means of a steady noise sits ~1/1.5 below its mean
        self.over_subtraction = over_subtraction * bias
        self._memory = memory_chunks
        self._means: np.ndarray | None = None   # ring buffer (memory_chunks, bins) of chunk means
        self._count = 0                         # chunks seen

    def reset(self) -> None:
        self._means, self._count = None, 0

    def weights(self, power: np.ndarray) -> np.ndarray:
        """Weights in [0, 1] for one chunk of band power ``(frames, bins)``; updates the floor first."""
        return self.gains(power, self.update(power))

    def update(self, power: np.ndarray) -> np.ndarray:
        """Take one chunk of band power ``(frames, bins)`` into the floor; returns the floor ``(bins,)``."""
        return self.update_mean(power.mean(axis=0))

    def update_mean(self, mean: np.ndarray) -> np.ndarray:
        """``update`` from the chunk's mean band power over its frames ``(bins,)``."""
        if self._means is None or self._means.shape[1:] != mean.shape:
            self._means, self._count = np.empty((self._memory, *mean.shape), mean.dtype), 0
        self._means[self._count % self._memory] = mean
        self._count += 1
        return self._means[: min(self._count, self._memory)].min(axis=0)

    def gains(self, power: np.ndarray, floor: np.ndarray) -> np.ndarray:
        """``w = clip(1 - g N / P, 0, 1)`` for band power ``power`` and a floor broadcasting against it
        (several floors' chunks at once: ``(k, frames, bins)`` with ``(k, 1, bins)``)."""
        return np.clip(1.0 - self.over_subtraction * floor / np.maximum(power, np.finfo(power.dtype).tiny), 0.0, 1.0)
