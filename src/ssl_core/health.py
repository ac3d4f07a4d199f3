"""Microphone health: which channels of the array can be trusted, from the audio alone.

Every ``hop_s`` the monitor analyses the last ``window_s`` of audio (array frame, channels in geometry
order) and names faults:

* ``dead``        band level ``dead_db`` below the median channel (disconnected, broken capsule);
* ``saturated``   more than ``clip_fraction`` of the samples at full scale (gain far too high);
* ``stuck``       no signal but a constant non-zero value (ADC or driver stuck, DC only);
* ``incoherent``  the channel's magnitude-squared coherence with the others is a small fraction of the
                  array's (a loose wire picking up its own noise), while the array hears one coherent sound;
* ``polarity``    the channel's GCC-PHAT peaks are negative with most others (capsule wired inverted);
* ``swapped``     the pair delays fit a plane wave only with two channels exchanged (wiring or
                  channel-map error: TDOAs inconsistent with the array geometry);
* ``device_slip`` (two capture devices) the delays fit a plane wave plus a common offset of the second
                  device's channels (the devices' streams slipped by ``value`` samples). Slips beyond the pair
                  delays' search (``max_slip_samples``) are found first by a GCC-PHAT of the two devices' summed
                  channels over half the window (+-0.5 s by default), then measured on the re-aligned window;
* ``common_mode`` one sound arrives at every channel at the same instant (zero lag on every pair): no
                  acoustic source can do that to a 3-D array, electrical noise (ground loop, USB) can.

A fault is reported once two consecutive analyses agree (``window_s + hop_s`` of audio: 1.5 s by
default) and cleared after two clean ones. ``excluded`` channels (dead, saturated, stuck, incoherent,
polarity, swapped) are meant to be given to ``Localizer.exclude_channels``. Pure numpy/scipy.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
import scipy.fft

from ssl_core.blas import one_blas_thread
from ssl_core.gcc_phat import LagSteering, band_bins, frame_spectra, summed_phat_cross_spectra
from ssl_core.geometry import ArrayGeometry, get_array
from ssl_core.srp import SOUND_SPEED

#: Fault kinds whose channels should be left out of localization.
EXCLUDING = ("dead", "saturated", "stuck", "incoherent", "polarity", "swapped")


@dataclass(frozen=True)
class HealthConfig:
    """Monitor parameters; levels in dB, times in s, fractions 0..1. Thresholds were set from simulated faults
    (pyroomacoustics room, talker at 1.5 m, RT60 0.2-0.6 s, SNR 10-30 dB; ``tests/test_health.py``), with margin."""

    fs: int = 16000
    window_s: float = 1.0            # audio per analysis
    hop_s: float = 0.5               # analysis every
    frame_size: int = 512
    band_hz: tuple[float, float] = (300.0, 4000.0)  # where a 15 cm cube's pairs are coherent for a voice
    min_level_dbfs: float = -70.0    # median band level needed to judge coherence, polarity, delays
    dead_db: float = 30.0            # dead: this far below the median channel (healthy spread: a few dB;
                                     # an open input: -76 dB)
    clip_level: float = 0.99         # |x| at or above this (full scale 1) counts as clipped
    clip_fraction: float = 0.01      # saturated: more clipped samples than this (30x gain: 54-57 %)
    stuck_ac_db: float = 40.0        # stuck: AC level this far below the median, with a DC value ...
    stuck_dc: float = 1e-3           # ... of at least this (full scale 1)
    min_coherence: float = 0.08      # the array's median pair coherence needed to judge a channel or the delays
                                     # (sensor noise: 0.017, diffuse noise 0.11-0.12, talkers at SNR 10 dB: 0.14)
    incoherent_ratio: float = 0.35   # incoherent: channel's median coherence below this x the array's
                                     # (healthy channels within 10 % of each other; own noise: ~0.02)
    polarity_fraction: float = 0.7   # polarity: this fraction of a channel's pairs peak negative (inverted: 7/7)
    max_fit_residual_s: float = 25e-6  # a plane-wave fit this good is "consistent with the geometry"
                                       # (healthy: 9-14 us; 1-sample slip 27-34 us, a swap 40-200 us)
    swap_gain: float = 3.0           # swapped: exchanging two channels cuts the misfit this many times (7-18x)
    slip_samples: float = 0.5        # device_slip: fitted offset at least this (samples) ...
    slip_gain: float = 1.8           # ... and the offset cuts the misfit this many times (1 sample: 2.3-3.6x)
    max_slip_samples: int = 8        # delays searched beyond the geometric range (samples)
    coarse_slip_gain: float = 2.0    # a slip beyond that: the devices' GCC-PHAT peak outside +-(geometric delay +
                                     # max_slip_samples) at least this x the one inside (talkers in a room, slips of
                                     # 80-2000 samples: 2.5-19x; healthy 0.3-0.45x; sensor noise alone 1.2-1.5x)
    common_mode_peak: float = 0.25   # common_mode: every pair's GCC-PHAT at lag 0 at least this (noise 6 dB
                                     # under the talker: 0.47-0.52; a real source leaves some pairs near 0)
    sound_speed: float = SOUND_SPEED

    def __post_init__(self) -> None:
        def need(ok: bool, name: str, expected: str) -> None:
            if not ok:
                raise ValueError(f"HealthConfig.{name}={getattr(self, name)!r}: expected {expected}")

        need(isinstance(self.fs, (int, np.integer)) and self.fs > 0, "fs", "a positive integer sample rate in Hz")
        need(0 < self.hop_s <= self.window_s, "hop_s", f"> 0 and <= window_s ({self.window_s} s)")
        need(self.window_s * self.fs >= 4 * self.frame_size, "window_s", "at least 4 frames of audio")
        need(0 < self.band_hz[0] < self.band_hz[1] <= self.fs / 2, "band_hz", f"0 < low < high <= {self.fs / 2:g} Hz")
        need(0 < self.clip_fraction < 1, "clip_fraction", "a fraction in (0, 1)")
        # its lag table grows with it (bins x lags); larger slips are the coarse search's (_coarse_slip)
        need(1 <= self.max_slip_samples <= self.frame_size // 4, "max_slip_samples",
             f"an integer in [1, frame_size / 4 = {self.frame_size // 4}]")
        need(self.coarse_slip_gain > 1, "coarse_slip_gain", "a ratio > 1")


@dataclass(frozen=True)
class Fault:
    """A named fault of ``channels`` (array microphone indices); ``value`` its measure (dB, fraction,
    coherence, samples of slip ...) as ``detail`` explains."""

    kind: str
    channels: tuple[int, ...]
    value: float
    detail: str

    def __str__(self) -> str:
        return f"{self.kind} mic {'+'.join(str(c) for c in self.channels)}: {self.detail}"


@dataclass(frozen=True)
class HealthReport:
    """The monitor's view at stream time ``time`` (s): confirmed ``faults`` and per-channel measures."""

    time: float
    faults: tuple[Fault, ...]
    level_db: np.ndarray = field(repr=False)      # band level per channel (dB re full-scale sine)
    coherence: np.ndarray = field(repr=False)     # median coherence with the other channels (nan if quiet)
    fit_residual_s: float | None = None           # plane-wave misfit of the pair delays (s), None if quiet

    @property
    def excluded(self) -> tuple[int, ...]:
        """Channels to leave out of localization."""
        return tuple(sorted({c for f in self.faults if f.kind in EXCLUDING for c in f.channels}))

    def has(self, kind: str) -> bool:
        return any(f.kind == kind for f in self.faults)


