"""WAV replay source and dry-run drive."""
import math

import numpy as np
import pytest
from scipy.io import wavfile

from robot.hal import ManualClock
from robot.kinematics import OmniDriveParams
from robot.odometry import Odometry
from robot.replay import DryRunDrive, WavFileSource

FS = 16000


def _write(tmp_path, data, rate=FS, name="rec.wav"):
    p = tmp_path / name
    wavfile.write(p, rate, data)
    return p


@pytest.fixture
def pcm16(tmp_path):
    rng = np.random.default_rng(1)
    data = rng.integers(-20000, 20000, size=(1000, 8), dtype=np.int16)
    return _write(tmp_path, data), data


def test_blocks_are_the_file_in_order_with_timestamps(pcm16):
    path, data = pcm16
    src = WavFileSource(path, expected_channels=8, expected_rate=FS, start_time=10.0)
    assert (src.n_channels, src.sample_rate, src.n_samples) == (8, FS, 1000)
    b1 = src.read(300)
    b2 = src.read(300)
    assert b1.samples.shape == (8, 300) and b1.samples.dtype == np.int16
    np.testing.assert_array_equal(b1.samples, data[:300].T)
    np.testing.assert_array_equal(b2.samples, data[300:600].T)
    assert b1.timestamp == pytest.approx(10.0)
    assert b2.timestamp == pytest.approx(10.0 + 300 / FS)
    assert b1.sample_rate == FS


def test_eof_at_the_end(pcm16):
    path, data = pcm16
    src = WavFileSource(path)
    src.read(600)
    src.read(400)
    with pytest.raises(EOFError, match="end reached"):
        src.read(1)
    src.seek(0.05)  # 800 samples in
    np.testing.assert_array_equal(src.read(200).samples, data[800:].T)
    with pytest.raises(EOFError):
        src.read(10)


def test_int32_and_float_are_scaled_to_unit_range(tmp_path):
    t = np.arange(2000) / FS
    x = 0.5 * np.sin(2 * np.pi * 440 * t)
    multi = np.stack([x, -x, 0.25 * x, x], axis=1)
    p32 = _write(tmp_path, (multi * 2**31).astype(np.int32), name="i32.wav")
    pf = _write(tmp_path, multi.astype(np.float32), name="f32.wav")
    for p in (p32, pf):
        b = WavFileSource(p, expected_channels=4).read(2000)
        assert b.samples.dtype == np.float64
        np.testing.assert_allclose(b.samples, multi.T, atol=1e-6)


def test_mono_file_is_one_channel(tmp_path):
    p = _write(tmp_path, np.zeros(100, np.int16))
    assert WavFileSource(p).read(100).samples.shape == (1, 100)


def test_clear_errors(tmp_path, pcm16):
    path, _ = pcm16
    with pytest.raises(ValueError, match=r"has 8 channel\(s\), expected 4"):
        WavFileSource(path, expected_channels=4)
    with pytest.raises(ValueError, match="sample rate is 16000 Hz, expected 48000 Hz"):
        WavFileSource(path, expected_rate=48000)
    with pytest.raises(FileNotFoundError, match="nope.wav"):
        WavFileSource(tmp_path / "nope.wav")
    junk = tmp_path / "junk.wav"
    junk.write_bytes(b"not a wav file at all")
    with pytest.raises(ValueError, match="not a readable WAV"):
        WavFileSource(junk)
    with pytest.raises(ValueError, match="n_samples"):
        WavFileSource(path).read(0)


def test_reads_pace_the_clock(pcm16):
    path, _ = pcm16
    clock = ManualClock(5.0)
    src = WavFileSource(path, clock=clock)
    src.read(800)
    assert clock.now() == pytest.approx(5.0 + 800 / FS)


def test_dry_run_drive_integrates_ideal_odometry():
    clock = ManualClock()
    params = OmniDriveParams()
    drive = DryRunDrive(clock, params)
    odo = Odometry(params)
    odo.update(drive.odometry())
    drive.set_twist(0.2, 0.0, 0.0)
    clock.sleep(1.0)
    odo.update(drive.odometry())
    drive.set_twist(0.0, 0.0, np.pi / 4)
    clock.sleep(2.0)
    odo.update(drive.odometry())
    drive.set_twist(0.1, 0.0, 0.0)
    clock.sleep(1.0)
    drive.stop()
    clock.sleep(3.0)  # stopped: nothing moves
    odo.update(drive.odometry())
    np.testing.assert_allclose(odo.pose, [0.2, 0.1, np.pi / 2], atol=1e-9)
    assert [c.twist for c in drive.commands] == [(0.2, 0.0, 0.0), (0.0, 0.0, np.pi / 4), (0.1, 0.0, 0.0),
                                                (0.0, 0.0, 0.0)]
    assert drive.status().ok


def test_dry_run_drive_saturates_like_the_real_base():
    clock = ManualClock()
    drive = DryRunDrive(clock)
    drive.set_twist(10.0, 0.0, 0.0)  # far beyond the wheels' limit
    assert np.abs(drive.commands[-1].wheel_speeds).max() == pytest.approx(OmniDriveParams().max_wheel_speed)
    vx, vy, om = drive.twist
    assert vx > 0 and abs(vy) < 1e-12 and abs(om) < 1e-12
    with pytest.raises(ValueError, match="twist"):
        drive.set_twist(float("nan"), 0.0, 0.0)


@pytest.mark.parametrize("rate", [48000, 44100, 22050])
def test_a_replay_at_another_rate_is_resampled_block_by_block_as_the_whole_file(tmp_path, rate):
    """resample_to=16000: blocks of any size, read in turn, equal the whole file resampled at once
    (scipy.signal.resample_poly), sample for sample."""
    from scipy.signal import resample_poly
    x = (np.random.default_rng(1).standard_normal((rate * 2 + 37, 3)) * 3000).astype(np.int16)
    path = tmp_path / "x.wav"
    wavfile.write(path, rate, x)
    src = WavFileSource(path, resample_to=16000, min_rate=12000)
    g = math.gcd(16000, rate)
    whole = np.clip(np.round(resample_poly(x.astype(float), 16000 // g, rate // g, axis=0)), -32768, 32767).T
    assert src.sample_rate == 16000 and src.file_rate == rate and src.n_samples == whole.shape[1]
    blocks, sizes = [], [1600, 37, 4000, 999]
    while src.position + sizes[len(blocks) % 4] <= src.n_samples:
        blocks.append(src.read(sizes[len(blocks) % 4]).samples)
    got = np.concatenate(blocks, axis=1)
    assert got.dtype == np.int16 and np.array_equal(got, whole[:, :got.shape[1]].astype(np.int16))
    with pytest.raises(ValueError, match="sample rate 8000 Hz is too low"):
        wavfile.write(tmp_path / "y.wav", 8000, x)
        WavFileSource(tmp_path / "y.wav", resample_to=16000, min_rate=12000)
