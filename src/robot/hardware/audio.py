"""Capture of the real array: two 4-channel USB microphone devices (PS3 Eye
class) merged into one aligned 8-channel stream.

The two devices run on independent clocks and start at different moments, so
the same sound reaches their streams at different sample indices. The
*offset* ``k`` (samples) is defined by: an instant at index ``i`` of device 0's
stream is at index ``i + k`` of device 1's stream. It is measured with
GCC-PHAT on a common sound:

1. *coarse*: GCC-PHAT between one reference channel of each device over up to
   ``max_offset_s``. The lag also contains the acoustic delay between the two
   reference microphones (up to their distance / c, ~5 samples at 16 kHz for
   the cube), which is removed by ``expected_tdoa_s`` when the calibration
   sound comes from a known direction;
2. *refine* (when the microphone positions are known): on the coarsely aligned
   data, GCC-PHAT of every microphone pair, then a least-squares fit of a
   plane wave (slowness vector, 3 unknowns) plus the residual inter-device
   offset (1 unknown) to all pair delays. This needs no knowledge of where the
   sound came from, so it also tracks clock drift during a mission.

Compensation is by whole samples (the residual is at most half a sample,
~1 cm of path at 16 kHz).

``ChannelMerger`` is pure numpy (testable without devices); ``ArrayCapture`` is
the ``AudioSource`` on top of ``sounddevice`` (optional ``hardware`` extra,
imported lazily).
"""
from __future__ import annotations

import logging
import math
import queue
import re
import threading
from dataclasses import dataclass
from itertools import combinations

import numpy as np
from ssl_core.gcc_phat import gcc_phat

from robot.hal import AudioBlock, AudioSource, Clock, WallClock, as_float_audio

log = logging.getLogger(__name__)

SOUND_SPEED = 343.0  # m/s

#: Output channel k <- (device, channel): device 0 feeds array mics 0-3, device 1 mics 4-7.
DEFAULT_CHANNEL_MAP: tuple[tuple[int, int], ...] = tuple((d, c) for d in (0, 1) for c in range(4))


def parse_channel_map(text: str) -> tuple[tuple[int, int], ...]:
    """``"A0,A1,A2,A3,B0,B1,B2,B3"`` or ``"0:0,0:1,...,1:3"`` -> ((device, channel), ...).

    Entry k names the device channel that becomes array microphone k.
    """
    out = []
    for k, item in enumerate(t.strip() for t in text.split(",")):
        m = re.fullmatch(r"([ABab])(\d+)", item) or re.fullmatch(r"([01]):(\d+)", item)
        if not m:
            raise ValueError(
                f"channel map entry {k} ({item!r}): expected A<ch>/B<ch> or <device>:<ch> with device 0 or 1, "
                "e.g. 'A0,A1,A2,A3,B0,B1,B2,B3'"
            )
        dev = m.group(1).upper()
        out.append(({"A": 0, "B": 1, "0": 0, "1": 1}[dev], int(m.group(2))))
    return tuple(out)