class MicHealth:
    """Streaming microphone health monitor for one array; see the module docstring.

    ``devices``: the capture device of each channel (e.g. ``[0]*4 + [1]*4``), enables ``device_slip``."""

    def __init__(self, geometry: ArrayGeometry | str = "cube8", config: HealthConfig = HealthConfig(),
                 devices: np.ndarray | None = None) -> None:
        self.geometry = g = get_array(geometry)
        self.config = cfg = config
        self.pairs = g.pairs
        self.devices = None if devices is None else np.asarray(devices, int)
        if self.devices is not None and self.devices.shape != (g.n_mics,):
            raise ValueError(f"devices: expected one device index per microphone ({g.n_mics}), got {devices!r}")
        self._window = np.hanning(cfg.frame_size)
        self._bins = band_bins(cfg.fs, cfg.frame_size, cfg.band_hz)
        omega = 2 * np.pi * self._bins * cfg.fs / cfg.frame_size
        d = np.linalg.norm(g.positions[self.pairs[:, 0]] - g.positions[self.pairs[:, 1]], axis=1)
        self._max_tau = d / cfg.sound_speed  # geometric |TDOA| bound per pair (s)
        span = (d.max() / cfg.sound_speed) * cfg.fs + cfg.max_slip_samples + 1
        self._lags = np.arange(-np.ceil(span * 8), np.ceil(span * 8) + 1) / (8 * cfg.fs)  # 1/8 sample steps (s)
        self._steer = LagSteering(omega, self._lags, dtype=np.float64)
        self._ms_scale = 2.0 / (cfg.frame_size * np.sum(self._window**2))
        self._near = int(np.ceil(span))  # samples: a device offset within this is the pair delays' to measure
        self.reset()

    def reset(self) -> None:
        self._buf = np.zeros((self.geometry.n_mics, 0))
        self._consumed = 0       # samples dropped from the front of the buffer
        self._since = 0          # samples since the last analysis
        self._seen: list[set] = [set(), set()]  # fault keys of the last two analyses
        self._confirmed: dict[tuple, Fault] = {}
        self.report = HealthReport(0.0, (), np.full(self.geometry.n_mics, np.nan),
                                   np.full(self.geometry.n_mics, np.nan))

    # ------------------------------------------------------------------ streaming
    def update(self, block) -> HealthReport | None:
        """Feed a block (channels, samples), int16/int32/float full scale 1; returns a new report when an
        analysis ran, else None (``self.report`` keeps the latest)."""
        x = _as_float(block, self.geometry.n_mics)
        cfg = self.config
        win, hop = int(cfg.window_s * cfg.fs), int(cfg.hop_s * cfg.fs)
        self._buf = np.concatenate([self._buf, x], axis=1)[:, -win:] if x.shape[1] else self._buf
        self._since += x.shape[1]
        self._consumed += x.shape[1]
        report = None
        if self._buf.shape[1] >= win and self._since >= hop:
            self._since = 0
            report = self._confirm(self.analyse(self._buf), self._consumed / cfg.fs)
        return report

    def _confirm(self, found: list[Fault], time: float) -> HealthReport:
        keys = {(f.kind, f.channels): f for f in found}
        prev = self._seen[-1]
        self._seen = [prev, set(keys)]
        for k, f in keys.items():
            if k in prev or k in self._confirmed:
                self._confirmed[k] = f           # confirmed (or still present): latest measure
        for k in list(self._confirmed):
            if k not in keys and k not in prev:  # absent twice in a row
                del self._confirmed[k]
        self.report = HealthReport(time, tuple(self._confirmed.values()), self._level, self._coh, self._resid)
        return self.report

    # ------------------------------------------------------------------ one window
    def analyse(self, x: np.ndarray) -> list[Fault]:
        """Faults visible in one window ``x`` (channels, samples) float; no confirmation."""
        with one_blas_thread():
            return self._analyse(x)

    def _analyse(self, x: np.ndarray) -> list[Fault]:
        cfg = self.config
        faults: list[Fault] = []
        n_ch = x.shape[0]
        dc = x.mean(axis=1)
        spec = frame_spectra(x - dc[:, None], cfg.frame_size, cfg.frame_size // 2, self._window)[..., self._bins]
        power = (spec.real**2 + spec.imag**2).sum(axis=-1) * self._ms_scale  # (channels, frames) band mean square
        with np.errstate(divide="ignore"):
            level = 10 * np.log10(np.maximum(power.mean(axis=1), 1e-30) / 0.5)
        self._level, self._coh, self._resid = level, np.full(n_ch, np.nan), None
        ref = float(np.median(level))
        clipped = (np.abs(x) >= cfg.clip_level).mean(axis=1)
        bad = np.zeros(n_ch, bool)
        for c in range(n_ch):
            if clipped[c] > cfg.clip_fraction:
                faults.append(Fault("saturated", (c,), float(clipped[c]),
                                    f"{100 * clipped[c]:.1f} % of samples at full scale"))
            elif level[c] < ref - cfg.stuck_ac_db and abs(dc[c]) >= cfg.stuck_dc:
                faults.append(Fault("stuck", (c,), float(dc[c]), f"constant {dc[c]:+.4f} full scale, no signal"))
            elif level[c] < ref - cfg.dead_db:
                faults.append(Fault("dead", (c,), float(level[c] - ref),
                                    f"level {level[c] - ref:.0f} dB below the median channel"))
            else:
                continue
            bad[c] = True
        # Frames where the array hears something: the median channel above the floor.
        med_frame = 10 * np.log10(np.maximum(np.median(power, axis=0), 1e-30) / 0.5)
        active = med_frame >= cfg.min_level_dbfs
        if active.sum() < 4:
            return faults
        spec = spec[:, active]
        coarse = self._coarse_slip(x, bad) if self.devices is not None else 0
        if coarse:
            # The devices slipped further than the pair delays are searched: measure on the re-aligned window.
            spec = self._aligned_spectra(x - dc[:, None], coarse)
        coherent = self._coherence_faults(spec, bad, faults)
        if coherent:  # delays and signs mean nothing without one coherent sound (e.g. sensor noise only)
            faults += self._delay_faults(spec, bad, coarse)
        return faults

    def _coarse_slip(self, x: np.ndarray, bad: np.ndarray) -> int:
        """Samples by which the other devices' channels lag device ``devices[0]``'s, when that is beyond the
        pair delays' search (else 0): the GCC-PHAT of the two devices' summed PHAT-normalised channel spectra
        (the sum over all cross-device pairs, at the cost of one product), over +-half the window."""
        cfg = self.config
        first = (self.devices == self.devices[0]) & ~bad
        other = (self.devices != self.devices[0]) & ~bad
        if not (first.any() and other.any()):
            return 0
        n = x.shape[1]
        half = n // 2
        nfft = scipy.fft.next_fast_len(n + half + 1, real=True)   # lags up to +-half without circular wrap-around
        spec = scipy.fft.rfft(x - x.mean(axis=1, keepdims=True), nfft, axis=1)
        f = np.fft.rfftfreq(nfft, 1.0 / cfg.fs)
        band = (f >= cfg.band_hz[0]) & (f <= cfg.band_hz[1])
        u = np.where(band, spec / np.maximum(np.abs(spec), 1e-30), 0)
        cc = scipy.fft.irfft(u[first].sum(axis=0) * np.conj(u[other].sum(axis=0)), nfft)
        lags = np.r_[np.arange(half + 1), np.arange(-half, 0)]
        mag = np.abs(np.r_[cc[:half + 1], cc[-half:]])
        near = np.abs(lags) <= self._near
        k = int(np.argmax(np.where(near, -1.0, mag)))
        if mag[k] < cfg.coarse_slip_gain * mag[near].max():
            return 0
        return -int(lags[k])   # a positive lag of this product: device 0 late; the slip is the other's lateness

    def _aligned_spectra(self, x: np.ndarray, slip: int) -> np.ndarray:
        """Frame spectra (active frames) of ``x`` with the other devices' channels moved ``slip`` samples earlier."""
        cfg = self.config
        n = x.shape[1] - abs(slip)
        other = self.devices != self.devices[0]
        y = np.empty((x.shape[0], n))
        a, b = (0, slip) if slip > 0 else (-slip, 0)
        y[~other], y[other] = x[~other, a:a + n], x[other, b:b + n]
        spec = frame_spectra(y, cfg.frame_size, cfg.frame_size // 2, self._window)[..., self._bins]
        power = (spec.real**2 + spec.imag**2).sum(axis=-1) * self._ms_scale
        med_frame = 10 * np.log10(np.maximum(np.median(power, axis=0), 1e-30) / 0.5)
        return spec[:, med_frame >= cfg.min_level_dbfs]

    def _coherence_faults(self, spec: np.ndarray, bad: np.ndarray, out: list[Fault]) -> bool:
        """Magnitude-squared coherence per pair, averaged over the band; appends channels far below the
        array's to ``out``. Returns whether the array hears a coherent sound at all."""
        cfg = self.config
        y = spec.transpose(2, 0, 1)                          # (bins, channels, frames)
        cov = y @ np.conj(y.transpose(0, 2, 1))               # (bins, channels, channels)
        auto = np.real(np.einsum("bii->bi", cov))
        msc = (np.abs(cov) ** 2 / np.maximum(auto[:, :, None] * auto[:, None, :], 1e-60)).mean(axis=0)
        n = msc.shape[0]
        np.fill_diagonal(msc, np.nan)
        good = ~bad
        coh = np.array([np.nanmedian(msc[c, good & (np.arange(n) != c)]) if good.sum() > 1 else np.nan
                        for c in range(n)])
        self._coh = coh
        array_coh = float(np.nanmedian(msc[np.ix_(good, good)])) if good.sum() > 2 else np.nan
        if not array_coh >= cfg.min_coherence:
            return False
        for c in np.flatnonzero(good & (coh < cfg.incoherent_ratio * array_coh)):
            out.append(Fault("incoherent", (int(c),), float(coh[c]),
                             f"coherence {coh[c]:.2f} with the others (array {array_coh:.2f})"))
            bad[c] = True
        return True

    def _delay_faults(self, spec: np.ndarray, bad: np.ndarray, coarse: int = 0) -> list[Fault]:
        """Polarity, common mode, device slip and swapped channels from the pair GCC-PHATs; ``coarse``: samples
        the other devices' channels were moved earlier in ``spec`` (a slip found by ``_coarse_slip``)."""
        cfg = self.config
        cross = summed_phat_cross_spectra(spec, self.pairs) / spec.shape[1]
        gcc = self._steer(cross)                               # (pairs, lags), 1 = perfectly coherent
        zero = int(np.argmin(np.abs(self._lags)))
        out = []
        i, j = self.pairs[:, 0], self.pairs[:, 1]
        use = ~(bad[i] | bad[j])
        if use.sum() >= 3 and gcc[use, zero].min() >= cfg.common_mode_peak:
            out.append(Fault("common_mode", tuple(range(spec.shape[0])), float(gcc[use, zero].min()),
                             f"one sound at zero delay on every pair (GCC-PHAT >= {gcc[use, zero].min():.2f}): "
                             "electrical, not acoustic"))
            return out  # the delays are those of the noise: nothing more to learn from them
        # Peak per pair within the geometric range plus the slip margin, by magnitude (a sign flip keeps it).
        slack = cfg.max_slip_samples / cfg.fs if self.devices is not None else 1.0 / cfg.fs
        allowed = np.abs(self._lags)[None, :] <= (self._max_tau + slack)[:, None]
        mag = np.where(allowed, np.abs(gcc), -1.0)
        k = mag.argmax(axis=1)
        peak = gcc[np.arange(len(k)), k]
        tdoa = self._lags[k]
        weight = np.abs(peak)
        negative = peak < 0
        for c in np.flatnonzero(~bad):
            mine = use & ((i == c) | (j == c))
            if mine.sum() >= 3 and negative[mine].mean() >= cfg.polarity_fraction:
                out.append(Fault("polarity", (int(c),), float(negative[mine].mean()),
                                 f"{negative[mine].sum()} of {mine.sum()} pairs correlate negatively: inverted"))
                bad[c] = True
        use = ~(bad[i] | bad[j])
        if use.sum() < 8:
            return out
        base, delta = self._fit(tdoa, weight, use)
        self._resid = base
        if self.devices is not None:
            slipped, delta = self._fit(tdoa, weight, use, with_offset=True)
            # re-aligned by a coarse slip: the delays fitting the geometry confirm it (the fit then measures
            # what is left of it); else a slip needs a fitted offset that explains the misfit
            small = abs(delta) * cfg.fs >= cfg.slip_samples and base >= cfg.slip_gain * slipped
            if slipped <= cfg.max_fit_residual_s and (coarse or small):
                value = coarse + delta * cfg.fs
                out.append(Fault("device_slip", tuple(int(c) for c in np.flatnonzero(self.devices != self.devices[0])),
                                 float(value), f"device 1 is {value:+.1f} samples off device 0"))
                return out
            if coarse:
                return out  # re-aligned delays that fit nothing: no conclusion on slips or swaps from this window
        if base <= cfg.max_fit_residual_s:
            return out
        best = (base, None)
        for a, b in combinations(np.flatnonzero(~bad), 2):
            perm = np.arange(spec.shape[0])
            perm[[a, b]] = perm[[b, a]]
            r, _ = self._fit(tdoa, weight, use, perm=perm)
            if r < best[0]:
                best = (r, (int(a), int(b)))
        if best[1] is not None and best[0] <= cfg.max_fit_residual_s and base >= cfg.swap_gain * best[0]:
            out.append(Fault("swapped", best[1], float(base / best[0]),
                             f"pair delays fit the geometry {base / best[0]:.0f}x better with the two exchanged"))
        return out

    def _fit(self, tdoa, weight, use, perm=None, with_offset=False) -> tuple[float, float]:
        """Weighted least-squares plane wave (+ device offset) to pair delays; (RMS misfit s, offset s).

        Model: ``tdoa_p = t_i - t_j = (r_j - r_i) . u / c (+ delta (dev_i - dev_j))``, ``perm`` maps a
        channel to the microphone it really is."""
        pos = self.geometry.positions if perm is None else self.geometry.positions[perm]
        i, j = self.pairs[use, 0], self.pairs[use, 1]
        cols = [pos[j] - pos[i]]
        if with_offset:
            cols.append((self.devices[i] - self.devices[j]).astype(float)[:, None])
        a = np.hstack(cols)
        w = np.sqrt(weight[use])
        sol, *_ = np.linalg.lstsq(a * w[:, None], tdoa[use] * w, rcond=None)
        res = a @ sol - tdoa[use]
        rms = float(np.sqrt(np.sum(weight[use] * res**2) / np.sum(weight[use])))
        return rms, float(sol[3]) if with_offset else 0.0


def _as_float(block, n_ch: int) -> np.ndarray:
    a = np.asarray(block)
    if a.ndim != 2 or a.shape[0] != n_ch:
        raise ValueError(f"audio block: expected shape ({n_ch}, samples), got {a.shape}")
    if a.dtype == np.int16:
        return a / 32768.0
    if a.dtype == np.int32:
        return a / 2147483648.0
    if not np.issubdtype(a.dtype, np.floating):
        raise ValueError(f"audio dtype {a.dtype} not supported: expected int16, int32 or float")
    return a.astype(float)
