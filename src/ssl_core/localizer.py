"""Streaming SRP-PHAT localizer: blocks of multichannel audio in, detections out.

Pipeline per window of ``window_frames`` STFT frames: PHAT cross spectra of
all pairs (band-limited, silent frames gated out) are summed over the window,
turned into an upsampled GCC, steered over a coarse grid (with the GCC
max-pooled over the lag span of one coarse cell, so no peak falls between coarse
points), peaks are picked with angular non-maximum suppression, and each peak is
refined on the fine grid around it. All directions are in the array frame.

Detection test (no fixed power floor): a peak counts when its *significance*
``z = (SRP(u) - SRP_rev(u)) sqrt(N_eff P)`` reaches ``min_significance``. ``SRP_rev`` reads
every pair's GCC at the negated lag (the SRP of the time-reversed correlations, i.e. of the
antipodal direction in the far field). Noise without a direction - independent sensor noise,
an isotropic diffuse field, common-mode hum - has cross-correlations that are even in the lag,
so ``SRP - SRP_rev`` has zero mean whatever the noise level or spectrum, and its standard
deviation is ``1 / sqrt(N_eff P)`` (PHAT terms of unit modulus, ``N_eff`` effective
time-frequency bins, ``P`` pairs). A source at ``u`` raises ``SRP(u)`` but not ``SRP_rev(u)``.
The whole recording (:meth:`Localizer.locate`) pools the windows' detections
(:mod:`ssl_core.pooling`) so every source the windows find consistently is reported.
"""
from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np
from scipy.ndimage import maximum_filter1d
from scipy.signal import lfilter
from scipy.spatial import cKDTree

from ssl_core.beamform import FULL_SCALE_SINE_MS as _FULL_SCALE_SINE_MS
from ssl_core.beamform import arrival_times, delay_and_sum
from ssl_core.blas import one_blas_thread
from ssl_core.detection import Detection
from ssl_core.ego_noise import EgoNoiseSuppressor
from ssl_core.gcc_phat import LagSteering, band_bins, frame_spectra, summed_phat_cross_spectra
from ssl_core.geometry import ArrayGeometry, get_array
from ssl_core.grid import SphericalGrid, azimuth_elevation, make_grid, n_points_for_spacing
from ssl_core.near_field import Focus, FocusScan
from ssl_core.noise import NoiseFloor
from ssl_core.peaks import local_maxima, neighbour_table
from ssl_core.pooling import DirectionPool
from ssl_core.srp import SOUND_SPEED, SteeringTable, tdoa_table

