"""Ego-noise suppression: the robot's own drive motors, heard by the array while the wheels turn.

Methods, driven by side information the robot has every control tick (the wheel speeds, the motors' mounting):

* **Spatial (cone).** While the wheels turn the search skips directions within ``exclude_deg`` of a motor
  or its floor image (far below any caller the robot can hear).
* **Spatial (lag mask).** The motors sit at fixed positions in the array frame (a few tens of cm below
  the array, well inside its near field), so each motor's TDOA on every microphone pair is a constant.
  Like the multi-source search masks a found source, the GCC of every pair is zeroed within half a main
  lobe of each motor's near-field TDOA (and of its floor image's: the floor is a few cm under the motor
  and reflects it almost as loudly) before the SRP search. Only while the wheels turn.
* **Spectral (template).** A calibration records, with no one talking, the channel-mean power spectral
  density of the drive's noise at the array at a series of wheel speeds (:class:`EgoNoiseTemplate`). At run
  time the noise PSD of each motor is the template at the nearest calibrated speed, its frequency axis
  stretched by the speed ratio (the gear-mesh tone and its harmonics move with the speed) and its level
  scaled by it, divided among the three motors of the calibration; each time-frequency bin is weighted
  ``clip(1 - g N / P, 0, 1)`` (``P`` the bin's channel-mean power, ``N`` the predicted noise power,
  ``g`` the over-subtraction), as :mod:`ssl_core.noise` does for a steady noise floor.

The template file (``.npz``, :meth:`EgoNoiseTemplate.save`): ``format`` = ``"ssl-ego-noise-template/1"``,
``fs`` (Hz), ``freqs_hz`` (F,), ``speeds_rad_s`` (K,) (|wheel speed|, all three wheels together),
``psd`` (K, F) one-sided channel-mean PSD in full-scale^2/Hz (full scale = 1.0 for float audio, 32768 for
int16), ``level_dbfs`` (K,) the band level in dB re a full-scale sine, ``channels`` (the number of
microphones averaged). Speeds in rad/s at the wheel, frequencies in Hz.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import signal as ss

from ssl_core.geometry import ArrayGeometry

TEMPLATE_FORMAT = "ssl-ego-noise-template/1"
FULL_SCALE_SINE_MS = 0.5  # mean square of a full-scale sine


@dataclass(frozen=True)
class EgoNoiseTemplate:
    """Channel-mean PSD of the drive's noise at the array per wheel speed (see the module docstring)."""

    fs: int
    freqs_hz: np.ndarray = field(repr=False)
    speeds_rad_s: np.ndarray
    psd: np.ndarray = field(repr=False)
    level_dbfs: np.ndarray
    channels: int = 8

    def __post_init__(self) -> None:
        f, s, p = (np.asarray(v, float) for v in (self.freqs_hz, self.speeds_rad_s, self.psd))
        if not (isinstance(self.fs, (int, np.integer)) and self.fs > 0):
            raise ValueError(f"EgoNoiseTemplate.fs: expected a positive integer sample rate (Hz), got {self.fs!r}")
        if f.ndim != 1 or f.size < 2 or np.any(np.diff(f) <= 0):
            raise ValueError(f"EgoNoiseTemplate.freqs_hz: expected >= 2 increasing frequencies (Hz), shape {f.shape}")
        if s.ndim != 1 or s.size < 1 or np.any(s <= 0) or np.any(np.diff(s) <= 0):
            raise ValueError("EgoNoiseTemplate.speeds_rad_s: expected >= 1 increasing positive wheel speeds (rad/s)")
        if p.shape != (s.size, f.size) or not np.all(np.isfinite(p)) or np.any(p < 0):
            raise ValueError(f"EgoNoiseTemplate.psd: expected finite non-negative (speeds, freqs) = "
                             f"{(s.size, f.size)}, got shape {p.shape}")
        if np.asarray(self.level_dbfs).shape != s.shape:
            raise ValueError(f"EgoNoiseTemplate.level_dbfs: expected one level per speed, shape {s.shape}")
        for name, v in (("freqs_hz", f), ("speeds_rad_s", s), ("psd", p)):
            object.__setattr__(self, name, v)
        object.__setattr__(self, "level_dbfs", np.asarray(self.level_dbfs, float))

    @classmethod
    def from_recordings(cls, speeds_rad_s, recordings, fs: int, nperseg: int = 512,
                        band_hz: tuple[float, float] = (300.0, 6000.0)) -> "EgoNoiseTemplate":
        """Template from recordings ``(channels, samples)`` (float, full scale 1) of the drive alone, one per
        wheel speed (rad/s, all three wheels at that magnitude); Welch PSD with ``nperseg``-sample Hann frames."""
        speeds = np.abs(np.asarray(speeds_rad_s, float))
        recs = list(recordings)
        if len(recs) != speeds.size:
            raise ValueError(f"from_recordings: {len(recs)} recordings for {speeds.size} speeds")
        order = np.argsort(speeds)
        psds, levels = [], []
        for k in order:
            x = np.asarray(recs[k], float)
            if x.ndim != 2 or x.shape[1] < nperseg:
                raise ValueError(f"from_recordings: recording {k} must be (channels, >= {nperseg} samples), "
                                 f"got shape {x.shape}")
            f, p = ss.welch(x, fs=fs, window="hann", nperseg=nperseg, axis=-1)
            p = p.mean(axis=0)
            psds.append(p)
            band = (f >= band_hz[0]) & (f <= band_hz[1])
            ms = float(np.trapezoid(p[band], f[band]))
            levels.append(10 * np.log10(max(ms, 1e-30) / FULL_SCALE_SINE_MS))
        return cls(int(fs), f, speeds[order], np.array(psds), np.array(levels), int(np.asarray(recs[0]).shape[0]))

    def save(self, path: str | Path) -> None:
        """Write the documented ``.npz`` file (module docstring)."""
        np.savez(Path(path), format=TEMPLATE_FORMAT, fs=self.fs, freqs_hz=self.freqs_hz,
                 speeds_rad_s=self.speeds_rad_s, psd=self.psd, level_dbfs=self.level_dbfs, channels=self.channels)

    @classmethod
    def load(cls, path: str | Path) -> "EgoNoiseTemplate":
        path = Path(path)
        try:
            z = np.load(path, allow_pickle=False)
        except (OSError, ValueError) as e:
            raise ValueError(f"{path}: not an ego-noise template file ({e})") from None
        fmt = str(z["format"]) if "format" in z else ""
        if fmt != TEMPLATE_FORMAT:
            raise ValueError(f"{path}: format {fmt!r}, expected {TEMPLATE_FORMAT!r}")
        missing = {"fs", "freqs_hz", "speeds_rad_s", "psd", "level_dbfs", "channels"} - set(z.files)
        if missing:
            raise ValueError(f"{path}: missing fields {sorted(missing)}")
        return cls(int(z["fs"]), z["freqs_hz"], z["speeds_rad_s"], z["psd"], z["level_dbfs"], int(z["channels"]))

    def noise_psd(self, wheel_speeds, freqs_hz: np.ndarray) -> np.ndarray:
        """Predicted channel-mean PSD (full-scale^2/Hz) at ``freqs_hz`` of the drive with its wheels at
        ``wheel_speeds`` (3,) rad/s: per motor a third of the template at the nearest calibrated speed ``s_k``,
        frequencies scaled by ``s / s_k`` and the density by ``s / s_k`` (the power then scales as
        ``(s / s_k)^2``, the calibration's own law between neighbouring speeds). Zero for a stopped wheel."""
        out = np.zeros(len(freqs_hz))
        for s in np.abs(np.asarray(wheel_speeds, float)).ravel():
            if s <= 0:
                continue
            k = int(np.argmin(np.abs(np.log(self.speeds_rad_s / s))))
            a = s / self.speeds_rad_s[k]
            out += a * np.interp(np.asarray(freqs_hz) / a, self.freqs_hz, self.psd[k], right=0.0) / 3.0
        return out


