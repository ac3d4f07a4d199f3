"""ssl_sim.acoustics: geometry, levels, delays, reverberation, pose, sensor, validation.

Truth is independent of the simulator: analytic distances/delays, the inverse-distance law,
Eyring's formula, the diffuse-field coherence sinc(kd), and the geometry we place."""
from __future__ import annotations


import numpy as np
import pytest

from ssl_core.localizer import Localizer, LocalizerConfig
from ssl_sim.acoustics import (AcousticConfig, AcousticScene, AcousticSimulator, AmbientNoise, ArrayMount,
                               ClippingWarning, RobotPose, SensorConfig, ShapedNoise, SoundSource,
                               continuous_voice, get_material, point_at, register_material)
from ssl_sim.acoustics.materials import eyring_absorption_for_rt60, eyring_rt60
from ssl_sim.world import Box, Room, VictimSite, World

FS = 16000
C = 343.0
P_62_5 = 20e-6 * 10 ** (62.5 / 20)  # Pa


def white(seed: int = 3) -> ShapedNoise:
    return ShapedNoise(FS, seed, "white")


def free_field(sources, **kw) -> AcousticSimulator:
    """Anechoic (all surfaces absorbing), direct path only, no ambient noise."""
    cfg = AcousticConfig(rt60_s=0.0, ism_order=0, ambient=None, **kw)
    return AcousticSimulator(World(room=Room((12.0, 12.0, 6.0))), cfg, sources)


def angular_error_deg(az1, el1, az2, el2) -> float:
    u = np.array([np.cos(el1) * np.cos(az1), np.cos(el1) * np.sin(az1), np.sin(el1)])
    v = np.array([np.cos(el2) * np.cos(az2), np.cos(el2) * np.sin(az2), np.sin(el2)])
    return float(np.rad2deg(np.arccos(np.clip(u @ v, -1, 1))))


# ----------------------------------------------------------------------------- materials
def test_materials_resolve_and_unknown_names_fail():
    assert get_material("brickwork").absorption[3] == pytest.approx(0.03)
    assert get_material("concrete_floor").absorption[0] == pytest.approx(0.01)
    assert get_material("concrete").absorption == get_material("rough_concrete").absorption
    assert len(get_material("plasterboard").absorption) == 7
    with pytest.raises(ValueError, match="unknown acoustic material 'unobtainium'"):
        get_material("unobtainium")
    register_material("test_foam", 0.8)
    assert get_material("test_foam").absorption == (0.8,) * 7
    world = World(room=Room(wall_material="unobtainium"))
    with pytest.raises(ValueError, match="world.room.wall_material"):
        AcousticSimulator(world)
    world = World(obstacles=(Box((2, 2, 0.5), (1, 1, 1), material="nope"),))
    with pytest.raises(ValueError, match=r"world.obstacles\[0\].material"):
        AcousticSimulator(world)


def test_eyring_inverse_is_consistent():
    v, s = 6 * 5 * 3.0, 2 * (30 + 18 + 15.0)
    for t in (0.2, 0.5, 1.0):
        a = eyring_absorption_for_rt60(t, v, s)
        assert eyring_rt60(v, np.array([s]), np.full((1, 7), a))[0] == pytest.approx(t, rel=1e-9)