# interference_rescan's novelty weight w = clip(1 - g / q, 0, 1): g = 3 was the best of g in {2, 3, 4} x
# rescan memory {0.6, 0.8, 1.2 s} x covariance memory {1.5, 3 s} on the real-chain rooms of
# tests/test_hearing.py, and again of g {2, 3} x memory {0.8, 1.2, 2 s} with the peak-elsewhere rule; with
# the onset weight, on the tuning rooms (DEV_ROOM_CASES): g 3 over 2, rescan memory 1.6 s over 0.4 / 0.8 /
# 2.4 / 3.2 s, covariance memory 1.5 over 3 s (docs/design/hearing.md, "The interference rescan"); ridge: 1 % of the mean
# eigenvalue keeps R invertible where few frames have filled it (0.1 % and 10 % measured within a few
# windows of it per room).
_NOVELTY_GAIN = 3.0
_NOVELTY_RIDGE = 0.01
# The rescan's onset weight clip(1 - g_on Pbar / P, 0, 1) (Localizer._onset_weights): g_on 2 and the 64 ms
# memory (LocalizerConfig.onset_memory_s) sit in the middle of a plateau on the first six tuning rooms
# (tests/sound_dataset.py DEV_ROOM_CASES, docs/design/hearing.md): her -6 dB windows detected 77-79 % for g_on 1.5-3 x memory
# 32-128 ms, except g_on 1.5 at 128 ms (73 %); g_on 4 was no better on all eight.
_ONSET_GAIN = 2.0
_TABLE_BYTES_PER_POINT_PAIR = 48  # peak bytes of building the tables, per fine point and pair: tracemalloc, 45-48 at 0.5-1.5 deg


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
    el_min_deg: float = -90.0             # lowest elevation searched (degrees, array frame)
    el_max_deg: float = 90.0              # highest elevation searched (degrees, array frame)
    radius_m: float | None = None         # grid radius; None = far field
    n_sources: int = 1                    # at most this many detections per window
    min_separation_deg: float = 20.0      # between two detections
    rel_threshold: float = 0.4            # a detection's power >= this x the strongest
    # Detection test (module docstring): significance z >= this. Noise-only windows (diffuse hvac/pink/
    # white noise at 35-75 dB SPL plus sensor noise, 2808 windows of 128 ms, RT60 0.5 s) had z above 6.2 in
    # 1 % and above 7.35 in 0.1 % of windows (max 7.7): 7 gives a false-alarm rate of about 0.3 % per window.
    min_significance: float = 7.0
    min_power: float = 0.0                # optional extra floor on normalised SRP (1 = coherent on all pairs); 0 = off
    max_table_mb: float = 1024.0          # refuse grids whose steering tables would need more memory
    min_level_dbfs: float = -85.0         # frames with a quieter band level are ignored (silence)
    # Weight bins by their power above a minimum-statistics noise floor (see ssl_core.noise):
    # voices keep their bins, steady noise (pumps, generators) loses its. Off = the paper's plain
    # SRP-PHAT; steady sources (a loudspeaker playing noise) are then localizable too.
    noise_suppression: bool = False
    noise_memory_s: float = 1.5           # how far back the noise floor looks
    # Rescan beside a loud machine (n_sources > 1; see Localizer._spatial_novelty): after the first
    # source, the search scans a GCC whose time-frequency bins are weighted by how far each frame departs
    # from the array's recent spatial covariance (memory ``interference_memory_s``), summed over the
    # recent windows (memory ``rescan_memory_s``). A steady machine's direct path *and* reflections match
    # that covariance and fade; a talker's bursts stand out. Used only when that map peaks away from the
    # first source (else the novel source is the one found, and its reflections would pass the test in
    # the summed map): then the paper's rescan of the same map, as with the option off.
    # The rescan's bins are also weighted by their onset (Localizer._onset_weights): power above the recent
    # mean of the same bin, memory ``onset_memory_s``. At a speech onset the direct path leads the room's
    # response (the precedence effect), so these bins carry her direction, not the echoes of her or of the machine.
    interference_rescan: bool = False     # search the second source in bins that depart from the recent covariance
    interference_memory_s: float = 1.5    # memory of the spatial covariance the rescan departs from (s)
    rescan_memory_s: float = 1.6          # memory of the rescan's GCC summed over windows (s)
    onset_memory_s: float = 0.064         # memory of the per-bin mean an onset rises above (s)
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
        need(0 <= self.min_power < 1, "min_power", "a normalised SRP power in [0, 1) (0 = no floor)")
        need(np.isfinite(self.min_significance) and self.min_significance >= 0, "min_significance",
             "a finite number of noise standard deviations >= 0")
        need(self.max_table_mb > 0, "max_table_mb", "> 0 MB")
        need(self.upsample >= 1, "upsample", "an integer >= 1")
        need(self.sound_speed > 0, "sound_speed", "> 0 m/s")
        need(self.noise_memory_s > 0, "noise_memory_s", "> 0 s")
        need(self.interference_memory_s > 0, "interference_memory_s", "> 0 s")
        need(self.rescan_memory_s > 0, "rescan_memory_s", "> 0 s")
        need(self.onset_memory_s > 0, "onset_memory_s", "> 0 s")
        if self.n_sources > 1:
            need(self.min_separation_deg >= 2 * self.coarse_resolution_deg, "min_separation_deg",
                 f">= 2 x coarse_resolution_deg = {2 * self.coarse_resolution_deg:g} degrees: the coarse grid is "
                 "too coarse to separate sources this close; lower coarse_resolution_deg")


def check_table_memory(cfg: LocalizerConfig, n_pairs: int) -> float:
    """The steering tables' memory (MB) for ``n_pairs`` microphone pairs: the fine grid's share of the sphere
    times its density; ValueError naming ``resolution_deg`` when above ``max_table_mb``. Callers that know the
    array (a scenario: the cube's 28 pairs) check at validation, before anything is built."""
    el_min, el_max = np.deg2rad(cfg.el_min_deg), np.deg2rad(cfg.el_max_deg)
    n_fine = n_points_for_spacing(np.deg2rad(cfg.resolution_deg)) * (np.sin(el_max) - np.sin(el_min)) / 2
    need_mb = n_fine * n_pairs * _TABLE_BYTES_PER_POINT_PAIR / 1e6
    if need_mb > cfg.max_table_mb:
        raise ValueError(
            f"LocalizerConfig.resolution_deg={cfg.resolution_deg:g}: the fine grid has about {n_fine:.0f} "
            f"points, its steering tables need about {need_mb:.0f} MB, more than max_table_mb="
            f"{cfg.max_table_mb:g}; use a coarser resolution (memory grows as 1/resolution^2) or raise "
            "max_table_mb")
    return need_mb


@dataclass(frozen=True)
class LocalizationResult:
    """Detections (strongest first) of one analysis window ending at ``time`` (s from stream start)."""

    time: float
    detections: list[Detection]
    srp_map: np.ndarray = field(repr=False)  # coarse-grid SRP power, (n_coarse,)
    active_frames: int = 0
    level_db: float = -np.inf                # mean band level over the active frames (dB re full-scale sine)
    gcc: np.ndarray | None = field(default=None, repr=False)  # the window's GCC (pairs, lags), for pooling
    weight_sum: float = 0.0                  # sum of the time-frequency weights behind ``gcc``
    n_eff: float = 0.0                       # effective number of independent time-frequency bins behind it