@dataclass(frozen=True)
class EgoNoiseConfig:
    """Where the drive's motors are and which suppression to use.

    ``motor_positions``: centres of the three gear motors in the ARRAY frame (m), from the robot's
    mechanical drawing (``robot.config_values`` / the mount config), not measured acoustically.
    ``floor_below_m``: height of the array centre above the floor (m; the motors' floor images are
    masked too), None: no images. ``spatial``/``spectral``: the two methods (module docstring). The spectral
    method alone is the default: measured (experiments/listen_while_driving.py, docs/design/ego_noise.md) it
    brings the median error while driving at 0.1-0.3 m/s back to that of a silent drive, while the lag mask,
    alone or with it, also removes lags the caller shares with a motor on some pairs and costs degrees.
    ``over_subtraction``: ``g`` of the spectral weights. ``exclude_deg``: while the wheels turn the search skips
    directions within this angle of a motor or floor image (30: two front motors turning together make an SRP
    peak between them, 21 deg from each; docs/design/ego_noise.md). ``min_speed``: wheel speeds (rad/s) below this
    count as standing (no suppression at all: a parked robot hears exactly as without it)."""

    motor_positions: tuple[tuple[float, float, float], ...]
    floor_below_m: float | None = None
    spatial: bool = False
    spectral: bool = True
    # g: 6 and 8 tracked the caller within 10 deg in 92-94 % of 1 s windows at 0.1-0.3 m/s (three drives each),
    # 3-4 in 67-94 %: PHAT counts every bin the weights let through at full coherence, and the motors'
    # residue in a pause of her voice is one fixed direction (docs/design/ego_noise.md).
    over_subtraction: float = 6.0
    exclude_deg: float = 30.0
    min_speed: float = 0.05

    def __post_init__(self) -> None:
        m = np.asarray(self.motor_positions, float)
        if m.ndim != 2 or m.shape[1] != 3 or m.shape[0] < 1 or not np.all(np.isfinite(m)):
            raise ValueError(f"EgoNoiseConfig.motor_positions: expected finite (n_motors, 3) m in the array frame, "
                             f"got shape {m.shape}")
        object.__setattr__(self, "motor_positions", tuple(tuple(float(v) for v in p) for p in m))
        if self.floor_below_m is not None and not self.floor_below_m > 0:
            raise ValueError(f"EgoNoiseConfig.floor_below_m: expected > 0 m or None, got {self.floor_below_m}")
        if not self.over_subtraction > 0:
            raise ValueError(f"EgoNoiseConfig.over_subtraction: expected > 0, got {self.over_subtraction}")
        if not 0 <= self.exclude_deg < 90:
            raise ValueError(f"EgoNoiseConfig.exclude_deg: expected 0 <= deg < 90, got {self.exclude_deg}")
        if not self.min_speed >= 0:
            raise ValueError(f"EgoNoiseConfig.min_speed: expected >= 0 rad/s, got {self.min_speed}")


