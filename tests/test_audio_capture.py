"""Merging two 4-channel USB devices into the 8-channel array stream (no devices needed)."""
import sys
import threading
import time
import types

import numpy as np
import pytest

from robot.hardware.audio import (
    ArrayCapture,
    ChannelMerger,
    MergeConfig,
    fit_plane_wave_offset,
    gcc_phat_lag,
    import_sounddevice,
    parse_channel_map,
)
from ssl_core.geometry import cube8

FS = 16000
C = 343.0
G = cube8()


def _plane_wave(direction, n, seed):
    """8-channel far-field noise burst from unit ``direction`` (array frame), exact fractional delays."""
    rng = np.random.default_rng(seed)
    s = rng.standard_normal(n)
    f = np.fft.rfftfreq(n, 1 / FS)
    delays = -(G.positions @ direction) / C
    return np.fft.irfft(np.fft.rfft(s)[None] * np.exp(-2j * np.pi * f[None] * delays[:, None]), n)


def _unit(az_deg, el_deg):
    az, el = np.deg2rad(az_deg), np.deg2rad(el_deg)
    return np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])


def _devices(truth, offset, cmap=((0, 0), (0, 1), (0, 2), (0, 3), (1, 0), (1, 1), (1, 2), (1, 3))):
    """Raw streams of the two devices for array signals ``truth`` (8, n): device 1's stream holds
    the instant at device-0 index i at index i + offset. ``cmap[k]`` = (device, channel) of mic k."""
    n = truth.shape[1]
    dev = [np.zeros((4, n)), np.zeros((4, n))]
    for k, (d, c) in enumerate(cmap):
        dev[d][c] = truth[k]
    if offset >= 0:  # device 1 started earlier: it has `offset` extra samples before
        dev[1] = np.concatenate([0.01 * np.ones((4, offset)), dev[1]], axis=1)[:, :n]
    else:  # device 1 started later: it missed the first |offset| samples
        dev[1] = np.concatenate([dev[1][:, -offset:], np.zeros((4, -offset))], axis=1)
    return dev


def _feed(merger, dev, chunks=(480, 512)):
    """Interleave pushes with different block sizes per device (as two USB devices deliver)."""
    n = dev[0].shape[1]
    pos = [0, 0]
    while pos[0] < n or pos[1] < n:
        for d in (0, 1):
            if pos[d] < n:
                merger.push(d, dev[d][:, pos[d]:pos[d] + chunks[d]])
                pos[d] += chunks[d]


def test_gcc_phat_lag_recovers_a_known_delay():
    rng = np.random.default_rng(3)
    x = rng.standard_normal(4000)
    y = np.concatenate([np.zeros(123), x])[:4000]
    lag, peak = gcc_phat_lag(x, y, FS, (-300, 300))
    assert lag == pytest.approx(123, abs=0.05)
    assert peak > 0.9


@pytest.mark.parametrize("offset", [437, -1290, 0])
def test_known_offset_recovered_and_blocks_aligned(offset):
    truth = _plane_wave(_unit(35, -20), 2 * FS, seed=11)
    dev = _devices(truth, offset)
    m = ChannelMerger(FS, MergeConfig(), positions=G.positions)
    _feed(m, dev)
    est = m.calibrate(window_s=0.5)
    assert est.confident
    assert est.offset == offset
    assert est.fit_residual_s < 5e-6
    # the calibration sound's direction comes out of the fit as a by-product
    assert np.degrees(np.arccos(np.clip(est.direction @ _unit(35, -20), -1, 1))) < 3.0
    # Output: device 1 shifted by the offset, so every block equals the true 8-channel signals.
    out = m.pop(m.available())
    start = m.cursor - out.shape[1]
    np.testing.assert_allclose(out, truth[:, start:start + out.shape[1]], atol=1e-12)
    assert out.shape[1] > FS // 2