@dataclass
class _Stream:
    """Streaming state: unconsumed samples, analysed frames not yet in a window, the noise floor."""

    buffer: np.ndarray
    spec: np.ndarray
    ms: np.ndarray
    floor: NoiseFloor | None
    start_time: float = 0.0
    frames_done: int = 0
    # interference_rescan: recursive spatial covariance (bins, channels, channels) of the active frames
    # (None until the first active window), and the running sums of the novelty-weighted GCC, its weights
    # and squared weights over n_eff (for the rescan map and its significance scale).
    cov: np.ndarray | None = None
    cov_windows: int = 0
    rescan: tuple[np.ndarray, float, float] | None = None
    onset_mean: np.ndarray | None = None  # per-bin recent mean power (bins,) of the onset weights
    wheel_speeds: np.ndarray | None = None  # the drive's wheel speeds (3,) rad/s for the ego-noise suppression


class Localizer:
    """SRP-PHAT localizer for one array geometry; see the module docstring.

    ``ego_noise``: suppression of the robot's own drive motors (:mod:`ssl_core.ego_noise`), active in the
    windows analysed while the wheel speeds given to :meth:`process` / :meth:`locate` are non-zero."""

    def __init__(self, geometry: ArrayGeometry | str = "cube8", config: LocalizerConfig = LocalizerConfig(),
                 ego_noise: EgoNoiseSuppressor | None = None):
        self.geometry = get_array(geometry)
        self.config = cfg = config
        if ego_noise is not None and ego_noise.geometry.n_mics != self.geometry.n_mics:
            raise ValueError(f"ego_noise: built for {ego_noise.geometry.n_mics} microphones, the array has "
                             f"{self.geometry.n_mics}")
        self.ego_noise = ego_noise
        self.pairs = self.geometry.pairs
        self._window = np.hanning(cfg.frame_size + 2)[1:-1].astype(np.float32)  # periodic-like Hann without zero ends
        self._bins = band_bins(cfg.fs, cfg.frame_size, cfg.band_hz)
        self._omega = 2 * np.pi * self._bins * cfg.fs / cfg.frame_size
        self._freqs = self._bins * cfg.fs / cfg.frame_size
        # Parseval: band mean square of a frame = 2 sum|X|^2 / (N sum w^2)
        self._ms_scale = 2.0 / (cfg.frame_size * np.sum(self._window**2))

        el_min, el_max = np.deg2rad(cfg.el_min_deg), np.deg2rad(cfg.el_max_deg)
        coarse_sp, fine_sp = np.deg2rad(cfg.coarse_resolution_deg), np.deg2rad(cfg.resolution_deg)
        check_table_memory(cfg, len(self.pairs))   # before building anything
        self.coarse_grid: SphericalGrid = make_grid(coarse_sp, el_min, el_max, cfg.radius_m)
        self.fine_grid: SphericalGrid = make_grid(fine_sp, el_min, el_max, cfg.radius_m)

        tdoa_c = tdoa_table(self.geometry, self.coarse_grid, cfg.sound_speed)
        tdoa_f = tdoa_table(self.geometry, self.fine_grid, cfg.sound_speed)
        max_tau = max(np.abs(tdoa_c).max(), np.abs(tdoa_f).max())
        self._max_lag = int(np.ceil(max_tau * cfg.fs * cfg.upsample)) + 2
        self._coarse = SteeringTable(tdoa_c, cfg.fs, cfg.upsample, self._max_lag, interpolate=False)
        self._fine = SteeringTable(tdoa_f, cfg.fs, cfg.upsample, self._max_lag, by_point=True)  # read by caps
        self._fine_az = np.arctan2(self.fine_grid.directions[:, 1], self.fine_grid.directions[:, 0])
        self._fine_pos = (tdoa_f * cfg.fs * cfg.upsample).astype(np.float32)  # lag of each fine point, per pair
        self._lag_axis = np.arange(-self._max_lag, self._max_lag + 1, dtype=np.float32)
        self._window_s = cfg.window_frames * cfg.hop / cfg.fs  # the hop between windows (s)
        self._noise_memory = max(1, int(np.ceil(cfg.noise_memory_s / self._window_s)))
        self._lag_steering = LagSteering(self._omega, self._lag_axis / (cfg.fs * cfg.upsample))
        self._focus = FocusScan(self.geometry, cfg.fs * cfg.upsample, self._max_lag, sound_speed=cfg.sound_speed)
        # Masking a found source: half the GCC main lobe, 1 / (2 f_high).
        f_high = cfg.band_hz[1] if cfg.band_hz else cfg.fs / 2
        self._mask_halfwidth = 0.5 * cfg.fs * cfg.upsample / f_high

        # Fine points around each coarse point (a cap of 1.5 coarse spacings) for refinement,
        # and the largest lag change inside such a cap, which sets the max-pooling width.
        cap = 1.5 * coarse_sp
        fine_tree = self._fine_tree = cKDTree(self.fine_grid.directions)  # also the pool's (locate_blocks)
        self._refine = [np.asarray(v, dtype=np.intp) for v in
                        fine_tree.query_ball_point(self.coarse_grid.directions, 2 * np.sin(cap / 2))]
        self._neighbours = neighbour_table(self.coarse_grid.directions, 1.3 * coarse_sp)
        _, owner = cKDTree(self.coarse_grid.directions).query(self.fine_grid.directions)
        span = np.abs(tdoa_f - tdoa_c[:, owner]).max() * cfg.fs * cfg.upsample
        self._pool = 2 * int(np.ceil(span + 0.5)) + 1  # +0.5: coarse reads the nearest lag
        self.reset()

    # ------------------------------------------------------------------ state
    def reset(self, start_time: float = 0.0) -> None:
        """Forget buffered audio and the noise floor; the next sample is at ``start_time`` (s)."""
        self._stream = self._new_stream(start_time)

    def _new_stream(self, start_time: float = 0.0) -> _Stream:
        n, bins = self.geometry.n_mics, len(self._bins)
        floor = NoiseFloor(self._noise_memory) if self.config.noise_suppression else None
        return _Stream(np.zeros((n, 0), dtype=np.float32), np.zeros((n, 0, bins), dtype=np.complex64),
                       np.zeros(0), floor, float(start_time))

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
    def process(self, block, fs: int | None = None, wheel_speeds=None) -> list[LocalizationResult]:
        """Feed a block (channels, samples) of any length; returns the windows it completed.
        ``wheel_speeds``: the drive's wheel speeds (3,) rad/s during the block, for the ego-noise suppression
        (None or zeros: standing; the windows completed by this block use them)."""
        x = self._check(block, fs)
        self._stream.wheel_speeds = self._check_speeds(wheel_speeds)
        with one_blas_thread():
            return self._process(x, self._stream)

    def process_all(self, recording, fs: int | None = None) -> list[LocalizationResult]:
        """Batch over a whole recording: the same windows as streaming it from a reset state."""
        self.reset()
        return self.process(recording, fs)

    def locate(self, recording, fs: int | None = None, wheel_speeds=None) -> LocalizationResult:
        """Localize over a whole recording (channels, samples): every source its windows find
        consistently, strongest first (see :meth:`locate_blocks`). ``wheel_speeds`` as in :meth:`process`."""
        x = self._check(recording, fs)
        if x.shape[1] < self.config.frame_size:
            raise ValueError(
                f"recording too short: {x.shape[1]} samples, need at least frame_size={self.config.frame_size}"
            )
        return self.locate_blocks([x], wheel_speeds=wheel_speeds)

    def locate_blocks(self, blocks: Iterable, fs: int | None = None, wheel_speeds=None) -> LocalizationResult:
        """Whole-recording answer from consecutive blocks (channels, samples), in bounded memory.

        The windows' detections are pooled into a direction density (:class:`~ssl_core.pooling.DirectionPool`);
        each mode seen in at least 2 windows is a source (two independent false alarms at the same place
        are far rarer than the 0.3 % per window). When no two windows agree (a short recording, a weak
        source), the answer is the peaks of the SRP of the GCC summed over all windows, under the same
        significance test. The summed map is not used to add sources beside pooled ones: its secondary
        peaks include strong reflections, which pass the test over a long recording.
        Works on its own state: the streaming state (:meth:`process`) is left alone.
        """
        cfg = self.config
        pool = DirectionPool(self.fine_grid.directions, tree=self._fine_tree)
        gcc_sum, w_sum, w_sq, ms_sum, frames, t_end = 0.0, 0.0, 0.0, 0.0, 0, 0.0
        st = self._new_stream()
        st.wheel_speeds = self._check_speeds(wheel_speeds)
        with one_blas_thread():
            for r in self._windows(blocks, fs, st):
                pool.add(r.detections)
                t_end = r.time
                frames += r.active_frames
                ms_sum += r.active_frames * 10 ** (r.level_db / 10)
                if r.weight_sum > 0:
                    gcc_sum = gcc_sum + r.weight_sum * r.gcc
                    w_sum += r.weight_sum
                    w_sq += r.weight_sum**2 / r.n_eff
            if frames == 0 or w_sum <= 0:
                return LocalizationResult(t_end, [], np.zeros(self.coarse_grid.n_points), frames)
            gcc, n_eff = gcc_sum / w_sum, w_sum**2 / w_sq
            detections = pool.modes(cfg.n_sources, np.deg2rad(cfg.min_separation_deg), min_windows=2)
            if detections:  # the summed map's peaks are not needed: only the map (the search's first one)
                srp_map, peaks = self._coarse.power(self._pooled(gcc)), []
            else:
                moving = self.ego_noise is not None and self.ego_noise.moving(st.wheel_speeds)
                srp_map, peaks = self._search(gcc, n_eff, excluded=self._ego_excluded() if moving else None)
        level = float(10 * np.log10(ms_sum / frames))
        if not detections:  # no two windows agreed: the summed map's peaks, if significant
            for power, f, z in peaks:
                u = self.fine_grid.directions[f]
                az, el = azimuth_elevation(u)
                # the beam level needs the spectra, gone by now: the recording's band level bounds it from above
                detections.append(Detection(float(az), float(el), u.copy(), power, level, z))
        return LocalizationResult(t_end, detections, srp_map, frames, level, gcc, w_sum, n_eff)

    def peak_in_sector(self, result: LocalizationResult, azimuth: float, half_width: float,
                       recording=None) -> Detection | None:
        """The strongest direction of ``result``'s window-summed SRP whose azimuth lies within ``half_width``
        (rad) of ``azimuth`` (rad, array frame), at any elevation of the fine grid, with the TDOAs of
        ``result.detections`` masked out of every pair's GCC first (as before each search of a further
        source: a louder source's lobes reach into the sector). For a direction known in azimuth only (a
        beam that heard a voice) it gives the elevation and the SRP power there. ``level_db``: the band level of
        the delay-and-sum beam toward it over ``recording`` (channels, samples: the audio ``result`` came
        from), else the result's band level (an upper bound). None for a silent result or an empty sector."""
        if result.gcc is None or result.weight_sum <= 0:
            return None
        cols = np.flatnonzero(np.abs(np.remainder(self._fine_az - azimuth + np.pi, 2 * np.pi) - np.pi) <= half_width)
        if not len(cols):
            return None
        work = result.gcc
        for d in result.detections:
            work = self._mask(work, int(np.argmax(self.fine_grid.directions @ np.asarray(d.direction, float))))
        p = self._fine.power(work, cols)
        f = int(cols[int(np.argmax(p))])
        z = float((p.max() - self._fine.power(np.ascontiguousarray(work[:, ::-1]), np.array([f]))[0])
                  * np.sqrt(max(result.n_eff, 0.0) * self._pairs_in_use()))
        u = self.fine_grid.directions[f]
        az, el = azimuth_elevation(u)
        level = result.level_db if recording is None else \
            self._beam_level(self._analyse(self._check(recording, None))[0], f)
        return Detection(float(az), float(el), u.copy(), float(p.max()), float(level), z)

    def focus(self, result: LocalizationResult, direction) -> Focus | None:
        """Range from the wavefront's curvature along unit ``direction`` (array frame), from ``result``'s GCC
        (:mod:`ssl_core.near_field`); None when the result has no GCC (nothing was heard)."""
        if result.gcc is None:
            return None
        return self._focus.scan(result.gcc, direction)

    def _mask(self, gcc: np.ndarray, fine_index: int) -> np.ndarray:
        """``gcc`` with the lags of fine grid point ``fine_index`` zeroed on every pair (a found source)."""
        centre = self._fine_pos[:, fine_index]
        return np.where(np.abs(self._lag_axis[None, :] - centre[:, None]) <= self._mask_halfwidth, 0.0, gcc)

    def srp_fine(self, result_or_gcc: np.ndarray) -> np.ndarray:
        """SRP power on the whole fine grid for a GCC (pairs, lags) - for plots, not for the hot path."""
        return self._fine.power(result_or_gcc)

    def locate_summed(self, recording, fs: int | None = None) -> LocalizationResult:
        """The paper's whole-recording method: one SRP map of the GCC summed over all the recording's
        non-silent frames, and its peaks (same significance test). Sharper than :meth:`locate` for one
        steady source; blurs moving or intermittent ones and merges talkers of unequal level."""
        x = self._check(recording, fs)
        if x.shape[1] < self.config.frame_size:
            raise ValueError(
                f"recording too short: {x.shape[1]} samples, need at least frame_size={self.config.frame_size}"
            )
        with one_blas_thread():
            spec, ms = self._analyse(x)
            t_end = ((ms.size - 1) * self.config.hop + self.config.frame_size) / self.config.fs
            return self._window_result(spec, ms, t_end, self._new_stream())

    def window_gcc(self, recording, fs: int | None = None) -> np.ndarray:
        """Window-summed GCC (pairs, lags) of a recording; use with :meth:`srp_fine` for full-resolution maps."""
        r = self.locate_summed(recording, fs)
        return r.gcc if r.gcc is not None else np.zeros((len(self.pairs), self._lag_axis.size), np.float32)

    # ------------------------------------------------------------------ internals
    def _check_speeds(self, wheel_speeds) -> np.ndarray | None:
        if wheel_speeds is None:
            return None
        w = np.asarray(wheel_speeds, float).ravel()
        if w.size != 3 or not np.all(np.isfinite(w)):
            raise ValueError(f"wheel_speeds: expected 3 finite wheel speeds (rad/s), got {wheel_speeds!r}")
        return w

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

    def _pairs_in_use(self) -> int:
        """Pairs that enter the SRP (all unless channels are excluded): the P of the significance scale."""
        return len(self.pairs) if self._pair_weights is None else int(np.count_nonzero(self._pair_weights))

    def _windows(self, blocks: Iterable, fs: int | None, st: _Stream) -> Iterator[LocalizationResult]:
        """Every window of consecutive ``blocks`` on stream ``st``, the frames after the last full
        window ending a short last one."""
        for block in blocks:
            yield from self._process(self._check(block, fs), st)
        if st.ms.size:
            t_end = st.start_time + ((st.frames_done + st.ms.size - 1) * self.config.hop + self.config.frame_size) \
                / self.config.fs
            yield self._window_result(st.spec, st.ms, t_end, st)

    def _process(self, x: np.ndarray, st: _Stream) -> list[LocalizationResult]:
        """Append ``x`` to stream ``st``; analyse its complete frames and return the completed windows."""
        cfg = self.config
        buf = np.concatenate([st.buffer, x], axis=1)
        n_frames = 0 if buf.shape[1] < cfg.frame_size else (buf.shape[1] - cfg.frame_size) // cfg.hop + 1
        if n_frames:
            spec, ms = self._analyse(buf[:, : (n_frames - 1) * cfg.hop + cfg.frame_size])
            st.spec = np.concatenate([st.spec, spec], axis=1)
            st.ms = np.concatenate([st.ms, ms])
        st.buffer = buf[:, n_frames * cfg.hop:]
        out = []
        w = cfg.window_frames
        while st.ms.size >= w:
            st.frames_done += w
            t_end = st.start_time + ((st.frames_done - 1) * cfg.hop + cfg.frame_size) / cfg.fs
            out.append(self._window_result(st.spec[:, :w], st.ms[:w], t_end, st))
            st.spec = st.spec[:, w:]
            st.ms = st.ms[w:]
        return out

    def _gcc(self, spec: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, float, float]:
        """Weighted-mean GCC-PHAT (pairs, lags) of band spectra (channels, frames, bins), the sum of the
        weights, and the effective number of independent time-frequency bins ``(sum w)^2 / sum w^2``.

        Normalised by the weights (not the frame count), so a perfectly coherent source gives 1
        with or without noise-suppression weights and powers stay comparable."""
        n_bins = spec.shape[-1]
        if weights is None:
            w_sum = w_sq = float(spec.shape[1] * n_bins)
        else:
            w_sum, w_sq = float(weights.sum()), float(np.square(weights).sum())
        if w_sum <= 0:  # every bin suppressed: no evidence at all
            return np.zeros((len(self.pairs), self._lag_axis.size), np.float32), 0.0, 0.0
        cross = summed_phat_cross_spectra(spec, self.pairs, weights)
        if self._pair_weights is not None:
            cross = cross * self._pair_weights[:, None].astype(cross.real.dtype)
        return self._lag_steering(cross * (n_bins / w_sum)), w_sum, w_sum**2 / w_sq

    def _bin_weights(self, spec: np.ndarray, floor: NoiseFloor | None) -> np.ndarray | None:
        """Noise-suppression weights (frames, bins), updating ``floor`` chunk by chunk as streaming would."""
        if floor is None:
            return None
        power = (spec.real**2 + spec.imag**2).mean(axis=0)
        w = self.config.window_frames
        return np.concatenate([floor.weights(power[k:k + w]) for k in range(0, power.shape[0], w)]) \
            if power.shape[0] else power

    def _window_result(self, spec, ms, t_end: float, st: _Stream) -> LocalizationResult:
        active = self._active(ms)
        weights = self._bin_weights(spec, st.floor)  # the floor learns from quiet windows too
        n_active = int(active.sum())
        if n_active == 0:
            return LocalizationResult(t_end, [], np.zeros(self.coarse_grid.n_points), 0)
        level = float(10 * np.log10(ms[active].mean() / _FULL_SCALE_SINE_MS))
        spec_a = spec[:, active]
        w_a = None if weights is None else weights[active]
        ego = self.ego_noise if self.ego_noise is not None and self.ego_noise.moving(st.wheel_speeds) else None
        if ego is not None and ego.config.spectral:
            w_e = ego.bin_weights((spec_a.real**2 + spec_a.imag**2).mean(axis=0), self._freqs, st.wheel_speeds,
                                  self._window)
            w_a = w_e if w_a is None else w_a * w_e
        gcc, w_sum, n_eff = self._gcc(spec_a, w_a)
        rescan = self._rescan_gcc(spec_a, w_a, st) if self.config.interference_rescan and \
            self.config.n_sources > 1 else None
        if ego is not None and ego.config.spatial:  # the motors' near-field TDOAs, as a found source's
            mask = ego.lag_mask(self._lag_axis / (self.config.fs * self.config.upsample),
                                self._mask_halfwidth / (self.config.fs * self.config.upsample))
            gcc = np.where(mask, 0.0, gcc).astype(gcc.dtype)
            if rescan is not None:
                rescan = (np.where(mask, 0.0, rescan[0]).astype(rescan[0].dtype), rescan[1])
        srp_map, peaks = self._search(gcc, n_eff, rescan, None if ego is None else self._ego_excluded())
        detections = []
        for power, f, z in peaks:
            u = self.fine_grid.directions[f]
            az, el = azimuth_elevation(u)
            detections.append(Detection(float(az), float(el), u.copy(), power, self._beam_level(spec_a, f), z))
        return LocalizationResult(t_end, detections, srp_map, n_active, level, gcc, w_sum, n_eff)

    def _rescan_gcc(self, spec: np.ndarray, weights: np.ndarray | None, st: _Stream
                    ) -> tuple[np.ndarray, float] | None:
        """The GCC (pairs, lags) and effective bin count the search scans after its first source, or None
        while the covariance is younger than two windows. Each time-frequency bin is weighted by its spatial
        novelty (:meth:`_spatial_novelty`) times ``weights``; the weighted GCCs are summed over the recent
        windows (exponential memory ``rescan_memory_s``), since a talker's direct path is consistent over
        a second while a machine's residue is not. Then this window enters the covariance."""
        cfg = self.config
        x = spec.transpose(2, 0, 1)  # (bins, channels, frames)
        out = None
        onset = self._onset_weights(x, st)
        if st.cov is not None and st.cov_windows >= 2:
            w = self._spatial_novelty(x, st.cov) * onset
            g, w_sum, n_eff = self._gcc(spec, w if weights is None else w * weights)
            keep = np.exp(-self._window_s / cfg.rescan_memory_s)
            g_acc, w_acc, w2_acc = st.rescan if st.rescan is not None else (0.0, 0.0, 0.0)
            if w_sum > 0:
                g_acc, w_acc, w2_acc = keep * g_acc + w_sum * g, keep * w_acc + w_sum, keep * w2_acc + w_sum**2 / n_eff
                st.rescan = (g_acc, w_acc, w2_acc)
            if w_acc > 0:
                out = (g_acc / w_acc, w_acc**2 / w2_acc)
        now = (x @ np.conj(x.transpose(0, 2, 1))) / x.shape[-1]
        a = np.float32(np.exp(-self._window_s / cfg.interference_memory_s))
        st.cov = now if st.cov is None else a * st.cov + (1 - a) * now
        st.cov_windows += 1
        return out

    def _onset_weights(self, x: np.ndarray, st: _Stream) -> np.ndarray:
        """Weights (frames, bins) in [0, 1] of frames ``x`` (bins, channels, frames): ``clip(1 - g_on Pbar / P,
        0, 1)``, ``P`` the channel-mean power of the bin, ``Pbar`` its exponential mean over the frames
        before (memory ``onset_memory_s``; state in ``st``). Updates that mean.

        Why: in a room a sound's direct path arrives first and its reflections build up over the next tens
        of ms, so the bins whose power rises above their recent past carry the direct path (the precedence
        effect; the onset-weighted GCC of Wilson and Darrell 2006, "Learning a precedence effect-like
        weighting function for the generalized cross-correlation framework"). At 2 m in an RT60 0.6 s room
        the direct path is ~10 dB below the reverberant field, and the spatial novelty alone also passes
        the reverberant tail of her syllables and of a changing machine."""
        p = (x.real**2 + x.imag**2).mean(axis=1)  # (bins, frames)
        a = np.exp(-self.config.hop / (self.config.fs * self.config.onset_memory_s))
        before = p[:, :1] if st.onset_mean is None else st.onset_mean[:, None]
        # the recursive mean after each frame (scipy's first-order filter from the stored state)
        after, _ = lfilter([1 - a], [1, -a], p, axis=1, zi=a * before)
        before = np.concatenate([before, after[:, :-1]], axis=1)
        st.onset_mean = after[:, -1]
        w = 1.0 - _ONSET_GAIN * before / np.maximum(p, np.finfo(p.dtype).tiny)
        return np.clip(w, 0.0, 1.0).T.astype(np.float32)

    @staticmethod
    def _spatial_novelty(x: np.ndarray, cov: np.ndarray) -> np.ndarray:
        """Weights (frames, bins) in [0, 1] of frames ``x`` (bins, channels, frames) against the recent
        spatial covariance ``cov`` (bins, channels, channels): ``w = clip(1 - g / q, 0, 1)`` with
        ``q = x^H R^-1 x / M`` (mean 1 for frames drawn from ``R``; large for a new direction or a burst).

        Why: a machine's spatial signature in a reverberant room is its room transfer function, direct
        path plus reflections; masking its direct-path TDOA leaves the reflections, which outnumbered
        a talker's direct path in the rescan (measured, docs/design/hearing.md). ``R`` holds all of it, so frames that
        only repeat the machine get ``q`` near 1 and weight 0. Projecting the dominant eigenvector out of
        the spectra instead (``X - u u^H X``) did not help: at low frequencies every steering vector of a
        15 cm array lies near ``u``, and the projection scrambles the talker's phases there (measured)."""
        m = x.shape[1]
        ridge = _NOVELTY_RIDGE * np.trace(cov, axis1=1, axis2=2).real / m
        y = np.linalg.solve(cov + ridge[:, None, None] * np.eye(m, dtype=cov.dtype), x)
        q = (np.conj(x) * y).sum(axis=1).real / m
        return np.clip(1.0 - _NOVELTY_GAIN / np.maximum(q, 1e-12), 0.0, 1.0).T.astype(np.float32)

    def _ego_excluded(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Coarse and fine points the search skips while the wheels turn (the motors' directions), or None."""
        if self._ego_points is None:
            c = self.ego_noise.excluded(self.coarse_grid.directions)
            self._ego_points = (c, self.ego_noise.excluded(self.fine_grid.directions)) if c.any() else ()
        return self._ego_points or None

    _ego_points: tuple | None = None

    def _search(self, gcc: np.ndarray, n_eff: float, rescan: tuple[np.ndarray, float] | None = None,
                excluded: tuple[np.ndarray, np.ndarray] | None = None
                ) -> tuple[np.ndarray, list[tuple[float, int, float]]]:
        """Coarse-to-fine multi-source search; returns the first coarse map and (power, fine index,
        significance) of each detection.

        After each source is found, its TDOA is masked out of every pair's GCC before the next
        scan (as in ODAS, Grondin and Michaud 2019), so its lobes do not hide weaker sources.
        ``rescan``: (GCC, effective bins) scanned after the first source instead of ``gcc`` if it peaks
        away from that source (found TDOAs masked the same way, the significance scaled by its own bin
        count; see ``interference_rescan``). ``excluded``: (coarse, fine) masks of points never searched (ego-noise directions).
        The search stops at the first peak that fails the significance test (module docstring).
        """
        cfg = self.config
        cos_sep = np.cos(np.deg2rad(cfg.min_separation_deg))
        z_scale = np.sqrt(max(n_eff, 0.0) * self._pairs_in_use())
        work = gcc
        peaks: list[tuple[float, int, float]] = []
        srp_map = None
        for k in range(cfg.n_sources):
            coarse = self._coarse.power(self._pooled(work))
            if srp_map is None:
                srp_map = coarse
            if peaks:  # no second detection inside the separation cone of a found one
                found_dirs = self.fine_grid.directions[[f for _, f, _ in peaks]]
                coarse = np.where((self.coarse_grid.directions @ found_dirs.T).max(axis=1) > cos_sep, -np.inf, coarse)
            floor = max(cfg.min_power, cfg.rel_threshold * peaks[0][0]) if peaks else cfg.min_power
            # A pooled coarse value bounds the refined power in its cap from above: refine the best
            # few local maxima, skipping those that cannot beat the floor or the best so far.
            if excluded is None:
                maxima = local_maxima(coarse, self._neighbours, top=4)
            else:
                # Maxima of the map with the motors' directions in it, those outside them kept: masked first,
                # the motors' residue peaks on the mask's rim (their lobes fall off across it), a point
                # with no sound of its own (measured while driving: peaks 31 deg from two motors with a
                # 30 deg mask, 41 deg with a 40 deg one).
                maxima = [c for c in local_maxima(coarse, self._neighbours, top=4 + int(excluded[0].sum()))
                          if not excluded[0][c]][:4]
                coarse = np.where(excluded[0], -np.inf, coarse)
            best = (-np.inf, -1)
            for c in maxima:
                if coarse[c] < max(floor, best[0]):
                    break
                cols = self._refine[c]
                p = self._fine.power(work, cols)
                if excluded is not None:
                    p = np.where(excluded[1][cols], -np.inf, p)
                j = int(np.argmax(p))
                if p[j] > best[0]:
                    best = (float(p[j]), int(cols[j]))
            if best[0] < floor or best[1] < 0:
                break
            col = np.array([best[1]])
            z = float((best[0] - self._fine.power(np.ascontiguousarray(work[:, ::-1]), col)[0]) * z_scale)
            if z < cfg.min_significance:
                break
            peaks.append((best[0], best[1], z))
            if k + 1 < cfg.n_sources:
                if k == 0 and rescan is not None and self._novel_elsewhere(rescan[0], best[1], cos_sep):
                    work, z_scale = rescan[0], np.sqrt(max(rescan[1], 0.0) * self._pairs_in_use())
                work = self._mask(work, best[1])
        if srp_map is None:
            srp_map = np.zeros(self.coarse_grid.n_points)
        return srp_map, peaks

    def _pooled(self, gcc: np.ndarray) -> np.ndarray:
        """``gcc`` max-pooled over the coarse grid's lag spacing (what the nearest-lag coarse search reads)."""
        return maximum_filter1d(gcc, self._pool, axis=1, mode="nearest") if self._pool > 1 else gcc

    def _novel_elsewhere(self, gcc: np.ndarray, found: int, cos_sep: float) -> bool:
        """Does the novelty-weighted ``gcc`` peak away from the found source (fine index ``found``)? If not,
        the found source is itself the novel one (a lone talker: measured, scanning the summed novelty map
        then found her reflections, false windows 35 -> 63 % at SNR 5 dB), so the rescan is not used."""
        c = int(np.argmax(self._coarse.power(self._pooled(gcc))))
        return float(self.coarse_grid.directions[c] @ self.fine_grid.directions[found]) <= cos_sep

    def _beam_level(self, spec: np.ndarray, fine_index: int) -> float:
        """Band level (dB re full-scale sine) of the delay-and-sum beam toward a fine grid point."""
        g = self.fine_grid
        arrival = arrival_times(self.geometry.positions, g.directions[fine_index], self.config.sound_speed, g.radius)
        beam = delay_and_sum(spec, self._omega / (2 * np.pi), arrival)
        ms = (np.abs(beam) ** 2).sum(axis=-1).mean() * self._ms_scale
        return float(10 * np.log10(max(ms, 1e-30) / _FULL_SCALE_SINE_MS))
