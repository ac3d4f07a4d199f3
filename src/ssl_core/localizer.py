"""Streaming SRP-PHAT localizer: blocks of multichannel audio in, detections out.

Pipeline per window of ``window_frames`` STFT frames: PHAT cross spectra of
all pairs (band-limited, silent frames gated out) are summed over the window,
turned into an upsampled GCC, steered over a coarse grid (with the GCC
max-pooled over the lag span of one coarse cell, so no peak falls between coarse
points), peaks are picked with angular non-maximum suppression, and each peak is
refined on the fine grid around it. All directions are in the array frame.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import maximum_filter1d
from scipy.spatial import cKDTree

from ssl_core.gcc_phat import LagSteering, band_bins, frame_spectra, summed_phat_cross_spectra
from ssl_core.geometry import ArrayGeometry, get_array
from ssl_core.grid import SphericalGrid, azimuth_elevation, make_grid
from ssl_core.noise import NoiseFloor
from ssl_core.peaks import local_maxima, neighbour_table
from ssl_core.beamform import FULL_SCALE_SINE_MS as _FULL_SCALE_SINE_MS
from ssl_core.beamform import arrival_times, delay_and_sum
from ssl_core.srp import SOUND_SPEED, SteeringTable, tdoa_table



@dataclass(frozen=True)
class LocalizerConfig:
    """Parameters of the localizer. Frequencies in Hz, angles in degrees (user-facing), lengths in m."""

    fs: int = 16000                       # sample rate (Hz)
    frame_size: int = 512                 # STFT frame (samples); 32 ms at 16 kHz
    hop: int = 256                        # STFT hop (samples)
    window_frames: int = 8                # frames summed per output window (8 x 16 ms = 128 ms)
    # Voice band. Wider than the 300-3400 Hz telephone band because angular resolution grows with
    # frequency: 6 kHz separates talkers 25-30 degrees apart that 3.4 kHz merges. None = all bins.
    band_hz: tuple[float, float] | None = (300.0, 6000.0)
    resolution_deg: float = 1.5           # fine grid spacing
    coarse_resolution_deg: float = 5.0    # coarse search grid spacing
    el_min_deg: float = -90.0
    el_max_deg: float = 90.0
    radius_m: float | None = None         # grid radius; None = far field
    n_sources: int = 1                    # at most this many detections per window
    min_separation_deg: float = 20.0      # between two detections
    rel_threshold: float = 0.4            # a detection's power >= this x the strongest
    min_power: float = 0.08               # normalised SRP (1 = perfectly coherent on all pairs)
    min_level_dbfs: float = -85.0         # frames with a quieter band level are ignored (silence)
    # Weight bins by their power above a minimum-statistics noise floor (see ssl_core.noise):
    # voices keep their bins, steady noise (pumps, generators) loses its. Off = the paper's plain
    # SRP-PHAT; steady sources (a loudspeaker playing noise) are then localizable too.
    noise_suppression: bool = False
    noise_memory_s: float = 1.5           # how far back the noise floor looks
    upsample: int = 4                     # GCC interpolation factor
    sound_speed: float = SOUND_SPEED      # m/s

    def __post_init__(self) -> None:
        def need(ok: bool, name: str, expected: str) -> None:
            if not ok:
                raise ValueError(f"LocalizerConfig.{name}={getattr(self, name)!r}: expected {expected}")

        need(isinstance(self.fs, (int, np.integer)) and self.fs > 0, "fs", "a positive integer sample rate in Hz")
        need(self.frame_size >= 16 and self.frame_size % 2 == 0, "frame_size", "an even number of samples >= 16")
        need(0 < self.hop <= self.frame_size, "hop", f"1..frame_size ({self.frame_size}) samples")
        need(self.window_frames >= 1, "window_frames", "an integer >= 1")
        need(0 < self.resolution_deg <= self.coarse_resolution_deg, "resolution_deg",
             f"> 0 and <= coarse_resolution_deg ({self.coarse_resolution_deg})")
        need(self.coarse_resolution_deg < 45, "coarse_resolution_deg", "< 45 degrees")
        need(self.n_sources >= 1, "n_sources", "an integer >= 1")
        need(0 <= self.rel_threshold <= 1, "rel_threshold", "a fraction in [0, 1]")
        need(self.upsample >= 1, "upsample", "an integer >= 1")
        need(self.sound_speed > 0, "sound_speed", "> 0 m/s")
        need(self.noise_memory_s > 0, "noise_memory_s", "> 0 s")
        if self.n_sources > 1:
            need(self.min_separation_deg >= 2 * self.coarse_resolution_deg, "min_separation_deg",
                 f">= 2 x coarse_resolution_deg = {2 * self.coarse_resolution_deg:g} degrees: the coarse grid is "
                 "too coarse to separate sources this close; lower coarse_resolution_deg")


@dataclass(frozen=True)
class Detection:
    """One localized source, array frame: angles in rad, ``power`` normalised SRP-PHAT (0..1),
    ``level_db`` the delay-and-sum beam's band level toward it (dB re a full-scale sine)."""

    azimuth: float
    elevation: float
    direction: np.ndarray
    power: float
    level_db: float

    @property
    def azimuth_deg(self) -> float:
        return float(np.rad2deg(self.azimuth))

    @property
    def elevation_deg(self) -> float:
        return float(np.rad2deg(self.elevation))

    def to_dict(self) -> dict:
        return {"azimuth_deg": round(self.azimuth_deg, 3), "elevation_deg": round(self.elevation_deg, 3),
                "power": round(self.power, 5), "level_db": round(self.level_db, 2)}