@dataclass(frozen=True)
class MergeConfig:
    """How two devices' channels form the array stream and how their offset is measured.

    ``channel_map[k] = (device, channel)`` feeds output (array microphone) k.
    ``reference``: the channel of device 0 and of device 1 used for the coarse
    GCC-PHAT. ``expected_tdoa_s``: known arrival time at device 1's reference
    mic minus device 0's for the calibration sound (0 when it is equidistant).
    """

    channel_map: tuple[tuple[int, int], ...] = DEFAULT_CHANNEL_MAP
    device_channels: tuple[int, int] = (4, 4)
    reference: tuple[int, int] = (0, 0)
    max_offset_s: float = 0.25
    band_hz: tuple[float, float] = (200.0, 4000.0)
    expected_tdoa_s: float = 0.0
    min_peak: float = 0.1             # coarse GCC-PHAT peak (0..1, 1 = perfectly coherent) to trust an estimate
    max_fit_residual_s: float = 40e-6  # refine: RMS pair-delay misfit (s) to trust an estimate
    history_s: float = 2.0            # audio kept per device for offset estimation (s)

    def __post_init__(self) -> None:
        cmap = tuple(tuple(int(v) for v in e) for e in self.channel_map)
        object.__setattr__(self, "channel_map", cmap)
        if len(self.device_channels) != 2 or min(self.device_channels) < 1:
            raise ValueError(f"device_channels: expected two channel counts >= 1, got {self.device_channels}")
        if not cmap:
            raise ValueError("channel_map: expected at least one (device, channel) entry")
        for k, (d, c) in enumerate(cmap):
            if d not in (0, 1):
                raise ValueError(f"channel_map[{k}]: device must be 0 or 1, got {d}")
            if not 0 <= c < self.device_channels[d]:
                raise ValueError(
                    f"channel_map[{k}]: device {d} has channels 0..{self.device_channels[d] - 1}, got {c}"
                )
        if len(set(cmap)) != len(cmap):
            raise ValueError(f"channel_map: a device channel is used twice: {cmap}")
        for d in (0, 1):
            if not 0 <= self.reference[d] < self.device_channels[d]:
                raise ValueError(f"reference[{d}]: expected a channel of device {d}, got {self.reference[d]}")
        if not self.max_offset_s > 0:
            raise ValueError(f"max_offset_s: expected > 0 s, got {self.max_offset_s}")
        if not 0 <= self.band_hz[0] < self.band_hz[1]:
            raise ValueError(f"band_hz: expected (low, high) Hz with 0 <= low < high, got {self.band_hz}")
        if not self.history_s > 2 * self.max_offset_s:
            raise ValueError(
                f"history_s: expected > 2 * max_offset_s = {2 * self.max_offset_s} s, got {self.history_s}")


@dataclass(frozen=True)
class OffsetEstimate:
    """Result of an offset measurement (see the module docstring for the sign)."""

    offset: int                   # samples to compensate (device-1 index minus device-0 index)
    offset_exact: float           # sub-sample estimate (samples)
    peak: float                   # coarse GCC-PHAT peak height (0..1)
    fit_residual_s: float | None  # refine: RMS misfit of the pair delays (s); None when not refined
    direction: np.ndarray | None  # refine: unit vector toward the calibration sound (array frame)
    confident: bool
    window: tuple[int, int] | None = None  # device-0 stream indices [start, end) of the audio it was measured on

    def __str__(self) -> str:
        fit = "" if self.fit_residual_s is None else f", fit residual {self.fit_residual_s * 1e6:.1f} us"
        return f"offset {self.offset} samples ({self.offset_exact:+.2f}), GCC-PHAT peak {self.peak:.2f}{fit}"


def gcc_phat_lag(x: np.ndarray, y: np.ndarray, fs: float, lag_range: tuple[float, float], band_hz=None,
                 upsample: int = 1) -> tuple[float, float]:
    """Lag (samples) by which ``y`` trails ``x`` (``y[n] ~ x[n - lag]``), and the PHAT peak height.

    ``x``, ``y``: 1-D, any lengths. Only lags in ``lag_range = (lo, hi)`` samples are
    searched (ssl_core's GCC-PHAT); the peak is refined by a parabolic fit. The height is 1
    for a perfectly coherent delayed copy.
    """
    _, lags, cc = gcc_phat(y, x, fs, band_hz=band_hz, upsample=upsample,
                           lag_range=(lag_range[0] / fs, lag_range[1] / fs))
    i = int(np.argmax(cc))
    frac = 0.0
    if 0 < i < cc.size - 1:
        a, b, c = cc[i - 1], cc[i], cc[i + 1]
        den = a - 2 * b + c
        frac = 0.5 * (a - c) / den if den < 0 else 0.0
    return (lags[i] * fs * upsample + frac) / upsample, float(cc[i])


