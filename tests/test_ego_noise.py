"""The robot's ego-noise (ssl_sim.acoustics.ego_noise): level from the stated datasheet figure with
spherical spreading, +20 lg of the wheel-speed ratio, the gear-mesh tone where the gear train puts it,
and exactly nothing while the wheels stand still (independent truth: the stated figures and geometry)."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from ssl_sim.acoustics import AcousticConfig, AcousticSimulator
from ssl_sim.acoustics.ego_noise import EgoNoise, EgoNoiseConfig
from ssl_sim.scenario import load_scenario
from ssl_sim.world import Room, World

FS = 16000


def _free_field():
    world = World(room=Room((6.0, 5.0, 3.0), "anechoic", "anechoic", "anechoic"))
    return AcousticSimulator(world, AcousticConfig(ism_order=0, late_reverb=False, ambient=None), sources=[])


def _rms_db(x):
    return 20 * math.log10(float(np.sqrt(np.mean(x[:, FS // 4:] ** 2))) / 20e-6)


def test_level_follows_datasheet_figure_and_spreading():
    """One motor at rated speed, a microphone 0.25 m away in free field: 40 dB SPL at 1 m (60 dB(A) at
    10 cm) minus 20 lg(0.25) = 52.0 dB SPL."""
    cfg = EgoNoiseConfig()
    ego = EgoNoise(_free_field(), cfg)
    motors = np.array([[3.0, 2.5, 0.05], [5.0, 4.0, 2.0], [1.0, 1.0, 2.0]])
    mic = np.array([[3.0, 2.5, 0.30]])
    w = np.zeros((3, FS))
    w[0] = cfg.rated_speed
    p = ego.pressure(mic, motors, w, 0)
    assert _rms_db(p) == pytest.approx(cfg.level_db_spl_1m - 20 * math.log10(0.25), abs=0.5)


@pytest.mark.parametrize("ratio", [0.5, 0.25])
def test_level_scales_with_wheel_speed(ratio):
    cfg = EgoNoiseConfig()
    motors = np.array([[3.0, 2.5, 0.05], [3.1, 2.6, 0.05], [2.9, 2.6, 0.05]])
    mics = np.array([[3.0, 2.55, 0.30], [3.05, 2.5, 0.32]])
    full = EgoNoise(_free_field(), cfg).pressure(mics, motors, np.full((3, FS), cfg.rated_speed), 0)
    part = EgoNoise(_free_field(), cfg).pressure(mics, motors, np.full((3, FS), -ratio * cfg.rated_speed), 0)
    assert _rms_db(part) - _rms_db(full) == pytest.approx(20 * math.log10(ratio), abs=0.5)


def test_mesh_tone_at_gear_train_frequency():
    """Wheel at 10 rad/s, 34:1 gearbox, 12-tooth pinion: mesh at 10 * 34 / (2 pi) * 12 = 649.4 Hz."""
    cfg = EgoNoiseConfig()
    sig = EgoNoise(_free_field(), cfg).source_signals(np.full((3, FS), 10.0), 0)[0]
    spec = np.abs(np.fft.rfft(sig * np.hanning(FS)))
    f = np.fft.rfftfreq(FS, 1 / FS)
    # Motor 0 runs 1 % slow (speed tolerance, see the module docstring).
    assert f[np.argmax(spec)] == pytest.approx(0.99 * 10.0 * 34 / (2 * math.pi) * 12, abs=2.0)


def test_standing_still_is_silent():
    ego = EgoNoise(_free_field())
    motors = np.array([[3.0, 2.5, 0.05], [3.1, 2.6, 0.05], [2.9, 2.6, 0.05]])
    p = ego.pressure(np.array([[3.0, 2.55, 0.30]]), motors, np.zeros((3, 8000)), 0)
    assert not np.any(p)


def test_sim_hal_hears_its_motors_only_while_driving():
    """Same scenario and seed with and without ego-noise: identical samples while parked, different
    (louder) while the wheels turn."""
    sc = load_scenario("paper_lab")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        on = sc.hal(0)
        from ssl_sim.backends import make_sim_hal
        world = sc.world(0)
        off = make_sim_hal(world, sources=sc.sources(world, 0), acoustic_config=sc.acoustic_config(0), ego_noise=None)
    assert np.array_equal(on.audio.read(8000).samples, off.audio.read(8000).samples)
    for hal in (on, off):
        hal.robot.set_twist(0.15, 0.0, 0.0)
        hal.audio.read(8000)  # accelerate
    a, b = on.audio.read(8000).samples.astype(float), off.audio.read(8000).samples.astype(float)
    assert np.std(a - b) > 2.0  # LSB: the motors are heard (the sensor noise is the same in both)