@dataclass(frozen=True)
class LocalizationResult:
    """Detections (strongest first) of one analysis window ending at ``time`` (s from stream start)."""

    time: float
    detections: list[Detection]
    srp_map: np.ndarray = field(repr=False)  # coarse-grid SRP power, (n_coarse,)
    active_frames: int = 0
    level_db: float = -np.inf                # mean band level over the active frames (dB re full-scale sine)


class Localizer:
    """SRP-PHAT localizer for one array geometry; see the module docstring."""

    def __init__(self, geometry: ArrayGeometry | str = "cube8", config: LocalizerConfig = LocalizerConfig()):
        self.geometry = get_array(geometry)
        self.config = cfg = config
        self.pairs = self.geometry.pairs
        self._window = np.hanning(cfg.frame_size + 2)[1:-1].astype(np.float32)  # periodic-like Hann without zero ends
        self._bins = band_bins(cfg.fs, cfg.frame_size, cfg.band_hz)
        self._omega = 2 * np.pi * self._bins * cfg.fs / cfg.frame_size
        # Parseval: band mean square of a frame = 2 sum|X|^2 / (N sum w^2)
        self._ms_scale = 2.0 / (cfg.frame_size * np.sum(self._window**2))

        el_min, el_max = np.deg2rad(cfg.el_min_deg), np.deg2rad(cfg.el_max_deg)
        coarse_sp, fine_sp = np.deg2rad(cfg.coarse_resolution_deg), np.deg2rad(cfg.resolution_deg)
        self.coarse_grid: SphericalGrid = make_grid(coarse_sp, el_min, el_max, cfg.radius_m)
        self.fine_grid: SphericalGrid = make_grid(fine_sp, el_min, el_max, cfg.radius_m)

        tdoa_c = tdoa_table(self.geometry, self.coarse_grid, cfg.sound_speed)
        tdoa_f = tdoa_table(self.geometry, self.fine_grid, cfg.sound_speed)
        max_tau = max(np.abs(tdoa_c).max(), np.abs(tdoa_f).max())
        self._max_lag = int(np.ceil(max_tau * cfg.fs * cfg.upsample)) + 2
        self._coarse = SteeringTable(tdoa_c, cfg.fs, cfg.upsample, self._max_lag, interpolate=False)
        self._fine = SteeringTable(tdoa_f, cfg.fs, cfg.upsample, self._max_lag)
        self._fine_pos = (tdoa_f * cfg.fs * cfg.upsample).astype(np.float32)  # lag of each fine point, per pair
        self._lag_axis = np.arange(-self._max_lag, self._max_lag + 1, dtype=np.float32)
        chunk_s = cfg.window_frames * cfg.hop / cfg.fs
        self._noise_memory = max(1, int(np.ceil(cfg.noise_memory_s / chunk_s)))
        self._noise = self._new_floor()  # the streaming path's floor
        self._lag_steering = LagSteering(self._omega, self._lag_axis / (cfg.fs * cfg.upsample))
        # Masking a found source: half the GCC main lobe, 1 / (2 f_high).
        f_high = cfg.band_hz[1] if cfg.band_hz else cfg.fs / 2
        self._mask_halfwidth = 0.5 * cfg.fs * cfg.upsample / f_high

        # Fine points around each coarse point (a cap of 1.5 coarse spacings) for refinement,
        # and the largest lag change inside such a cap, which sets the max-pooling width.
        cap = 1.5 * coarse_sp
        fine_tree = cKDTree(self.fine_grid.directions)
        self._refine = [np.asarray(v, dtype=np.intp) for v in
                        fine_tree.query_ball_point(self.coarse_grid.directions, 2 * np.sin(cap / 2))]
        self._neighbours = neighbour_table(self.coarse_grid.directions, 1.3 * coarse_sp)
        _, owner = cKDTree(self.coarse_grid.directions).query(self.fine_grid.directions)
        span = np.abs(tdoa_f - tdoa_c[:, owner]).max() * cfg.fs * cfg.upsample
        self._pool = 2 * int(np.ceil(span + 0.5)) + 1  # +0.5: coarse reads the nearest lag
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self, start_time: float = 0.0) -> None:
        """Forget buffered audio; the next sample is at ``start_time`` (s)."""
        self._buffer = np.zeros((self.geometry.n_mics, 0), dtype=np.float32)
        self._pending_spec = np.zeros((self.geometry.n_mics, 0, len(self._bins)), dtype=np.complex64)
        self._pending_ms = np.zeros(0)
        self._start_time = float(start_time)
        self._frames_done = 0  # frames already emitted in windows
        if self._noise is not None:
            self._noise.reset()

    # ------------------------------------------------------------------ input
    def _check(self, block, fs: int | None) -> np.ndarray:
        cfg = self.config
        if fs is not None and int(fs) != cfg.fs:
            raise ValueError(f"sample rate mismatch: audio is {fs} Hz, localizer expects {cfg.fs} Hz")
        a = np.asarray(block)
        if a.ndim != 2:
            raise ValueError(f"audio block must be 2-D (channels, samples), got shape {a.shape}")
        if a.shape[0] != self.geometry.n_mics:
            raise ValueError(
                f"audio has {a.shape[0]} channels, array '{self.geometry.name}' expects {self.geometry.n_mics} "
                f"(shape must be (channels, samples), got {a.shape})"
            )
        # float32 is ample for phase-based localization and halves the memory traffic.
        if a.dtype == np.int16:
            return a.astype(np.float32) * np.float32(1 / 32768)
        if a.dtype == np.int32:
            return a.astype(np.float32) * np.float32(1 / 2147483648)
        if not np.issubdtype(a.dtype, np.floating):
            raise ValueError(f"audio dtype {a.dtype} not supported: expected int16, int32 or float")
        if not np.all(np.isfinite(a)):
            ch, n = np.argwhere(~np.isfinite(a))[0]
            raise ValueError(f"audio contains a non-finite sample (NaN/inf) at channel {ch}, sample {n}")
        return a.astype(np.float32, copy=False)

    def _analyse(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Band spectra (channels, frames, bins) and band mean squares (frames,) of every frame of ``x``."""
        cfg = self.config
        spec = frame_spectra(x, cfg.frame_size, cfg.hop, self._window)[..., self._bins]
        ms = (spec.real**2 + spec.imag**2).sum(axis=-1).mean(axis=0) * self._ms_scale
        return spec, ms

    # ------------------------------------------------------------------ public API
    def process(self, block, fs: int | None = None) -> list[LocalizationResult]:
        """Feed a block (channels, samples) of any length; returns the windows it completed."""
        x = self._check(block, fs)
        cfg = self.config
        buf = np.concatenate([self._buffer, x], axis=1)
        n_frames = 0 if buf.shape[1] < cfg.frame_size else (buf.shape[1] - cfg.frame_size) // cfg.hop + 1
        if n_frames:
            spec, ms = self._analyse(buf[:, : (n_frames - 1) * cfg.hop + cfg.frame_size])
            self._pending_spec = np.concatenate([self._pending_spec, spec], axis=1)
            self._pending_ms = np.concatenate([self._pending_ms, ms])
        self._buffer = buf[:, n_frames * cfg.hop:]
        out = []
        w = cfg.window_frames
        while self._pending_ms.size >= w:
            self._frames_done += w
            t_end = self._start_time + ((self._frames_done - 1) * cfg.hop + cfg.frame_size) / cfg.fs
            out.append(self._window_result(self._pending_spec[:, :w], self._pending_ms[:w], t_end, self._noise))
            self._pending_spec = self._pending_spec[:, w:]
            self._pending_ms = self._pending_ms[w:]
        return out

    def process_all(self, recording, fs: int | None = None) -> list[LocalizationResult]:
        """Batch over a whole recording: the same windows as streaming it from a reset state."""
        self.reset()
        return self.process(recording, fs)

    def locate(self, recording, fs: int | None = None) -> LocalizationResult:
        """Localize over a whole recording, summing the SRP over all its (non-silent) frames."""
        x = self._check(recording, fs)
        if x.shape[1] < self.config.frame_size:
            raise ValueError(
                f"recording too short: {x.shape[1]} samples, need at least frame_size={self.config.frame_size}"
            )
        spec, ms = self._analyse(x)
        t_end = ((ms.size - 1) * self.config.hop + self.config.frame_size) / self.config.fs
        # a whole recording learns its own floor and leaves the streaming state alone
        return self._window_result(spec, ms, t_end, self._new_floor())

    def srp_fine(self, result_or_gcc: np.ndarray) -> np.ndarray:
        """SRP power on the whole fine grid for a GCC (pairs, lags) - for plots, not for the hot path."""
        return self._fine.power(result_or_gcc)

    def window_gcc(self, recording, fs: int | None = None) -> np.ndarray:
        """Window-summed GCC (pairs, lags) of a recording; use with :meth:`srp_fine` for full-resolution maps."""
        spec, ms = self._analyse(self._check(recording, fs))
        active = self._active(ms)
        weights = self._bin_weights(spec, self._new_floor())
        return self._gcc(spec[:, active], None if weights is None else weights[active])

    # ------------------------------------------------------------------ internals
    def _active(self, ms: np.ndarray) -> np.ndarray:
        with np.errstate(divide="ignore"):
            level = 10 * np.log10(ms / _FULL_SCALE_SINE_MS)
        return level >= self.config.min_level_dbfs

    _pair_weights: np.ndarray | None = None  # None: every pair counts (see exclude_channels)

    def exclude_channels(self, channels: list[int] | tuple[int, ...]) -> None:
        """Leave every pair of ``channels`` (faulty microphones, e.g. ``ssl_core.health``'s ``excluded``) out
        of the SRP sum from the next window on; the others are scaled so that 1 stays perfectly coherent."""
        bad = np.isin(self.pairs, np.asarray(channels, int)).any(axis=1)
        if bad.all():
            raise ValueError(f"exclude_channels: excluding {list(channels)} leaves no microphone pair")
        self._pair_weights = None if not bad.any() else np.where(bad, 0.0, len(bad) / (~bad).sum())

    def _gcc(self, spec: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """Frame-averaged GCC-PHAT (pairs, lags) of band spectra (channels, frames, bins)."""
        cross = summed_phat_cross_spectra(spec, self.pairs, weights)
        if self._pair_weights is not None:
            cross = cross * self._pair_weights[:, None].astype(cross.real.dtype)
        return self._lag_steering(cross / max(spec.shape[1], 1))

    def _new_floor(self) -> NoiseFloor | None:
        return NoiseFloor(self._noise_memory) if self.config.noise_suppression else None

    def _bin_weights(self, spec: np.ndarray, floor: NoiseFloor | None) -> np.ndarray | None:
        """Noise-suppression weights (frames, bins), updating ``floor`` chunk by chunk as streaming would."""
        if floor is None:
            return None
        power = (spec.real**2 + spec.imag**2).mean(axis=0)
        w = self.config.window_frames
        return np.concatenate([floor.weights(power[k:k + w]) for k in range(0, power.shape[0], w)]) \
            if power.shape[0] else power

    def _window_result(self, spec, ms, t_end: float, floor: NoiseFloor | None) -> LocalizationResult:
        active = self._active(ms)
        weights = self._bin_weights(spec, floor)  # the floor learns from quiet windows too
        n_active = int(active.sum())
        if n_active == 0:
            return LocalizationResult(t_end, [], np.zeros(self.coarse_grid.n_points), 0)
        level = float(10 * np.log10(ms[active].mean() / _FULL_SCALE_SINE_MS))
        spec_a = spec[:, active]
        srp_map, peaks = self._search(self._gcc(spec_a, None if weights is None else weights[active]))
        detections = []
        for power, f in peaks:
            u = self.fine_grid.directions[f]
            az, el = azimuth_elevation(u)
            detections.append(Detection(float(az), float(el), u.copy(), power, self._beam_level(spec_a, f)))
        return LocalizationResult(t_end, detections, srp_map, n_active, level)

    def _search(self, gcc: np.ndarray) -> tuple[np.ndarray, list[tuple[float, int]]]:
        """Coarse-to-fine multi-source search; returns the first coarse map and (power, fine index) peaks.

        After each source is found, its TDOA is masked out of every pair's GCC before the next
        scan (as in ODAS, Grondin and Michaud 2019), so its lobes do not hide weaker sources.
        """
        cfg = self.config
        cos_sep = np.cos(np.deg2rad(cfg.min_separation_deg))
        work = gcc
        peaks: list[tuple[float, int]] = []
        srp_map = None
        for k in range(cfg.n_sources):
            pooled = maximum_filter1d(work, self._pool, axis=1, mode="nearest") if self._pool > 1 else work
            coarse = self._coarse.power(pooled)
            if srp_map is None:
                srp_map = coarse
            if peaks:  # no second detection inside the separation cone of a found one
                found_dirs = self.fine_grid.directions[[f for _, f in peaks]]
                coarse = np.where((self.coarse_grid.directions @ found_dirs.T).max(axis=1) > cos_sep, -np.inf, coarse)
            floor = max(cfg.min_power, cfg.rel_threshold * peaks[0][0]) if peaks else cfg.min_power
            # A pooled coarse value bounds the refined power in its cap from above: refine the best
            # few local maxima, skipping those that cannot beat the floor or the best so far.
            best = (-np.inf, -1)
            for c in local_maxima(coarse, self._neighbours, top=4):
                if coarse[c] < max(floor, best[0]):
                    break
                cols = self._refine[c]
                p = self._fine.power(work, cols)
                j = int(np.argmax(p))
                if p[j] > best[0]:
                    best = (float(p[j]), int(cols[j]))
            if best[0] < floor:
                break
            peaks.append(best)
            if k + 1 < cfg.n_sources:
                centre = self._fine_pos[:, best[1]]
                work = np.where(np.abs(self._lag_axis[None, :] - centre[:, None]) <= self._mask_halfwidth, 0.0, work)
        return srp_map, peaks

    def _beam_level(self, spec: np.ndarray, fine_index: int) -> float:
        """Band level (dB re full-scale sine) of the delay-and-sum beam toward a fine grid point."""
        g = self.fine_grid
        arrival = arrival_times(self.geometry.positions, g.directions[fine_index], self.config.sound_speed, g.radius)
        beam = delay_and_sum(spec, self._omega / (2 * np.pi), arrival)
        ms = (np.abs(beam) ** 2).sum(axis=-1).mean() * self._ms_scale
        return float(10 * np.log10(max(ms, 1e-30) / _FULL_SCALE_SINE_MS))