class EgoNoiseSuppressor:
    """The two methods for one array, STFT layout and band (used by :class:`ssl_core.localizer.Localizer`).

    ``template`` is needed by the spectral method (ignored if ``config.spectral`` is off)."""

    def __init__(self, geometry: ArrayGeometry, config: EgoNoiseConfig, template: EgoNoiseTemplate | None = None,
                 sound_speed: float = 343.0) -> None:
        if config.spectral and template is None:
            raise ValueError("EgoNoiseSuppressor: the spectral method needs a template (EgoNoiseTemplate; "
                             "ssl-robot calibrate-ego-noise writes one) or EgoNoiseConfig(spectral=False)")
        self.geometry, self.config, self.template = geometry, config, template
        src = np.asarray(config.motor_positions, float)
        if config.floor_below_m is not None:  # floor image: z -> -2 h - z (floor at z = -h in the array frame)
            img = src.copy()
            img[:, 2] = -2 * config.floor_below_m - src[:, 2]
            src = np.vstack([src, img])
        self._sources = src
        arrival = np.linalg.norm(src[:, None, :] - geometry.positions[None], axis=-1) / sound_speed  # (S, M)
        p = geometry.pairs
        #: near-field TDOAs t_i - t_j (s) of every masked source, (pairs, sources)
        self.tdoas = (arrival[:, p[:, 0]] - arrival[:, p[:, 1]]).T
        self._mask_cache: dict = {}

    def moving(self, wheel_speeds) -> bool:
        """Whether any wheel turns at ``min_speed`` or faster (else nothing is suppressed)."""
        return wheel_speeds is not None and bool(np.any(np.abs(np.asarray(wheel_speeds, float))
                                                       >= self.config.min_speed))

    def excluded(self, directions: np.ndarray) -> np.ndarray:
        """Boolean (n,): unit ``directions`` (n, 3, array frame) within ``exclude_deg`` of a motor (or floor
        image) seen from the array centre, where the search may not place a source while the wheels turn."""
        if self.config.exclude_deg <= 0:
            return np.zeros(len(directions), bool)
        m = self._sources / np.linalg.norm(self._sources, axis=1, keepdims=True)
        return (np.asarray(directions) @ m.T).max(axis=1) >= np.cos(np.deg2rad(self.config.exclude_deg))

    def lag_mask(self, lags_s: np.ndarray, halfwidth_s: float) -> np.ndarray:
        """Boolean (pairs, lags): True where a lag (s) lies within ``halfwidth_s`` of a motor's TDOA."""
        key = (lags_s.size, float(lags_s[0]), float(lags_s[-1]), float(halfwidth_s))
        m = self._mask_cache.get(key)
        if m is None:
            m = (np.abs(lags_s[None, :, None] - self.tdoas[:, None, :]) <= halfwidth_s).any(axis=-1)
            self._mask_cache[key] = m
        return m

    def bin_weights(self, power: np.ndarray, freqs_hz: np.ndarray, wheel_speeds, window: np.ndarray) -> np.ndarray:
        """Spectral weights (frames, bins) in [0, 1] for channel-mean bin powers ``power`` (frames, bins) of
        ``window``-ed rfft frames of full-scale-1 audio at ``freqs_hz``."""
        t = self.template
        # E|X_k|^2 of a stationary noise of one-sided PSD S: S fs sum(w^2) / 2
        noise = t.noise_psd(wheel_speeds, freqs_hz) * t.fs * float(np.sum(np.square(window))) / 2
        g = self.config.over_subtraction
        return np.clip(1.0 - g * noise[None, :] / np.maximum(power, np.finfo(np.float32).tiny), 0.0, 1.0
                       ).astype(np.float32)