def fit_plane_wave_offset(tdoa: np.ndarray, pairs: np.ndarray, positions: np.ndarray, device: np.ndarray,
                          weights: np.ndarray | None = None) -> tuple[np.ndarray, float, float]:
    """Least-squares plane wave plus inter-device clock offset from pair delays.

    Model: ``tdoa[p] = t_j - t_i = (r_j - r_i) . s + delta * (dev_j - dev_i)`` for
    pair ``(i, j) = pairs[p]`` with microphone positions ``r`` (m) and device
    indices ``dev`` (0/1). Returns ``(s, delta, rms_residual)``: slowness vector
    ``s = -u / c`` (s/m, u the source direction), ``delta`` (s), residual (s).
    One pass of outlier rejection drops pairs whose residual exceeds 3x the median.
    """
    i, j = pairs[:, 0], pairs[:, 1]
    a = np.column_stack([positions[j] - positions[i], (device[j] - device[i]).astype(float)])
    w = np.ones(len(tdoa)) if weights is None else np.asarray(weights, float)
    use = np.ones(len(tdoa), bool)
    for _ in range(2):
        sw = np.sqrt(w[use])
        sol, *_ = np.linalg.lstsq(a[use] * sw[:, None], tdoa[use] * sw, rcond=None)
        res = a @ sol - tdoa
        med = np.median(np.abs(res[use]))
        use = np.abs(res) <= max(3 * med, 2e-6)
    rms = float(np.sqrt(np.mean(res[use] ** 2)))
    return sol[:3], float(sol[3]), rms


