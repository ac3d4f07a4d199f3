"""The robot's own noise: its three gear motors (motor whine, gear mesh, brushes) and omni rollers,
heard by the array a few centimetres above them while the robot drives.

Level (source of the figure): small brushed gear motors are graded by their no-load noise at rated
speed, 55-60 dB(A) "good" and 60-65 dB(A) "qualified" (Guang Dong Lihua Mechatronics, "Understanding
Micro Motor Noise", dcminimotors.com, 2025); such figures are taken 10 cm from the motor by the
usual micro-motor test practice (an assumption: the page does not give the distance). We take 60 dB(A)
at 10 cm at rated speed for one 25 mm gear motor with its wheel rollers, i.e. 40 dB SPL at 1 m
(free-field spreading). It scales as ``20 lg(omega / omega_rated)`` (+6 dB per doubling of speed, the
common rule of thumb for gear noise against pitch-line speed) and is exactly zero below
``min_speed`` (a stopped motor is silent).

Spectrum: half the power in the gear-mesh tone and its 2nd/3rd harmonics (mesh frequency = motor
shaft speed x pinion teeth, the shaft turning ``gear_ratio`` times faster than the wheel; 12-tooth
pinion and 34:1 ratio: 190 rpm at the wheel -> 6460 rpm at the motor, mesh at 1.29 kHz), half
broadband (pink, brush and roller noise). The tone's frequency follows the wheel speed sample by
sample (phase-continuous across blocks). The three motors' tones start at seeded random phases and
their speed-to-frequency factors differ by +-1 % (gear-motor speed tolerance under a speed loop), so
their tones beat instead of adding coherently at one frequency-dependent interference level.

Propagation: each motor is a point source at its position on the robot (the MuJoCo motor geoms) and
reaches the microphones by the room's image sources of order ``ism_order`` (direct path + floor and
wall reflections; the late diffuse tail of so weak and so close a source is ignored), like any
other source of :class:`~ssl_sim.acoustics.AcousticSimulator`; the robot's body does not shadow it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import signal as ss

from .rir import FRAC_HALF_TAPS, early_rir
from .signals import ShapedNoise

P_REF = 20e-6


@dataclass(frozen=True)
class EgoNoiseConfig:
    """Motor/gear/roller noise of the drive (see the module docstring for the sources of the numbers).

    ``level_db_spl_1m``: SPL at 1 m of one motor at ``rated_speed`` (wheel, rad/s). ``min_speed``:
    below this wheel speed (rad/s) a motor is silent. ``tonal_share``: fraction of the power in the mesh
    tone and its harmonics. ``ism_order``: reflection order of the paths to the microphones. ``seed``:
    combined with the acoustic simulation's seed (tone phases, broadband noise)."""

    level_db_spl_1m: float = 40.0   # SPL at 1 m of one motor at rated_speed (dB SPL)
    rated_speed: float = 20.0       # wheel speed (rad/s) at which level_db_spl_1m holds
    min_speed: float = 0.05         # below this wheel speed (rad/s) a motor is silent
    gear_ratio: float = 34.0        # motor turns per wheel turn: the motor shaft turns this much faster
    pinion_teeth: int = 12          # teeth of the motor pinion: mesh tone = shaft rate x teeth
    tonal_share: float = 0.5        # fraction of the power in the mesh tone and its harmonics
    harmonics: tuple[float, ...] = (1.0, 0.5, 0.25)   # amplitudes of mesh harmonics 1, 2, 3
    ism_order: int = 1              # reflection order of the paths from the motors to the microphones
    seed: int = 0                   # combined with the acoustic simulation's seed (tone phases, broadband noise)

    def __post_init__(self) -> None:
        if not np.isfinite(self.level_db_spl_1m) or not -20 <= self.level_db_spl_1m <= 100:
            raise ValueError(f"EgoNoiseConfig.level_db_spl_1m: expected -20..100 dB SPL, got {self.level_db_spl_1m}")
        for name in ("rated_speed", "gear_ratio"):
            if not getattr(self, name) > 0:
                raise ValueError(f"EgoNoiseConfig.{name}: expected > 0, got {getattr(self, name)}")
        if not self.min_speed >= 0:
            raise ValueError(f"EgoNoiseConfig.min_speed: expected >= 0 rad/s, got {self.min_speed}")
        if not 0 <= self.tonal_share <= 1:
            raise ValueError(f"EgoNoiseConfig.tonal_share: expected a fraction in [0, 1], got {self.tonal_share}")
        if self.pinion_teeth < 1 or not 0 <= self.ism_order <= 3:
            raise ValueError("EgoNoiseConfig.pinion_teeth: expected >= 1 and ism_order 0..3")

    def rms_pa_1m(self, wheel_speed) -> np.ndarray:
        """RMS pressure (Pa) at 1 m of one motor turning its wheel at ``wheel_speed`` (rad/s, any sign)."""
        w = np.abs(np.asarray(wheel_speed, float))
        with np.errstate(divide="ignore"):
            p = P_REF * 10 ** (self.level_db_spl_1m / 20) * w / self.rated_speed
        return np.where(w >= self.min_speed, p, 0.0)

    def mesh_hz(self, wheel_speed) -> np.ndarray:
        """Gear-mesh frequency (Hz) at wheel speed (rad/s)."""
        return np.abs(np.asarray(wheel_speed, float)) * self.gear_ratio / (2 * np.pi) * self.pinion_teeth


