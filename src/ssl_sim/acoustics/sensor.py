"""The microphone/ADC chain of the real array: sensitivity, self-noise, gain mismatch,
two capture devices with their own start offset and clock drift, 16-bit quantisation.

Calibration: ``sensitivity_dbfs`` is the digital RMS (dB re full scale 1.0, i.e. int16 32768)
produced by a 1 Pa RMS (94 dB SPL) sound: -26 dBFS, typical of electret capsules behind a
USB codec (the paper's PlayStation Eye microphones). Digital value ``x = p * 10^(S/20)``
per pascal, so 62.5 dB SPL (26.7 mPa) gives RMS 1.34e-3 = 43.8 LSB.

Timing: device ``d`` (channel group) takes its sample ``n`` at true time
``(n + offset_d + drift_ppm_d * 1e-6 * n) / fs``; non-integer instants are read from the
pressure signal by windowed-sinc interpolation (the real array is two 4-channel USB devices).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

from .signals import TimeKeyedNoise

P_REF = 20e-6  # Pa


class ClippingWarning(UserWarning):
    """A listen step drove the simulated ADC past full scale."""


@dataclass(frozen=True)
class SensorConfig:
    """Microphone + ADC model. Levels in dB SPL (re 20 uPa), gains in dB, timing in samples/ppm."""

    fs: int = 16000
    sensitivity_dbfs: float = -26.0
    self_noise_db_spl: float = 32.0          # equivalent input noise, flat spectrum, per channel
    gain_mismatch_db: float = 0.5            # std of the fixed per-channel gain error
    device_channels: tuple[tuple[int, ...], ...] = ((0, 1, 2, 3), (4, 5, 6, 7))
    device_offset_samples: tuple[float, ...] = (0.0, 0.0)   # start offset of each device
    clock_drift_ppm: tuple[float, ...] = (0.0, 0.0)         # sample-clock error of each device
    bits: int | None = 16                    # None: no quantisation
    output: str = "int16"                    # "int16" or "float" (float32 in [-1, 1))

    def __post_init__(self) -> None:
        if self.fs <= 0:
            raise ValueError(f"SensorConfig.fs: expected a positive rate in Hz, got {self.fs}")
        if self.output not in ("int16", "float"):
            raise ValueError(f"SensorConfig.output: expected 'int16' or 'float', got {self.output!r}")
        if self.output == "int16" and self.bits != 16:
            raise ValueError("SensorConfig.bits: int16 output needs bits=16")
        if self.bits is not None and not 2 <= self.bits <= 32:
            raise ValueError(f"SensorConfig.bits: expected 2..32 or None, got {self.bits}")
        n_dev = len(self.device_channels)
        for name in ("device_offset_samples", "clock_drift_ppm"):
            if len(getattr(self, name)) != n_dev:
                raise ValueError(f"SensorConfig.{name}: expected {n_dev} values (one per device), got {getattr(self, name)!r}")
        if self.gain_mismatch_db < 0:
            raise ValueError(f"SensorConfig.gain_mismatch_db: expected >= 0, got {self.gain_mismatch_db}")

    @property
    def pa_to_digital(self) -> float:
        """Digital full-scale units per pascal."""
        return 10 ** (self.sensitivity_dbfs / 20)


class Sensor:
    """Digitises pressure signals like the real array. Deterministic given ``seed``: the gain errors
    are fixed per instance and the self-noise is a function of absolute sample index."""

    HALF_TAPS = 16

    def __init__(self, config: SensorConfig, n_channels: int, seed: int, loop_chunks: int | None = None) -> None:
        chans = sorted(c for grp in config.device_channels for c in grp)
        if chans != list(range(n_channels)):
            uniform = len(set(config.device_offset_samples)) == 1 and len(set(config.clock_drift_ppm)) == 1
            if not uniform:
                raise ValueError(
                    f"SensorConfig.device_channels: must partition channels 0..{n_channels - 1} when the devices' "
                    f"timing differs, got {config.device_channels}"
                )
            # Other microphone counts (tests, other arrays): one device with the common timing.
            config = replace(config, device_channels=(tuple(range(n_channels)),),
                             device_offset_samples=config.device_offset_samples[:1],
                             clock_drift_ppm=config.clock_drift_ppm[:1])
        self.config = config
        self.n_channels = n_channels
        rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x6A1E])
        self.gain_db = rng.normal(0.0, config.gain_mismatch_db, n_channels) if config.gain_mismatch_db > 0 else np.zeros(n_channels)
        self.gain = 10 ** (self.gain_db / 20)
        self.noise = TimeKeyedNoise(seed, stream=0x5E1F, channels=n_channels, loop_chunks=loop_chunks)
        self.noise_rms_pa = P_REF * 10 ** (config.self_noise_db_spl / 20)

    def device_timing(self, n0: int, n: int) -> list[tuple[tuple[int, ...], np.ndarray]]:
        """Per device: its channels and the true sampling instants (fractional samples) of samples ``n0 .. n0+n-1``."""
        c = self.config
        idx = n0 + np.arange(n, dtype=np.float64)
        return [(tuple(ch), idx + off + drift * 1e-6 * idx)
                for ch, off, drift in zip(c.device_channels, c.device_offset_samples, c.clock_drift_ppm)]

    def timing_exact(self) -> bool:
        c = self.config
        return all(float(o).is_integer() for o in c.device_offset_samples) and not any(c.clock_drift_ppm)

    @classmethod
    def interpolate(cls, x: np.ndarray, x_start: int, times: np.ndarray) -> np.ndarray:
        """Values of band-limited signals ``x`` (ch, L) (sample 0 at absolute index ``x_start``)
        at fractional absolute instants ``times`` (n,), Hann-windowed sinc, ``HALF_TAPS`` each side."""
        h = cls.HALF_TAPS
        rel = times - x_start
        base = np.floor(rel).astype(np.int64)
        offs = np.arange(-h + 1, h + 1)
        pos = base[:, None] + offs
        if pos.min() < 0 or pos.max() >= x.shape[1]:
            raise ValueError("Sensor.interpolate: instants outside the rendered range")
        d = pos - rel[:, None]
        w = np.sinc(d) * (0.5 + 0.5 * np.cos(np.pi * d / h))
        return np.einsum("cnt,nt->cn", x[:, pos], w)

    def digitise(self, pressure: np.ndarray, n0: int) -> np.ndarray:
        """Pressure (n_channels, n) Pa at the true sampling instants -> ADC output."""
        c = self.config
        n = pressure.shape[1]
        p = pressure + self.noise_rms_pa * self.noise.samples(n0, n)
        x = p * (c.pa_to_digital * self.gain)[:, None]
        if c.bits is not None:
            q = 2.0 ** (c.bits - 1)
            xi = np.round(x * q)
            clipped = (xi > q - 1) | (xi < -q)
            if np.any(clipped):
                chans = np.flatnonzero(clipped.any(axis=1)).tolist()
                warnings.warn(
                    f"simulated ADC clipped {int(clipped.sum())} samples on channels {chans}: the sound exceeds "
                    f"full scale ({94 - c.sensitivity_dbfs:.0f} dB SPL peak at sensitivity {c.sensitivity_dbfs} dBFS/Pa); "
                    "lower the source level_db_spl or the sensor sensitivity",
                    ClippingWarning, stacklevel=3,
                )
            xi = np.clip(xi, -q, q - 1)
            if c.output == "int16":
                return xi.astype(np.int16)
            return (xi / q).astype(np.float32)
        return np.clip(x, -1.0, 1.0).astype(np.float32)