class ChannelMerger:
    """Buffers two devices' blocks and emits aligned multichannel blocks (pure numpy).

    ``push`` takes ``(n_channels, n)`` blocks per device (int16 or float) in
    capture order; ``pop(n)`` returns ``(len(channel_map), n)`` with device 1
    shifted by the current offset, or None until enough of both is buffered.
    ``positions`` (one row per output channel, m, array frame) enables the
    plane-wave refinement of the offset.
    """

    def __init__(self, sample_rate: int, config: MergeConfig = MergeConfig(), positions: np.ndarray | None = None,
                 sound_speed: float = SOUND_SPEED) -> None:
        if sample_rate <= 0:
            raise ValueError(f"sample_rate: expected > 0 Hz, got {sample_rate}")
        self.fs = int(sample_rate)
        self.config = config
        self.c = float(sound_speed)
        if positions is not None:
            positions = np.asarray(positions, float)
            if positions.shape != (len(config.channel_map), 3):
                raise ValueError(
                    f"positions: expected ({len(config.channel_map)}, 3) microphone positions in channel-map order, "
                    f"got shape {positions.shape}"
                )
        self.positions = positions
        self.offset = 0
        self.estimate: OffsetEstimate | None = None
        self.dropped = 0          # device-0 samples skipped because device 1 had no data for them
        self.slips = 0            # offset jumps beyond drift found (and corrected) by ``track``
        self._buf = [np.zeros((n, 0), np.int16) for n in config.device_channels]
        self._start = [0, 0]      # stream index of each buffer's first column
        self._cursor = 0          # device-0 stream index of the next output sample
        # (device-0 index, offset): a slip measured on audio ahead of the cursor applies from where it happened,
        # not to the audio before it still waiting to be popped
        self._pending: tuple[int, int] | None = None

    # -- buffering --------------------------------------------------------------
    def push(self, device: int, samples: np.ndarray, start_index: int | None = None) -> None:
        """Append a block of ``device`` (0/1). ``start_index``: its stream index if known (a gap drops the buffer)."""
        if device not in (0, 1):
            raise ValueError(f"device: expected 0 or 1, got {device}")
        x = np.asarray(samples)
        n_ch = self.config.device_channels[device]
        if x.ndim != 2 or x.shape[0] != n_ch:
            raise ValueError(f"samples of device {device}: expected shape ({n_ch}, n), got {x.shape}")
        buf = self._buf[device]
        end = self._start[device] + buf.shape[1]
        if start_index is not None and start_index != end:
            if start_index < end:
                raise ValueError(f"start_index {start_index} of device {device} overlaps buffered data (ends {end})")
            log.warning("device %d: %d samples missing in the capture; dropping its buffer", device, start_index - end)
            buf, self._start[device] = buf[:, :0], int(start_index)
        if buf.dtype != np.int16 or x.dtype != np.int16:  # int16 stays int16; anything else -> float
            buf, x = as_float_audio(buf), as_float_audio(x)
        self._buf[device] = np.concatenate([buf, x], axis=1)
        self._trim()

    def _end(self, d: int) -> int:
        return self._start[d] + self._buf[d].shape[1]

    def _clamp_cursor(self) -> None:
        lo = max(self._start[0], self._start[1] - self.offset)
        if self._cursor < lo:
            self.dropped += lo - self._cursor
            self._cursor = lo

    def _apply_pending(self) -> None:
        if self._pending is not None and self._cursor >= self._pending[0]:
            self.offset, self._pending = self._pending[1], None

    @property
    def latest_offset(self) -> int:
        """The offset of the newest audio (the current one unless a slip ahead of the cursor is pending)."""
        return self.offset if self._pending is None else self._pending[1]

    def available(self) -> int:
        """Aligned samples per channel that ``pop`` can return now."""
        self._apply_pending()
        self._clamp_cursor()
        c = self._cursor
        n = max(0, min(self._end(0) - c, self._end(1) - (c + self.offset)))
        if self._pending is not None and n >= self._pending[0] - c:
            at, new = self._pending
            n = max(at - c, min(self._end(0) - c, self._end(1) - (c + new)))
        return n

    def lacking(self, n: int) -> int | None:
        """The device whose data ``pop(n)`` waits for most (0/1), or None if ``n`` samples are ready."""
        if self.available() >= n:
            return None
        c = self._cursor
        need1 = c + self.offset + n - self._end(1)
        if self._pending is not None and c + n > self._pending[0]:
            at, new = self._pending
            need1 = max(at + self.offset - self._end(1), c + n + new - self._end(1))
        need = [c + n - self._end(0), need1]
        return int(np.argmax(need))

    def pop(self, n: int) -> np.ndarray | None:
        """The next ``n`` aligned samples, shape (n_outputs, n); None if not yet available."""
        if self.available() < n:
            return None
        if self._pending is not None and self._cursor + n > self._pending[0]:
            k = self._pending[0] - self._cursor      # up to the slip with the old offset, then the new one
            return np.concatenate([self.pop(k), self.pop(n - k)], axis=1)
        segs = []
        for d in (0, 1):
            a = self._cursor + (self.offset if d else 0) - self._start[d]
            segs.append(self._buf[d][:, a:a + n])
        if segs[0].dtype != segs[1].dtype:
            segs = [as_float_audio(s) for s in segs]
        out = np.stack([segs[d][c] for d, c in self.config.channel_map])
        self._cursor += n
        self._trim()
        return out

    def discard_pending(self) -> int:
        """Skip everything buffered but not yet popped (stale audio); returns the samples skipped."""
        before = self._cursor
        if self._pending is not None:   # the newest audio is past the slip
            self.offset, self._pending = self._pending[1], None
        self._cursor = max(self._cursor, min(self._end(0), self._end(1) - self.offset))
        return self._cursor - before

    @property
    def cursor(self) -> int:
        """Device-0 stream index of the next output sample."""
        return self._cursor

    def _trim(self) -> None:
        keep = int(self.config.history_s * self.fs)
        # History is kept behind the newest audio BOTH devices have (device-0 index): a device that runs ahead
        # (e.g. delivered a burst) must not drop the span the lagging one needs for the offset estimate.
        lo_offset = min(self.offset, self.latest_offset)
        common_end = min(self._end(0), self._end(1) - lo_offset)
        for d in (0, 1):
            shift = lo_offset if d else 0
            cut = min(self._cursor + shift, common_end + shift - keep) - self._start[d]
            if cut > 0:
                self._buf[d] = self._buf[d][:, cut:]
                self._start[d] += cut

    # -- offset -----------------------------------------------------------------
    def set_offset(self, offset: int, from_index: int | None = None) -> None:
        """Use ``offset`` samples (device-1 index minus device-0 index) from the next pop on, or from device-0
        stream index ``from_index`` on when that is still ahead of the cursor."""
        if from_index is None or from_index <= self._cursor:
            self.offset, self._pending = int(offset), None
        else:
            self._pending = (int(from_index), int(offset))

    def estimate_offset(self, window_s: float = 0.5, search_s: float | None = None,
                        centre: int | None = None) -> OffsetEstimate:
        """Measure the offset on the most recent ``window_s`` of buffered audio of both devices.

        ``search_s``: how far from the current offset to search (default
        ``max_offset_s``; a few ms is enough to track drift). Does not apply the
        result; see ``calibrate``. ``centre``: search around this offset instead of the current one.
        """
        cfg = self.config
        k = self.latest_offset if centre is None else int(centre)
        search = cfg.max_offset_s if search_s is None else float(search_s)
        L = int(round(window_s * self.fs))
        m = int(np.ceil(search * self.fs))
        # Device-0 window [a, a+L); device-1 window extended by m on both sides around the current offset.
        a = min(self._end(0) - L, self._end(1) - k - L - m)
        if L < 64 or a < self._start[0] or a + k - m < self._start[1]:
            have = min(self._end(0) - self._start[0], self._end(1) - self._start[1]) / self.fs
            raise ValueError(
                f"window_s: need {window_s} s (+{2 * search:g} s search) of audio from both devices for the offset "
                f"estimate, have {have:.2f} s"
            )
        r0, r1 = cfg.reference
        x = as_float_audio(self._buf[0][r0, a - self._start[0]:a - self._start[0] + L])
        b = a + k - m - self._start[1]
        y = as_float_audio(self._buf[1][r1, b:b + L + 2 * m])
        lag, peak = gcc_phat_lag(x, y, self.fs, (0, 2 * m), cfg.band_hz)
        exact = k + (lag - m) - cfg.expected_tdoa_s * self.fs
        confident = peak >= cfg.min_peak
        fit_res = direction = None
        if self.positions is not None and confident:
            coarse = int(round(exact))
            # Re-cut device 1 at the coarse offset so every pair delay is acoustic plus a small residual.
            b = a + coarse - self._start[1]
            if b >= 0 and b + L <= self._buf[1].shape[1]:
                seg0 = as_float_audio(self._buf[0][:, a - self._start[0]:a - self._start[0] + L])
                delta_s, direction, fit_res = self._refine(seg0, as_float_audio(self._buf[1][:, b:b + L]))
                exact = coarse + delta_s * self.fs
                confident = fit_res <= cfg.max_fit_residual_s
        return OffsetEstimate(int(round(exact)), float(exact), peak, fit_res, direction, bool(confident), (a, a + L))

    def _slip_start(self, old: int, new: int, window: tuple[int, int], seg: int = 1024) -> int:
        """Device-0 index from which the offset is ``new`` rather than ``old``: the start of the first 64 ms
        segment between the cursor and the end of the measuring ``window`` whose coarse GCC-PHAT lag (on the
        reference channels) is confidently nearer ``new``; the window's start if none is."""
        cfg = self.config
        r0, r1 = cfg.reference
        lo_lag, hi_lag = min(old, new) - 4, max(old, new) + 4
        first = max(self._cursor, self._start[0], self._start[1] - lo_lag)
        last = min(window[1], self._end(0), self._end(1) - hi_lag) - seg
        expected = cfg.expected_tdoa_s * self.fs
        for s0 in range(first, last + 1, seg):
            x = as_float_audio(self._buf[0][r0, s0 - self._start[0]:s0 - self._start[0] + seg])
            b = s0 + lo_lag - self._start[1]
            y = as_float_audio(self._buf[1][r1, b:b + seg + hi_lag - lo_lag])
            lag, peak = gcc_phat_lag(x, y, self.fs, (0, hi_lag - lo_lag), cfg.band_hz)
            k = lo_lag + lag - expected
            if peak >= cfg.min_peak and abs(k - new) < abs(k - old):
                return s0
        return window[0]

    def _refine(self, seg0: np.ndarray, seg1: np.ndarray) -> tuple[float, np.ndarray, float]:
        cmap = self.config.channel_map
        sig = [seg0[c] if d == 0 else seg1[c] for d, c in cmap]
        dev = np.array([d for d, _ in cmap])
        pos = self.positions
        pairs = np.array(list(combinations(range(len(cmap)), 2)))
        slack = 2.0  # samples of coarse-offset uncertainty allowed beyond the geometric delay
        tdoa, w = np.empty(len(pairs)), np.empty(len(pairs))
        ref_dist = np.max(np.linalg.norm(pos[:, None] - pos[None], axis=-1))
        for p, (i, j) in enumerate(pairs):
            max_lag = np.linalg.norm(pos[i] - pos[j]) / self.c * self.fs + slack
            if dev[i] != dev[j]:
                max_lag += ref_dist / self.c * self.fs  # the coarse lag may hold the reference mics' delay
            lag, pk = gcc_phat_lag(sig[i], sig[j], self.fs, (-max_lag, max_lag), self.config.band_hz, upsample=8)
            tdoa[p], w[p] = lag / self.fs, max(pk, 1e-3)
        s, delta, rms = fit_plane_wave_offset(tdoa, pairs, pos, dev, w)
        norm = np.linalg.norm(s)
        direction = -s / norm if norm > 0 else np.zeros(3)
        return delta, direction, rms

    def track(self, window_s: float = 0.5, search_s: float = 0.002, slip: float | None = None) -> OffsetEstimate | None:
        """Follow the offset during a mission; applies and returns a changed, confident estimate, else None.

        Re-measures within ``search_s`` of the current offset (clock drift, a sample now and then). When
        that finds nothing trustworthy, or its peak sits at the edge of the search (the true offset may
        lie beyond: the streams slipped, e.g. samples lost in a driver), the whole ``max_offset_s`` is
        searched again (re-calibration): a narrow search alone once applied -30 for an 80-sample slip.

        ``slip``: samples by which device 1's stream was seen to slip (``ssl_core.health``'s ``device_slip``:
        positive = device 1 later): the narrow search is made around ``offset + slip`` first. In a reverberant
        room the whole-range search alone locked an 80-sample slip to a reflection 4 samples off."""
        hinted = None
        if slip is not None and math.isfinite(slip):
            hinted = self.estimate_offset(window_s, search_s, centre=self.latest_offset + int(round(slip)))
            hinted = hinted if hinted.confident else None
        est = hinted or self.estimate_offset(window_s, search_s)
        at_edge = abs(est.offset_exact - self.latest_offset) >= search_s * self.fs - 1.5
        if hinted is None and (not est.confident or at_edge):
            est = self.estimate_offset(window_s, self.config.max_offset_s)
        current = self.latest_offset
        if not est.confident or est.offset == current:
            return None
        jump = est.offset - current
        if abs(jump) > 2:  # beyond clock drift between two tracks
            self.slips += 1
            at = self._slip_start(current, est.offset, est.window) if est.window else None
            log.warning("audio devices slipped by %+d samples (%.1f ms): offset %d -> %s%s", jump,
                        1e3 * jump / self.fs, current, est,
                        f", from sample {at}" if at is not None and at > self._cursor else "")
            self.set_offset(est.offset, from_index=at)
        else:
            log.info("device offset drifted %d -> %s", current, est)
            self.set_offset(est.offset)
        self.estimate = est
        return est

    def calibrate(self, window_s: float = 0.5, search_s: float | None = None) -> OffsetEstimate:
        """Estimate the offset and apply it when the estimate is confident."""
        est = self.estimate_offset(window_s, search_s)
        if est.confident:
            if est.offset != self.offset:
                log.info("device offset %d -> %s", self.offset, est)
            self.set_offset(est.offset)
            self.estimate = est
        else:
            log.warning("device offset not updated (estimate not confident): %s", est)
        return est


