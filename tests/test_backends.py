"""SimAudioSource: audio time is physics time, microphones follow the MuJoCo robot, localizable."""
from __future__ import annotations

import numpy as np
import pytest

from ssl_core.geometry import cube8
from ssl_core.grid import angular_distance, direction_from_angles
from ssl_core.localizer import Localizer, LocalizerConfig
from ssl_sim.acoustics import AcousticConfig, AmbientNoise, SoundSource
from ssl_sim.acoustics.voices import continuous_voice
from ssl_sim.backends import array_frame_directions, make_sim_hal
from ssl_sim.world import Room, World

FS = 16000


def _world(victim=(3.5, 2.0, 0.4)) -> World:
    return World(room=Room(size=(5.0, 4.0, 2.5)), robot_start=(1.5, 2.0, 0.3), name="backend_test")


def _hal(world, pos=(3.5, 2.0, 0.4), **kw):
    src = SoundSource(pos, continuous_voice("female", seed=3, fs=FS), 70.0, name="talker")
    cfg = AcousticConfig(seed=1, rt60_s=0.3, max_rir_s=0.5, ambient=AmbientNoise(30.0))
    return make_sim_hal(world, sources=[src], acoustic_config=cfg, **kw)


def test_reading_advances_physics_by_the_block_duration_and_blocks_are_contiguous():
    hal = _hal(_world())
    assert hal.audio.sample_rate == FS and hal.audio.n_channels == 8
    b1 = hal.audio.read(4000)
    assert b1.samples.shape == (8, 4000) and b1.samples.dtype == np.int16
    assert b1.timestamp == 0.0
    assert hal.clock.now() == pytest.approx(0.25, abs=hal.robot.timestep / 2)
    b2 = hal.audio.read(3000)
    assert b2.timestamp == pytest.approx(4000 / FS)
    assert hal.clock.now() == pytest.approx(7000 / FS, abs=hal.robot.timestep / 2)
    # Standing still, two consecutive blocks are exactly the samples of one long block.
    hal2 = _hal(_world())
    whole = hal2.audio.read(7000).samples
    # (equal up to FFT rounding at the 16-bit quantiser: +-1 LSB)
    diff = np.concatenate([b1.samples, b2.samples], axis=1).astype(int) - whole
    assert np.abs(diff).max() <= 1 and np.mean(diff != 0) < 0.02
    # A clock sleep in between moves the audio on too (no stale buffer).
    hal.clock.sleep(0.5)
    b3 = hal.audio.read(400)
    assert b3.timestamp == pytest.approx(7000 / FS + 0.5, abs=hal.robot.timestep)


def test_localizing_the_simulated_audio_gives_the_true_array_frame_direction():
    world = _world()
    hal = _hal(world)
    hal.clock.sleep(0.3)  # settle on the wheels
    block = hal.audio.read(FS)
    loc = Localizer(cube8(), LocalizerConfig(fs=FS))
    res = loc.locate(block.samples)
    az, el, _ = array_frame_directions(hal.robot, [(3.5, 2.0, 0.4)])
    # Independent truth: robot yaw 0.3 rad at (1.5, 2.0), array at 0.27 m, source 2 m ahead along +x (world).
    dx, dz = 2.0, 0.4 - hal.robot.config.array_height
    assert az[0] == pytest.approx(-0.3, abs=0.02)
    assert el[0] == pytest.approx(np.arctan2(dz, dx), abs=0.02)
    got = res.detections[0].direction
    assert np.rad2deg(angular_distance(got, direction_from_angles(az[0], el[0]))) < 5.0


def test_moving_robot_is_rendered_per_chunk_and_standing_robot_in_one_go():
    hal = _hal(_world())
    hal.audio.read(1600)
    assert hal.audio.moving_blocks == 0
    seen = []
    hal.audio.on_block = lambda block, mics: seen.append(mics.shape)
    hal.drive.set_twist(0.2, 0.0, 0.0)
    x0 = hal.robot.pose().x
    hal.audio.read(FS // 2)
    assert hal.audio.moving_blocks == 1
    assert seen[-1][0] == 10  # 0.5 s in 50 ms chunks
    # The robot drove while listening: about 0.2 m/s along its heading.
    assert hal.robot.pose().x - x0 > 0.05


def test_a_driving_array_is_rendered_at_a_held_pose_within_its_tolerance():
    hal = _hal(_world(), pose_hold_m=0.025)
    rendered, true = [], []
    hal.audio.on_block = lambda block, mics: rendered.append(mics[0].copy())
    hal.drive.set_twist(0.25, 0.0, 0.0)
    hal.audio.read(4000)   # up to speed
    rendered.clear()
    for _ in range(30):    # the control loop's 50 ms reads
        before = hal.robot.mic_positions()
        hal.audio.read(800)
        true.append(0.5 * (before + hal.robot.mic_positions()))
    off = [float(np.max(np.linalg.norm(r - t, axis=-1))) for r, t in zip(rendered, true)]
    assert max(off) <= 0.025 + 1e-9                     # never farther than the tolerance from the truth
    changes = sum(not np.array_equal(a, b) for a, b in zip(rendered, rendered[1:]))
    assert 5 <= changes <= 15                           # 0.0125 m a read: a new pose every second or third read
    with pytest.raises(ValueError, match="pose_hold_m"):
        _hal(_world(), pose_hold_m=-0.01)


def test_scenario_builds_a_hal_the_behaviour_can_use():
    from ssl_sim.scenario import load_scenario

    sc = load_scenario("paper_lab")
    hal = sc.hal(seed=4)
    assert hal.robot.time == 0.0 and hal.audio.n_channels == 8
    p = hal.robot.pose()
    assert (p.x, p.y) == pytest.approx(sc.world().robot_start[:2], abs=1e-3)
    assert [s.name for s in hal.acoustics.sources] == ["caller"]
    block = hal.audio.read(FS // 2)
    assert block.sample_rate == FS and hal.clock.now() == pytest.approx(0.5, abs=hal.robot.timestep)