def test_coarse_only_needs_the_expected_delay():
    # Without mic positions the reference-channel lag holds the acoustic delay between the two
    # reference mics; with a known calibration direction `expected_tdoa_s` removes it.
    u = _unit(20, 10)
    truth = _plane_wave(u, 2 * FS, seed=5)
    acoustic = -(G.positions[4] - G.positions[0]) @ u / C  # t(mic 4) - t(mic 0), s
    assert abs(acoustic * FS) > 3  # a bias worth removing
    for expected, tol in ((0.0, abs(acoustic * FS) + 0.6), (acoustic, 0.6)):
        m = ChannelMerger(FS, MergeConfig(expected_tdoa_s=expected))
        _feed(m, _devices(truth, 250))
        est = m.estimate_offset(0.5)
        assert abs(est.offset_exact - 250) <= tol
    assert est.offset == 250
    assert est.fit_residual_s is None


def test_channel_map_applied():
    # Mic k of the array is wired to an arbitrary (device, channel).
    cmap = ((1, 2), (0, 0), (1, 0), (0, 3), (0, 1), (1, 3), (0, 2), (1, 1))
    truth = _plane_wave(_unit(120, 30), 2 * FS, seed=8)
    cfg = MergeConfig(channel_map=cmap)
    m = ChannelMerger(FS, cfg, positions=G.positions)
    _feed(m, _devices(truth, -600, cmap))
    assert m.calibrate().offset == -600
    out = m.pop(4000)
    start = m.cursor - 4000
    np.testing.assert_allclose(out, truth[:, start:start + 4000], atol=1e-12)


def test_parse_channel_map():
    assert parse_channel_map("A0,A1,A2,A3,B0,B1,B2,B3") == MergeConfig().channel_map
    assert parse_channel_map("1:2, 0:0,b1") == ((1, 2), (0, 0), (1, 1))
    with pytest.raises(ValueError, match="entry 1"):
        parse_channel_map("A0,C1")
    with pytest.raises(ValueError, match="used twice"):
        MergeConfig(channel_map=((0, 0), (0, 0)))
    with pytest.raises(ValueError, match=r"channel_map\[1\]: device 1 has channels 0..3"):
        MergeConfig(channel_map=((0, 0), (1, 4)))


def test_int16_passes_through_and_stale_audio_is_skipped():
    rng = np.random.default_rng(2)
    m = ChannelMerger(FS)
    a = rng.integers(-1000, 1000, (4, 3000)).astype(np.int16)
    b = rng.integers(-1000, 1000, (4, 3000)).astype(np.int16)
    m.push(0, a)
    m.push(1, b)
    out = m.pop(1000)
    assert out.dtype == np.int16
    np.testing.assert_array_equal(out, np.vstack([a[:, :1000], b[:, :1000]]))
    assert m.discard_pending() == 2000 and m.available() == 0
    m.push(0, a[:, :100])
    assert m.pop(100) is None  # device 1 has nothing new yet
    m.push(1, b[:, :100])
    np.testing.assert_array_equal(m.pop(100), np.vstack([a[:, :100], b[:, :100]]))


def test_gap_in_one_device_skips_the_unmatched_samples():
    m = ChannelMerger(FS)
    m.push(0, np.ones((4, 1000)))
    m.push(1, np.ones((4, 400)))
    m.push(1, 2 * np.ones((4, 600)), start_index=700)  # 300 samples of device 1 were lost
    out = m.pop(m.available())
    assert out.shape[1] == 300  # device-0 samples 700..999 after the gap
    assert m.dropped == 700 and np.all(out[4:] == 2)


def test_plane_wave_fit_separates_offset_from_direction():
    rng = np.random.default_rng(0)
    pos = G.positions
    dev = np.array([0, 0, 0, 0, 1, 1, 1, 1])
    pairs = np.array([(i, j) for i in range(8) for j in range(i + 1, 8)])
    s_true = -_unit(200, -40) / C
    t = pos @ s_true + 1.7e-4 * dev
    tdoa = t[pairs[:, 1]] - t[pairs[:, 0]] + 2e-7 * rng.standard_normal(len(pairs))
    tdoa[5] += 3e-4  # one wild pair
    s, delta, rms = fit_plane_wave_offset(tdoa, pairs, pos, dev)
    assert delta == pytest.approx(1.7e-4, abs=2e-6)
    np.testing.assert_allclose(s, s_true, atol=5e-5)