# ----------------------------------------------------------------------------- scene geometry
def test_obstacle_faces_clipped_oriented_and_occluding():
    world = World(room=Room((6, 5, 3)), obstacles=(
        Box((3.0, 2.5, 0.5), (1.0, 1.0, 1.0)),            # resting on the floor
        Box((5.9, 1.0, 0.6), (0.6, 0.6, 1.2), yaw=0.0),   # poking through the east wall
    ))
    scene = AcousticScene(world)
    labels = [s.label for s in scene.obstacle_surfaces]
    assert "obstacle[0].bottom" not in labels and "obstacle[0].top" in labels
    assert "obstacle[1].+x" not in labels and "obstacle[1].bottom" not in labels
    for s in scene.obstacle_surfaces:  # normals point into the box (out of the air)
        box = world.obstacles[int(s.label[9])]
        assert np.dot(np.asarray(box.center) - s.corners.mean(axis=0), s.normal) > 0
        assert np.all(s.corners >= -1e-9) and np.all(s.corners <= np.asarray(scene.size) + 1e-9)
    assert scene.volume == pytest.approx(90.0 - 1.0 - 0.4 * 0.6 * 1.2, abs=1e-6)  # 0.4 m of box 1 inside

    src, rec = np.array([1.5, 2.5, 0.4]), np.array([4.5, 2.5, 0.4])  # the first box is between them
    imgs = scene.image_sources(src, rec, order=1)
    assert not imgs.direct_visible
    # reflection off the box's -x face (plane x = 2.5) is visible: image at x = 3.5
    mirror = np.array([3.5, 2.5, 0.4])
    assert np.min(np.linalg.norm(imgs.positions - mirror, axis=1)) > 1e-3  # from the far side: not visible
    imgs2 = scene.image_sources(src, np.array([1.5, 2.0, 0.4]), order=1)
    assert imgs2.direct_visible
    assert np.min(np.linalg.norm(imgs2.positions - mirror, axis=1)) < 1e-3
    ceiling_img = np.array([1.5, 2.5, 5.6])
    assert np.min(np.linalg.norm(imgs.positions - ceiling_img, axis=1)) < 1e-3  # over the box via the ceiling


# ----------------------------------------------------------------------------- levels and delays
def test_level_calibration_and_inverse_distance_law():
    src = SoundSource((3.0, 6.0, 3.0), white(), 62.5)
    sim = free_field([src])
    mics = np.array([[4.0, 6.0, 3.0], [5.0, 6.0, 3.0], [3.0, 8.0, 3.0], [3.0, 6.0, 4.5]])
    p = sim.pressure(mics, 0, 3 * FS)
    rms = np.sqrt(np.mean(p**2, axis=1))
    expected = P_62_5 / np.array([1.0, 2.0, 2.0, 1.5])
    np.testing.assert_allclose(20 * np.log10(rms / expected), 0.0, atol=1.0)
    # and through the ADC: 94 dB SPL -> -26 dBFS, i.e. 62.5 dB SPL at 1 m = 43.8 LSB RMS
    quiet = AcousticConfig(rt60_s=0.0, ism_order=0, ambient=None,
                           sensor=SensorConfig(self_noise_db_spl=-20.0, gain_mismatch_db=0.0))
    sim = AcousticSimulator(World(room=Room((12.0, 12.0, 6.0))), quiet, [src])
    x = sim.listen(mics[:1], 3.0)
    assert x.dtype == np.int16
    lsb = np.sqrt(np.mean(x.astype(float) ** 2))
    assert 20 * np.log10(lsb / (P_62_5 * 10 ** (-26 / 20) * 32768)) == pytest.approx(0.0, abs=1.0)


def test_band_snr_follows_the_inverse_distance_law():
    """Each source's band energy at the array against the rest: two white sources of the same level at 1 m and
    2 m from a small array in free field are +6 and -6 dB (inverse square law); with the ambient field added both
    fall, and a source that is silent in the window is -inf."""
    centre = np.array([6.0, 6.0, 3.0])
    mics = centre + 0.05 * np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], float)
    srcs = [SoundSource(tuple(centre + (1.0, 0.0, 0.0)), white(1), 70.0),
            SoundSource(tuple(centre + (0.0, 2.0, 0.0)), white(2), 70.0)]
    snr = free_field(srcs).band_snr_db(mics, FS, 2 * FS)
    np.testing.assert_allclose(snr, [6.02, -6.02], atol=0.5)
    noisy = AcousticSimulator(World(room=Room((12.0, 12.0, 6.0))),
                              AcousticConfig(rt60_s=0.0, ism_order=0, ambient=AmbientNoise(60.0, "white")), srcs)
    with_noise = noisy.band_snr_db(mics, FS, 2 * FS)
    assert np.all(with_noise < snr) and with_noise[0] < snr[0] - 1.0
    from ssl_sim.acoustics.signals import EventStream
    silent = SoundSource(tuple(centre + (1.0, 0.0, 0.0)), EventStream(lambda rng: np.ones(10), FS, 1.0, 0, p_event=0.0),
                         70.0)
    assert free_field([silent, srcs[1]]).band_snr_db(mics, FS, FS)[0] == -np.inf