# -- live capture (sounddevice) --------------------------------------------------

def import_sounddevice():
    """The ``sounddevice`` module, or an ImportError saying how to install it."""
    try:
        import sounddevice
    except ImportError as exc:  # also raised as OSError when PortAudio itself is missing
        raise ImportError(
            "live audio capture needs the optional 'sounddevice' package: pip install 'ssl-rescue[hardware]' "
            "(or pip install sounddevice) and the PortAudio library (Debian/Raspberry Pi OS: apt install libportaudio2)"
        ) from exc
    except OSError as exc:
        raise ImportError(f"sounddevice is installed but PortAudio could not be loaded ({exc}); "
                          "apt install libportaudio2") from exc
    return sounddevice


def _resolve_device(sd, spec, n_channels: int, fs: int) -> int:
    spec_v = int(spec) if isinstance(spec, str) and spec.strip().isdigit() else spec
    try:
        info = sd.query_devices(spec_v, kind="input")
    except (ValueError, sd.PortAudioError) as exc:
        names = [f"  {i}: {d['name']} ({d['max_input_channels']} in)"
                 for i, d in enumerate(sd.query_devices()) if d["max_input_channels"] > 0]
        raise ValueError(
            f"audio device {spec!r} not found or ambiguous ({exc}); input devices:\n" + ("\n".join(names) or "  (none)")
            + "\nGive a device index or a unique part of its name (two identical cameras: use the indices)."
        ) from exc
    if info["max_input_channels"] < n_channels:
        raise ValueError(f"audio device {spec!r} ({info['name']}) has {info['max_input_channels']} input channels, "
                         f"expected {n_channels}")
    return int(info["index"]) if "index" in info else int(spec_v)