# --- ArrayCapture on a fake sounddevice backend ---------------------------------

class _FakeSD(types.SimpleNamespace):
    """Just the parts of sounddevice that ArrayCapture uses; streams replay given arrays."""

    class PortAudioError(Exception):
        pass

    def __init__(self, streams, names=("USB Camera-B4.09.24.1", "USB Camera-B4.09.24.1"), pace=0.0, lag=(0.0, 0.0)):
        super().__init__()
        self.pace = pace  # wall seconds per second of audio delivered (0: all at once)
        self.lag = lag    # per device: wall seconds before its stream delivers anything
        self._data = streams
        self._names = names
        self.opened = []

    def query_devices(self, device=None, kind=None):
        devs = [{"name": "bcm2835 Headphones", "max_input_channels": 0, "default_samplerate": 48000.0}] + [
            {"name": n, "max_input_channels": 4, "default_samplerate": 16000.0} for n in self._names]
        if device is None:
            return devs
        if isinstance(device, int):
            if not 0 <= device < len(devs):
                raise self.PortAudioError(f"Error querying device {device}")
            return {**devs[device], "index": device}
        hits = [i for i, d in enumerate(devs) if device.lower() in d["name"].lower() and d["max_input_channels"]]
        if len(hits) != 1:
            raise ValueError(("Multiple" if hits else "No") + f" input devices found for {device!r}")
        return {**devs[hits[0]], "index": hits[0]}

    def InputStream(self, device, channels, samplerate, dtype, blocksize, callback):
        sd = self

        class Stream:
            def start(self_):
                data = (np.asarray(sd._data[device - 1]).T * 32767).astype(np.int16)  # (frames, channels)

                self_.stopped = False

                def run():
                    time.sleep(sd.lag[device - 1])
                    for i in range(0, len(data), blocksize):
                        if self_.stopped:
                            break
                        chunk = data[i:i + blocksize]
                        callback(chunk, len(chunk), None, None)
                        if sd.pace:
                            time.sleep(sd.pace * len(chunk) / samplerate)
                self_.thread = threading.Thread(target=run, daemon=True)
                self_.thread.start()

            def stop(self_):
                self_.stopped = True
                self_.thread.join()

            def close(self_):
                sd.opened.remove(self_)

        s = Stream()
        self.opened.append(s)
        return s


def test_array_capture_calibrates_and_streams_aligned_blocks():
    truth = 0.3 * _plane_wave(_unit(-150, 25), 3 * FS, seed=21) / 4
    dev = _devices(truth, 811)
    sd = _FakeSD(dev)
    cap = ArrayCapture((1, "2"), FS, positions=G.positions, blocksize=512, track_every_s=None, backend=sd)
    assert (cap.n_channels, cap.sample_rate) == (8, FS)
    est = cap.calibrate(seconds=1.0)
    assert est.confident and est.offset == 811
    block = cap.read(8000)
    assert block.samples.shape == (8, 8000) and block.samples.dtype == np.int16
    start = cap.merger.cursor - 8000
    expected = (truth[:, start:start + 8000] * 32767).astype(np.int16)
    np.testing.assert_array_equal(block.samples, expected)
    assert block.timestamp > 0
    for s in sd.opened:
        s.thread.join()  # all audio delivered: flushing leaves nothing to read
    cap.flush()
    cap.timeout_s = 0.05
    with pytest.raises(TimeoutError, match="delivered no audio"):
        cap.read(16)
    cap.close()
    assert sd.opened == []


def test_calibration_when_one_device_delivers_far_ahead_of_the_other():
    # Device A hands over all 3 s at once, device B starts late and paced: A's audio behind the output cursor
    # must be kept for the offset estimate (trimming it against A's own newest audio failed under CPU load).
    truth = 0.3 * _plane_wave(_unit(-150, 25), 3 * FS, seed=21) / 4
    sd = _FakeSD(_devices(truth, 811), pace=0.05, lag=(0.0, 0.2))
    cap = ArrayCapture((1, 2), FS, positions=G.positions, blocksize=512, track_every_s=None, backend=sd)
    est = cap.calibrate(seconds=1.0)
    assert est.confident and est.offset == 811
    cap.close()