def test_inter_microphone_delays_match_geometry():
    src_pos = np.array([3.0, 6.0, 3.0])
    sim = free_field([SoundSource(tuple(src_pos), white(), 62.5)])
    mics = ArrayMount(height_m=3.0).mic_positions_world(RobotPose(5.0, 5.3, yaw=0.4))
    p = sim.pressure(mics, 0, 2 * FS)
    n, up = 4 * FS, 32
    spec = np.fft.rfft(p, n, axis=1)
    for i, j in ((0, 4), (1, 6), (2, 7)):
        g = spec[j] * np.conj(spec[i])
        g /= np.abs(g) + 1e-12
        g[np.fft.rfftfreq(n, 1 / FS) > 6000] = 0
        cc = np.fft.irfft(g, n * up)
        cc = np.concatenate([cc[-20 * up:], cc[: 20 * up]])
        measured = (np.argmax(cc) - 20 * up) / up
        truth = (np.linalg.norm(mics[j] - src_pos) - np.linalg.norm(mics[i] - src_pos)) / C * FS
        assert measured == pytest.approx(truth, abs=0.05)


def test_reverberation_time_matches_target():
    import pyroomacoustics as pra

    world = World(room=Room((6.0, 5.0, 3.0)))
    for target in (0.3, 0.8):
        sim = AcousticSimulator(world, AcousticConfig(rt60_s=target, ambient=None), [SoundSource((1.5, 1.5, 1.2), white(), 62.5)])
        h = sim.impulse_responses(np.array([[4.0, 3.2, 1.5], [4.1, 3.3, 1.6]]))[0]
        for hh in h:
            rt = pra.experimental.measure_rt60(hh[sim.N_PRE:], FS, decay_db=30)
            assert rt == pytest.approx(target, rel=0.1)


def test_diffuse_ambient_noise_level_and_coherence():
    sim = AcousticSimulator(World(room=Room((6.0, 5.0, 3.0))),
                            AcousticConfig(ambient=AmbientNoise(50.0, "white"), late_reverb=False), [])
    mics = np.array([[3.0, 2.5, 1.5], [3.1, 2.5, 1.5], [3.0, 2.5, 1.8]])
    p = sim.pressure(mics, 0, 8 * FS)
    level = 20 * np.log10(np.sqrt(np.mean(p**2, axis=1)) / 20e-6)
    np.testing.assert_allclose(level, 50.0, atol=0.5)
    from scipy.signal import coherence

    for j, d in ((1, 0.1), (2, 0.3)):
        f, coh = coherence(p[0], p[j], fs=FS, nperseg=512)
        for f0 in (300.0, 800.0, 1500.0):
            k = np.argmin(np.abs(f - f0))
            expected = np.sinc(2 * f[k] * d / C) ** 2  # magnitude-squared coherence of a diffuse field
            assert coh[k] == pytest.approx(expected, abs=0.12)


# ----------------------------------------------------------------------------- localization
@pytest.fixture(scope="module")
def localizer():
    return Localizer("cube8", LocalizerConfig())