class EgoNoise:
    """Renders the drive's noise at the microphones of ``sim`` (an AcousticSimulator) for given wheel speeds."""

    def __init__(self, sim, config: EgoNoiseConfig | None = None) -> None:
        self.sim = sim
        self.config = cfg = config or EgoNoiseConfig()
        fs = sim.config.fs
        seed = (int(cfg.seed) * 7919 + int(sim.config.seed)) & 0xFFFFFFFF  # one realisation per simulation seed
        self._noise = [ShapedNoise(fs, seed, "pink", stream=0xE60 + m) for m in range(3)]
        rng = np.random.default_rng([seed, 0xE60])
        self._phase0 = rng.uniform(0, 2 * np.pi, 3)
        self._spread = np.array([0.99, 1.0, 1.01])[:, None]  # per-motor speed tolerance
        self._phase = self._phase0.copy()
        self._next_n0: int | None = None
        self._hist = np.zeros((3, 0))
        self._rirs: tuple[bytes, list] | None = None   # the last pose's motor RIRs
        h = cfg.harmonics
        # Tone amplitude so that the harmonics together carry tonal_share of the unit power.
        self._tone_amp = np.sqrt(2 * cfg.tonal_share / float(np.sum(np.square(h))))
        # Keep tones below Nyquist: harmonics above 0.45 fs are dropped.
        self._nyq = 0.45 * fs

    def source_signals(self, wheel_speeds: np.ndarray, n0: int, lookahead: int = 0) -> np.ndarray:
        """Pressure at 1 m (Pa) of the three motors for samples ``n0 .. n0 + n - 1`` given their wheel speeds
        ``(3, n)`` rad/s per sample, plus ``lookahead`` samples at the last speed. Consecutive calls (``n0``
        continuing the last block) keep the tone's phase."""
        cfg, fs = self.config, self.sim.config.fs
        n = np.asarray(wheel_speeds).shape[1]
        w = np.asarray(wheel_speeds, float)
        if lookahead and n:
            w = np.concatenate([w, np.repeat(w[:, -1:], lookahead, axis=1)], axis=1)
        if self._next_n0 != n0:
            self._phase = self._phase0.copy()
        if not np.any(w):  # motors standing: silent, the tone's phase stays (skips rendering the broadband part)
            self._next_n0 = n0 + n
            return np.zeros_like(w)
        f = cfg.mesh_hz(w) * self._spread                          # (3, n)
        phase = self._phase[:, None] + 2 * np.pi * np.cumsum(f, axis=1) / fs
        tone = np.zeros_like(f)
        for k, a in enumerate(cfg.harmonics, start=1):
            tone += np.where(k * f < self._nyq, a * np.sin(k * phase), 0.0)
        broad = np.stack([nz.render(n0, w.shape[1]) for nz in self._noise])  # unit RMS
        unit = self._tone_amp * tone + np.sqrt(1 - cfg.tonal_share) * broad
        self._phase = phase[:, n - 1] % (2 * np.pi) if n else self._phase
        self._next_n0 = n0 + n
        return unit * cfg.rms_pa_1m(w)

    def pressure(self, mic_positions_world: np.ndarray, motor_positions_world: np.ndarray,
                 wheel_speeds: np.ndarray, n0: int) -> np.ndarray:
        """Ego-noise pressure (n_mics, n) Pa at the microphones for samples ``n0 ..`` (``wheel_speeds`` (3, n)
        rad/s). Motors and microphones at their positions (world m) for the whole block: they move together,
        only the reflections' geometry changes with the pose. Zero (exactly) when all motors stand still."""
        sim, cfg = self.sim, self.config
        mics = np.asarray(mic_positions_world, float)
        w = np.asarray(wheel_speeds, float)
        n = w.shape[1]
        contiguous = self._next_n0 == n0
        fs, c, n_pre = sim.config.fs, sim.config.c, sim.N_PRE
        src = self.source_signals(w, n0, lookahead=n_pre)  # the RIRs' zero-phase part looks n_pre ahead
        if not np.any(src) and not (contiguous and np.any(self._hist)):
            self._hist = np.zeros((3, 0))
            return np.zeros((mics.shape[0], n))
        out = np.zeros((mics.shape[0], n))
        hist = self._hist if contiguous else np.zeros((3, 0))
        motors = np.asarray(motor_positions_world, float)
        key = mics.tobytes() + motors.tobytes()
        if self._rirs is not None and self._rirs[0] == key:   # the same pose again (a held pose: SimAudioSource)
            rirs = self._rirs[1]
        else:
            rirs = []
            for pos in motors:
                imgs = sim.scene.image_sources(pos, mics.mean(axis=0), cfg.ism_order, c)
                if imgs.positions.shape[0] == 0:  # no path from this motor (hidden by an obstacle): not heard
                    rirs.append(None)
                    continue
                d_max = float(np.max(np.linalg.norm(imgs.positions[:, None] - mics[None], axis=-1)))
                L = n_pre + int(np.ceil(d_max / c * fs)) + FRAC_HALF_TAPS + 1
                rirs.append(early_rir(imgs.positions, imgs.reflection, mics, fs, c, n_pre, L))
            self._rirs = (key, rirs)
        # History kept before the block: the longest RIR (its causal part plus the pre-emission part).
        keep = max((h.shape[1] for h in rirs if h is not None), default=1)
        full = np.concatenate([np.zeros((3, max(0, keep - hist.shape[1]))), hist[:, -keep:], src], axis=1)
        for m, h in enumerate(rirs):
            if h is None:
                continue
            y = ss.fftconvolve(full[m][None, :], h, axes=1)  # (n_mics, len)
            # Sample j of the block is at index keep + j of `full`; the RIR's emission instant is at n_pre.
            out += y[:, keep + n_pre: keep + n_pre + n]
        self._hist = full[:, : full.shape[1] - n_pre][:, -keep:]  # history ends at the block's last sample
        return out
