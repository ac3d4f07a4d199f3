"""Ego-noise suppression: the simulated robot drives with its motors audible; the caller's direction and the
motors' silence checked against the simulator's geometry (tests/ego_drive.py)."""
import numpy as np
import pytest

from ego_drive import caller_track_errors, calibration_template, drive, suppressor
from robot.ego_calibration import MotorMount
from ssl_core.ego_noise import EgoNoiseConfig, EgoNoiseSuppressor, EgoNoiseTemplate
from ssl_core.geometry import cube8
from ssl_core.localizer import Localizer, LocalizerConfig
from ssl_sim.acoustics.ego_noise import EgoNoiseConfig as SimEgoNoise


@pytest.fixture(scope="module")
def template():
    return calibration_template()


def test_caller_tracked_while_driving_sideways_at_0p2_m_s(template):
    err = caller_track_errors(suppressor(template), speed=0.2, seconds=6.0, seed=1)
    assert len(err) >= 5
    assert np.mean(err <= 10.0) >= 0.8, err
    assert np.median(err) <= 5.0, err
    off = caller_track_errors(None, speed=0.2, seconds=6.0, seed=1)   # the same drive, no suppression
    assert np.mean(off <= 10.0) < 0.8 or np.median(off) > 5.0, off


def test_silent_room_while_driving_confirms_no_track(template):
    twists = [(0.0, 0.2, 0.0), (0.2, 0.0, 0.0), (0.0, -0.3, 0.0), (0.0, 0.0, 0.8), (-0.1, 0.0, 0.0)]
    assert drive(suppressor(template), twists, 3.0, start=(3.0, 3.0, 0.0), with_caller=False) == []
    # control: the motors alone make tracks without the suppression
    assert drive(None, twists, 3.0, start=(3.0, 3.0, 0.0), with_caller=False) != []


def test_calibration_file_carries_the_simulated_motors_level_law_and_mesh_tone(template, tmp_path):
    path = tmp_path / "ego.npz"
    template.save(path)
    t = EgoNoiseTemplate.load(path)
    np.testing.assert_array_equal(t.psd, template.psd)
    assert t.channels == 8 and t.fs == 16000
    sim = SimEgoNoise()
    # level: +20 lg(speed ratio) (the simulated motors' law), from 3.5 to 17 rad/s, where the motors are far
    # above the room's 30 dB SPL ambient
    k = (t.speeds_rad_s > 3.0)
    slope = np.polyfit(20 * np.log10(t.speeds_rad_s[k]), t.level_dbfs[k], 1)[0]
    assert 0.85 <= slope <= 1.15, (t.speeds_rad_s, t.level_dbfs)
    # spectrum: the strongest line above 300 Hz is a harmonic of the gear mesh at that speed
    for s, p in zip(t.speeds_rad_s, t.psd):
        if s < 3.0:
            continue
        band = t.freqs_hz >= 300
        f_peak = t.freqs_hz[band][np.argmax(p[band])]
        f_mesh = float(sim.mesh_hz(s))
        h = max(1, round(f_peak / f_mesh))
        assert abs(f_peak - h * f_mesh) <= 0.03 * h * f_mesh + 31.25, (s, f_peak, f_mesh)


def test_standing_still_the_localizer_is_unchanged(template):
    rng = np.random.default_rng(0)
    x = rng.normal(size=(8, 16000)).astype(np.float32) * 0.01
    x[:, 3:] += 0.2 * x[:, :-3]   # a correlated component, so there is a peak to find
    cfg = LocalizerConfig()
    plain = Localizer(cube8(), cfg).locate(x, 16000)
    with_sup = Localizer(cube8(), cfg, ego_noise=suppressor(template)).locate(x, 16000, wheel_speeds=[0, 0, 0])
    assert [(d.azimuth, d.elevation, d.power) for d in plain.detections] == \
        [(d.azimuth, d.elevation, d.power) for d in with_sup.detections]


def test_motor_mount_matches_the_drive_geometry():
    m = MotorMount().motor_positions()
    assert m.shape == (3, 3)
    az = np.degrees(np.arctan2(m[:, 1], m[:, 0]))
    np.testing.assert_allclose(az, [60.0, 180.0, -60.0], atol=1e-9)   # on the wheel axles
    np.testing.assert_allclose(m[:, 2], 0.05 - 0.27)


def test_bad_input_is_named(template, tmp_path):
    with pytest.raises(ValueError, match="motor_positions"):
        EgoNoiseConfig(motor_positions=((0.0, 0.0),))
    with pytest.raises(ValueError, match="over_subtraction"):
        EgoNoiseConfig(motor_positions=((0.0, 0.0, -0.2),), over_subtraction=0.0)
    with pytest.raises(ValueError, match="template"):
        EgoNoiseSuppressor(cube8(), EgoNoiseConfig(motor_positions=((0.0, 0.0, -0.2),)))
    with pytest.raises(ValueError, match="wheel_speeds"):
        Localizer(cube8(), LocalizerConfig(), ego_noise=suppressor(template)).process(
            np.zeros((8, 512), np.float32), 16000, wheel_speeds=[1.0, 2.0])
    bad = tmp_path / "bad.npz"
    np.savez(bad, format="something-else")
    with pytest.raises(ValueError, match="format"):
        EgoNoiseTemplate.load(bad)
    with pytest.raises(ValueError, match="psd"):
        EgoNoiseTemplate(16000, np.array([1.0, 2.0]), np.array([1.0]), np.zeros((2, 2)), np.zeros(1))


class _Audio:
    sample_rate, n_channels = 16000, 8

    def __init__(self):
        self.rng = np.random.default_rng(5)

    def flush(self):
        pass

    def read(self, n):
        from robot.hal import AudioBlock
        return AudioBlock((0.01 * self.rng.normal(size=(8, n))).astype(np.float32), 16000, 0.0)


class _Drive:
    def __init__(self, speeds):
        self.speeds, self.reads = np.asarray(speeds, float), 0

    def odometry(self):
        from robot.hal import WheelOdometry
        self.reads += 1
        return WheelOdometry(0.0, np.zeros(3), self.speeds)


class _SpyLocalizer(Localizer):
    def locate(self, recording, fs=None, wheel_speeds=None):
        self.seen = wheel_speeds
        return super().locate(recording, fs, wheel_speeds=wheel_speeds)


def test_listener_passes_the_wheel_speeds_only_to_a_suppressing_localizer(template):
    from robot.hal import ManualClock
    from robot.listening import Listener

    drive = _Drive([2.0, -4.0, 2.0])
    loc = _SpyLocalizer(cube8(), LocalizerConfig(), ego_noise=suppressor(template))
    Listener(_Audio(), ManualClock(), loc, None, drive=drive).listen(0.5, 0.0, 0.0)
    np.testing.assert_allclose(loc.seen, [2.0, -4.0, 2.0])
    plain = _SpyLocalizer(cube8(), LocalizerConfig())
    drive = _Drive([2.0, -4.0, 2.0])
    Listener(_Audio(), ManualClock(), plain, None, drive=drive).listen(0.5, 0.0, 0.0)
    assert plain.seen is None and drive.reads == 0   # without a suppressor the drive is not even asked


def test_calibrate_cli_names_the_missing_drive(capsys):
    from robot.cli import main
    with pytest.raises(SystemExit):
        main(["calibrate-ego-noise", "--audio", "2,3"])
    assert "--serial" in capsys.readouterr().err