def test_localized_within_3_degrees_in_reverberant_room(localizer):
    world = World(room=Room((7.0, 6.0, 3.2)))
    mount = ArrayMount(height_m=1.0)
    pose = RobotPose(3.3, 2.7, yaw=0.3)
    centre = mount.centre_world(pose)
    for k, (az, el) in enumerate(((40.0, 15.0), (-120.0, -10.0), (160.0, 35.0))):
        pos = point_at(centre, np.deg2rad(az), np.deg2rad(el), 1.8, pose.rotation)
        src = SoundSource(tuple(pos), continuous_voice("male" if k % 2 else "female", seed=k), 62.5)
        sim = AcousticSimulator(world, AcousticConfig(rt60_s=0.5, seed=10 + k), [src])
        x = sim.listen_pose(pose, 1.5, mount=mount)
        d = localizer.locate(x).detections[0]
        assert angular_error_deg(d.azimuth, d.elevation, np.deg2rad(az), np.deg2rad(el)) < 3.0


def test_rotating_robot_rotates_localized_azimuth(localizer):
    world = World(room=Room((7.0, 6.0, 3.2)))
    src = SoundSource((5.5, 4.0, 0.6), continuous_voice("male", seed=4), 62.5)
    sim = AcousticSimulator(world, AcousticConfig(rt60_s=0.4, seed=5), [src])
    az = []
    for yaw in (0.0, np.pi / 2):
        x = sim.listen_pose(RobotPose(3.0, 2.5, yaw=yaw), 1.5)
        az.append(localizer.locate(x).detections[0].azimuth)
    diff = np.rad2deg(np.angle(np.exp(1j * (az[1] - az[0]))))
    assert diff == pytest.approx(-90.0, abs=3.0)
    truth, _, _ = ArrayMount().direction_in_array_frame(RobotPose(3.0, 2.5), src.position)
    assert np.rad2deg(abs(np.angle(np.exp(1j * (az[0] - truth))))) < 3.0