class ArrayCapture(AudioSource):
    """The 8-microphone array as two USB devices, merged by a ``ChannelMerger``.

    ``devices``: two device specs for sounddevice (index or unique name part).
    ``positions``: microphone positions in output order (e.g. ``cube8().positions``)
    enable the plane-wave offset refinement and drift tracking every
    ``track_every_s`` seconds of audio read (None = never). ``backend``: the
    sounddevice module (injected in tests); imported lazily otherwise.
    """

    def __init__(self, devices, sample_rate: int = 16000, config: MergeConfig = MergeConfig(),
                 positions: np.ndarray | None = None, blocksize: int = 1024, queue_s: float = 10.0,
                 timeout_s: float = 2.0, track_every_s: float | None = 10.0, clock: Clock | None = None,
                 backend=None) -> None:
        devices = tuple(devices)
        if len(devices) != 2:
            raise ValueError(f"devices: expected two audio devices (A, B), got {len(devices)}: {devices}")
        self._sd = backend if backend is not None else import_sounddevice()
        self.merger = ChannelMerger(sample_rate, config, positions)
        self.config = config
        self.timeout_s = float(timeout_s)
        self.track_every_s = track_every_s
        self.clock = clock or WallClock()
        self.overflows = 0
        self._overflows_tracked = 0
        self._rate = int(sample_rate)
        n_q = max(4, int(queue_s * sample_rate / blocksize))
        self._queues = [queue.Queue(maxsize=n_q) for _ in (0, 1)]
        self._count = [0, 0]
        self._lock = threading.Lock()
        self._since_track = 0
        idx = [_resolve_device(self._sd, spec, config.device_channels[d], sample_rate)
               for d, spec in enumerate(devices)]
        self._streams = []
        try:
            for d in (0, 1):
                self._streams.append(self._sd.InputStream(
                    device=idx[d], channels=config.device_channels[d], samplerate=sample_rate, dtype="int16",
                    blocksize=blocksize, callback=self._callback(d)))
            self._t0 = self.clock.now()
            for s in self._streams:
                s.start()
        except Exception:
            self.close()
            raise

    def _callback(self, d: int):
        def cb(indata, frames, time_info, status) -> None:  # runs on the PortAudio thread
            if status and getattr(status, "input_overflow", False):
                self.overflows += 1  # samples were lost inside the driver: the offset may have changed
            with self._lock:
                start = self._count[d]
                self._count[d] += frames
            try:
                self._queues[d].put_nowait((start, np.array(indata[:frames].T, copy=True)))
            except queue.Full:
                self.overflows += 1  # the reader is too slow: this block is lost (merger sees the gap)
        return cb

    @property
    def sample_rate(self) -> int:
        return self._rate

    @property
    def n_channels(self) -> int:
        return len(self.config.channel_map)

    def _drain(self, block: bool) -> None:
        for d in (0, 1):
            while True:
                try:
                    start, x = self._queues[d].get(timeout=self.timeout_s) if block else self._queues[d].get_nowait()
                except queue.Empty:
                    if block:
                        raise TimeoutError(f"audio device {d} delivered no audio for {self.timeout_s} s "
                                           "(unplugged, or the stream stopped?)") from None
                    break
                self.merger.push(d, x, start)
                block = False

    def read(self, n_samples: int) -> AudioBlock:
        n = int(n_samples)
        if n <= 0:
            raise ValueError(f"n_samples: expected a positive integer, got {n_samples!r}")
        self._drain(block=False)
        while (d := self.merger.lacking(n)) is not None:
            start, x = self._get(d)
            self.merger.push(d, x, start)
        t = self._t0 + self.merger.cursor / self._rate
        out = self.merger.pop(n)
        self._since_track += n
        # Track on schedule, and at once after lost samples (an overflow can shift one device's stream).
        due = self.track_every_s is not None and self._since_track >= self.track_every_s * self._rate
        if self.merger.positions is not None and (due or self.overflows != self._overflows_tracked):
            try:
                self.merger.track(window_s=0.5, search_s=0.002)
                self._since_track, self._overflows_tracked = 0, self.overflows
            except ValueError as exc:  # not enough audio buffered yet: try again on a later read
                log.debug("offset tracking skipped: %s", exc)
        return AudioBlock(out, self._rate, t)

    def resync(self, slip_samples: float | None = None) -> None:
        """Track the devices' offset now rather than on schedule (e.g. the health monitor saw a slip of
        ``slip_samples``, device 1 later)."""
        if self.merger.positions is None:
            return
        try:
            self.merger.track(window_s=0.5, search_s=0.002, slip=slip_samples)
            self._since_track = 0
        except ValueError as exc:
            log.debug("offset re-sync skipped: %s", exc)

    def _get(self, d: int):
        try:
            return self._queues[d].get(timeout=self.timeout_s)
        except queue.Empty:
            raise TimeoutError(f"audio device {d} delivered no audio for {self.timeout_s} s "
                               "(unplugged, or the stream stopped?)") from None

    def flush(self) -> None:
        self._drain(block=False)
        self.merger.discard_pending()

    def calibrate(self, seconds: float = 1.0, search_s: float | None = None) -> OffsetEstimate:
        """Listen for ``seconds`` (clap, or speak near the robot), then measure and apply the offset.

        The estimate uses the last ``seconds - 2 * search_s`` (at least 0.1 s)
        of that audio; the rest is the search margin."""
        search = self.config.max_offset_s if search_s is None else float(search_s)
        n = int(seconds * self._rate)
        got = 0
        while got < n:
            got += self.read(min(n - got, 4096)).samples.shape[1]
        window = min(max(0.1, seconds - 2 * search), self.config.history_s - 2 * search)
        return self.merger.calibrate(window_s=window, search_s=search)

    def close(self) -> None:
        for s in getattr(self, "_streams", []):
            try:
                s.stop()
                s.close()
            except Exception as exc:  # closing must not hide the error that made us close
                log.warning("closing audio stream failed: %s", exc)
        self._streams = []


def list_input_devices(backend=None) -> list[str]:
    """Human-readable lines for every input device sounddevice sees."""
    sd = backend if backend is not None else import_sounddevice()
    return [f"{i}: {d['name']} ({d['max_input_channels']} in, {d['default_samplerate']:.0f} Hz)"
            for i, d in enumerate(sd.query_devices()) if d["max_input_channels"] > 0]