def test_array_capture_errors_are_clear(monkeypatch):
    sd = _FakeSD([np.zeros((4, 10)), np.zeros((4, 10))])
    with pytest.raises(ValueError, match=r"(?s)audio device 'USB Camera' not found or ambiguous.*1: USB Camera"):
        ArrayCapture(("USB Camera", 2), backend=sd)  # two identical names: indices are needed
    with pytest.raises(ValueError, match="audio device 7 not found"):
        ArrayCapture((1, 7), backend=sd)
    with pytest.raises(ValueError, match="devices: expected two"):
        ArrayCapture((1,), backend=sd)
    monkeypatch.setitem(sys.modules, "sounddevice", None)  # as if not installed
    with pytest.raises(ImportError, match=r"pip install 'ssl-rescue\[hardware\]'"):
        import_sounddevice()


def test_capture_tracks_a_drifting_offset():
    # Device 1 slips by 3 samples half way (e.g. clock drift): tracking re-measures near the offset.
    truth = 0.3 * _plane_wave(_unit(60, -10), 4 * FS, seed=4) / 4
    a = _devices(truth, 200)
    b = _devices(truth, 203)
    half = 2 * FS
    dev = [a[0], np.concatenate([a[1][:, :half], b[1][:, half:]], axis=1)]
    sd = _FakeSD(dev)
    cap = ArrayCapture((1, 2), FS, positions=G.positions, blocksize=512, track_every_s=0.5, backend=sd)
    cap.merger.set_offset(200)
    got = 0
    while got < 3 * FS:
        got += cap.read(1024).samples.shape[1]
    assert cap.merger.offset == 203
    block = cap.read(4000)
    start = cap.merger.cursor - 4000
    np.testing.assert_array_equal(block.samples, (truth[:, start:start + 4000] * 32767).astype(np.int16))
    cap.close()


@pytest.mark.parametrize("pace", [0.15, 0.0], ids=["live", "all_buffered"])
def test_capture_detects_and_corrects_a_5_ms_slip(pace):
    # Device 1's stream slips by 80 samples (5 ms, beyond the +-2 ms drift search) 2 s in: the tracker
    # must not apply a wrong nearby offset but find the new one (re-calibration), count and log it.
    # "all_buffered": the devices delivered everything before the reader asks (a reader slowed by a loaded CPU
    # lags the capture by seconds): the slip is measured on audio far ahead of the cursor and must apply from
    # where it happened, not to the audio before it.
    truth = 0.3 * _plane_wave(_unit(-40, 20), 5 * FS, seed=8) / 4
    before, after = _devices(truth, 200), _devices(truth, 280)
    at = 2 * FS  # device-1 index of the slip
    dev = [before[0], np.concatenate([before[1][:, :at], after[1][:, at:]], axis=1)]
    sd = _FakeSD(dev, pace=pace)  # live: delivered as a live device would, 0.15 s per s of audio
    cap = ArrayCapture((1, 2), FS, positions=G.positions, blocksize=512, track_every_s=0.5, backend=sd)
    cap.merger.set_offset(200)
    seen = []
    while cap.merger.cursor < 4 * FS:
        cap.read(1024)
        seen.append((cap.merger.cursor, cap.merger.offset))
    assert {o for _, o in seen} <= {200, 280}                 # never a wrong offset in between
    fixed = min(c for c, o in seen if o == 280)
    assert fixed + 280 >= at - 1024                           # not before the slip happened ...
    assert fixed - (at - 200) <= 1.5 * FS                     # ... and within 1.5 s of audio after it
    assert cap.merger.slips == 1
    if pace == 0.0:   # measured ahead of the cursor: switched in the read that holds the slip (to a 64 ms segment)
        assert fixed - 1024 <= (at - 200) + 1024
    block = cap.read(4000)
    start = cap.merger.cursor - 4000
    np.testing.assert_array_equal(block.samples, (truth[:, start:start + 4000] * 32767).astype(np.int16))
    cap.close()