# ----------------------------------------------------------------------------- time keying, seeds
def test_blocks_are_continuous_and_reproducible():
    world = World(room=Room((6.0, 5.0, 3.0)), victims=(VictimSite((1.0, 4.0, 0.3)), VictimSite((5.0, 1.0, 0.5))))
    cfg = AcousticConfig(seed=7, rt60_s=0.4)
    pose = RobotPose(3.0, 2.5, yaw=0.2)
    sim = AcousticSimulator(world, cfg)
    mics = ArrayMount().mic_positions_world(pose)
    # Pressure is the same however the timeline is cut (up to FFT rounding) ...
    p_whole = sim.pressure(mics, 2 * FS, FS)
    p_parts = np.concatenate([sim.pressure(mics, 2 * FS + k * FS // 4, FS // 4) for k in range(4)], axis=1)
    np.testing.assert_allclose(p_parts, p_whole, rtol=0, atol=1e-9 * np.abs(p_whole).max())
    # ... so the ADC output differs at most where rounding sits on a half-LSB boundary.
    whole = sim.listen_pose(pose, 1.0, t0=2.0)
    parts = np.concatenate([sim.listen_pose(pose, 0.25, t0=2.0 + 0.25 * k) for k in range(4)], axis=1)
    assert np.max(np.abs(whole.astype(int) - parts)) <= 1
    assert np.mean(whole != parts) < 1e-3
    again = AcousticSimulator(world, cfg).listen_pose(pose, 1.0, t0=2.0)
    np.testing.assert_array_equal(whole, again)
    other = AcousticSimulator(world, AcousticConfig(seed=8, rt60_s=0.4)).listen_pose(pose, 1.0, t0=2.0)
    assert not np.array_equal(whole, other)


# ----------------------------------------------------------------------------- sensor
def test_device_offset_and_drift_shift_second_device():
    src = SoundSource((3.0, 6.0, 3.0), white(), 70.0)
    mics = ArrayMount(height_m=3.0).mic_positions_world(RobotPose(6.0, 6.0))

    def lag(offsets, drift=(0.0, 0.0), t0=0.0):
        sens = SensorConfig(output="float", self_noise_db_spl=0.0, gain_mismatch_db=0.0,
                            device_offset_samples=offsets, clock_drift_ppm=drift)
        sim = free_field([src], sensor=sens)
        x = sim.listen(mics, 1.0, t0=t0).astype(float)
        n, up = 2 * FS, 16
        s = np.fft.rfft(x, n, axis=1)
        g = s[4] * np.conj(s[0])
        g /= np.abs(g) + 1e-12
        cc = np.fft.irfft(g, n * up)
        cc = np.concatenate([cc[-200 * up:], cc[: 200 * up]])
        return (np.argmax(cc) - 200 * up) / up

    base = lag((0.0, 0.0))
    assert lag((0.0, 3.0)) - base == pytest.approx(-3.0, abs=0.1)   # device 2 samples 3 samples later
    assert lag((0.0, 0.5)) - base == pytest.approx(-0.5, abs=0.1)
    # 100 ppm drift: after 100 s device 2 is 160 samples late
    # (it grows by another 1.6 samples over the 1 s block: the correlation peak sits in between)
    assert lag((0.0, 0.0), (0.0, 100.0), t0=100.0) - base == pytest.approx(-160.8, abs=1.0)


def test_clipping_warns_and_gain_mismatch_is_fixed_per_seed():
    src = SoundSource((3.0, 6.0, 3.0), white(), 130.0)
    sim = free_field([src])
    with pytest.warns(ClippingWarning, match="clipped"):
        x = sim.listen(np.array([[3.5, 6.0, 3.0]]), 0.2)
    assert x.max() == 32767 and x.min() == -32768
    from ssl_sim.acoustics import Sensor

    a, b = Sensor(SensorConfig(), 8, seed=1), Sensor(SensorConfig(), 8, seed=1)
    np.testing.assert_array_equal(a.gain_db, b.gain_db)
    assert 0.1 < np.std(Sensor(SensorConfig(gain_mismatch_db=1.0), 8, seed=2).gain_db) < 2.5


# ----------------------------------------------------------------------------- validation
def test_bad_positions_and_inputs_raise_clear_errors():
    world = World(room=Room((6.0, 5.0, 3.0)), obstacles=(Box((3.0, 2.5, 0.5), (1.0, 1.0, 1.0)),))
    with pytest.raises(ValueError, match=r"sources\[0\].position.*outside the room"):
        AcousticSimulator(world, sources=[SoundSource((7.0, 1.0, 1.0), white(), 60.0)])
    with pytest.raises(ValueError, match=r"sources\[0\].position.*inside obstacle 0"):
        AcousticSimulator(world, sources=[SoundSource((3.0, 2.5, 0.5), white(), 60.0)])
    sim = AcousticSimulator(world, AcousticConfig(late_reverb=False), [SoundSource((1.0, 1.0, 1.0), white(), 60.0)])
    with pytest.raises(ValueError, match=r"mic_positions_world\[0\].*inside obstacle"):
        sim.listen(np.array([[3.0, 2.5, 0.8], [1.0, 4.0, 1.0]]), 0.1)
    # a microphone on the array's face pressed 4 mm into the box's top (z 1.0 m): a contact, heard as at the face
    x = sim.listen(np.array([[3.0, 2.5, 0.996], [1.0, 4.0, 1.0]]), 0.1)
    assert x.shape[0] == 2 and np.all(np.isfinite(x)) and np.abs(x[0]).max() > 0
    with pytest.raises(ValueError, match=r"mic_positions_world\[0\].*inside obstacle"):   # 3 cm deep: misplaced
        sim.listen(np.array([[3.0, 2.5, 0.97], [1.0, 4.0, 1.0]]), 0.1)
    with pytest.raises(ValueError, match="shape"):
        sim.listen(np.zeros((8, 2)), 0.1)
    with pytest.raises(ValueError, match="duration_s"):
        sim.listen(np.array([[1.0, 4.0, 1.0]]), 0.0)
    with pytest.raises(ValueError, match="level_db_spl"):
        SoundSource((1.0, 1.0, 1.0), white(), float("nan"))
    with pytest.raises(ValueError, match="buried"):
        SoundSource((1.0, 1.0, 1.0), white(), 60.0, buried=1.5)
    with pytest.raises(ValueError, match="signal.fs"):
        AcousticSimulator(world, sources=[SoundSource((1.0, 1.0, 1.0), ShapedNoise(8000, 1), 60.0)])
    with pytest.raises(ValueError, match="spectrum"):
        AmbientNoise(30.0, "purple")
    with pytest.raises(ValueError, match="device_offset_samples"):
        SensorConfig(device_offset_samples=(0.0,))


def test_burial_attenuates_and_darkens():
    pos = (3.0, 6.0, 3.0)
    mic = np.array([[4.0, 6.0, 3.0]])
    free = free_field([SoundSource(pos, white(), 62.5)]).pressure(mic, 0, 2 * FS)[0]
    buried = free_field([SoundSource(pos, white(), 62.5, buried=0.8)]).pressure(mic, 0, 2 * FS)[0]
    loss = 20 * np.log10(np.std(free) / np.std(buried))
    assert loss > 12.0
    sf, sb = np.abs(np.fft.rfft(free)), np.abs(np.fft.rfft(buried))
    f = np.fft.rfftfreq(free.size, 1 / FS)
    low, high = (f > 200) & (f < 500), (f > 3000) & (f < 5000)
    assert np.mean(sb[high]) / np.mean(sf[high]) < 0.3 * np.mean(sb[low]) / np.mean(sf[low])


def test_obstacle_rubble_room_listen_runs_with_occlusion():
    world = World(room=Room((6.0, 5.0, 3.0)),
                  obstacles=(Box((3.0, 2.5, 0.4), (0.5, 2.0, 0.8), material="rubble", kind="block"),),
                  victims=(VictimSite((1.5, 2.5, 0.3)),))
    cfg = AcousticConfig(seed=1, late_reverb=False, ambient=None)
    sim = AcousticSimulator(world, cfg, sources=[SoundSource((1.5, 2.5, 0.3), white(), 62.5)])
    d_s = 94 * C / FS  # a whole number of samples: the direct path is one sinc centred on a sample
    behind = np.array([[4.5, 2.5, 0.3]])        # the block hides the direct path (3 m)
    beside = np.array([[1.5, 2.5 + d_s, 0.3]])  # free line of sight
    h_b = sim.impulse_responses(behind)[0, 0]
    h_s = sim.impulse_responses(beside)[0, 0]
    assert h_s[sim.N_PRE + 94] == pytest.approx(1 / d_s, rel=0.15)
    n_direct_b = sim.N_PRE + int(round(3.0 / C * FS))
    assert np.max(np.abs(h_b[n_direct_b - 3: n_direct_b + 4])) < 0.1 / 3.0
    # the analysis' truth of the same geometry: blocked behind the block, clear beside the source and over its top
    assert [bool(sim.line_of_sight(p)[0]) for p in (behind[0], beside[0], (4.5, 2.5, 2.5))] == [False, True, True]


def test_robot_pitch_tilts_the_localized_elevation(localizer):
    """Nose down by 12 deg (positive pitch): a source level with the array appears 12 deg up in the array frame.
    (Array raised to 1 m: near the floor the floor reflection, 4 samples behind the direct sound, biases elevation.)"""
    world = World(room=Room((7.0, 6.0, 3.2)))
    mount = ArrayMount(height_m=1.0)
    pose = RobotPose(2.0, 3.0, yaw=0.0, pitch=np.deg2rad(12.0))
    centre = mount.centre_world(pose)
    src = SoundSource(tuple(centre + np.array([2.0, 0.0, 0.0])), continuous_voice("female", seed=9), 62.5)
    sim = AcousticSimulator(world, AcousticConfig(rt60_s=0.4, seed=3), [src])
    d = localizer.locate(sim.listen_pose(pose, 1.5, mount=mount)).detections[0]
    assert np.rad2deg(d.elevation) == pytest.approx(12.0, abs=3.0)
    assert abs(np.rad2deg(d.azimuth)) < 3.0
    az, el, r = mount.direction_in_array_frame(pose, src.position)
    assert np.rad2deg(el) == pytest.approx(12.0, abs=1e-6) and r == pytest.approx(2.0)
