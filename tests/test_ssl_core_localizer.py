"""SRP-PHAT localizer against independent truth: analytic delays, known source positions."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from signals import plane_wave, point_source, speech_like
from ssl_core.geometry import cube8
from ssl_core.grid import angular_distance, direction_from_angles
from ssl_core.localizer import Localizer, LocalizerConfig

FS = 16000


def deg_err(d, u) -> float:
    return float(np.rad2deg(angular_distance(d.direction, u)))


@pytest.fixture(scope="module")
def loc():
    return Localizer(cube8(), LocalizerConfig())


def test_far_field_plane_waves_over_whole_sphere(loc):
    rng = np.random.default_rng(7)
    g = cube8()
    errors = []
    for k in range(40):
        # directions spread over the sphere, poles included
        az = rng.uniform(-np.pi, np.pi)
        el = np.arcsin(rng.uniform(-1, 1)) if k > 1 else (np.pi / 2 if k == 0 else -np.pi / 2)
        u = direction_from_angles(az, el)
        x = 0.1 * plane_wave(g.positions, u, rng.standard_normal(FS // 2), FS)
        res = loc.locate(x)
        assert len(res.detections) == 1
        errors.append(deg_err(res.detections[0], u))
    assert max(errors) < loc.config.resolution_deg, errors


def test_near_field_grid_beats_far_field_at_half_a_metre():
    g = cube8()
    rng = np.random.default_rng(3)
    near = Localizer(g, LocalizerConfig(radius_m=0.5))
    far = Localizer(g, LocalizerConfig())
    e_near, e_far = [], []
    for _ in range(12):
        u = direction_from_angles(rng.uniform(-np.pi, np.pi), rng.uniform(-1.0, 1.0))
        x = 0.05 * point_source(g.positions, 0.5 * u, rng.standard_normal(FS // 2), FS)
        e_near.append(deg_err(near.locate(x).detections[0], u))
        e_far.append(deg_err(far.locate(x).detections[0], u))
    assert np.mean(e_near) < np.mean(e_far)
    assert max(e_near) < 1.5


def test_reverberant_room_speech_within_3_degrees():
    pra = pytest.importorskip("pyroomacoustics")
    g = cube8()
    room_dim = np.array([6.0, 5.0, 3.0])
    e_abs, max_order = pra.inverse_sabine(0.4, room_dim)
    centre = np.array([2.6, 2.2, 1.2])
    rng = np.random.default_rng(11)
    loc = Localizer(g, LocalizerConfig())
    for az_deg, el_deg in ((30.0, 10.0), (-120.0, -20.0), (160.0, 35.0)):
        u = direction_from_angles(np.deg2rad(az_deg), np.deg2rad(el_deg))
        room = pra.ShoeBox(room_dim, fs=FS, materials=pra.Material(e_abs), max_order=min(max_order, 12))
        room.add_source(centre + 1.5 * u, signal=speech_like(2 * FS, FS, seed=int(az_deg) % 97))
        room.add_microphone_array((centre + g.positions).T)
        room.simulate()
        x = room.mic_array.signals[:, : 2 * FS]
        rms = np.sqrt(np.mean(x**2))
        x = x + rng.standard_normal(x.shape) * rms / 10 ** (20 / 20)  # SNR 20 dB
        res = loc.locate(x)
        d = res.detections[0]
        assert abs(np.rad2deg(np.angle(np.exp(1j * (d.azimuth - np.deg2rad(az_deg)))))) <= 3.0
        assert abs(d.elevation_deg - el_deg) <= 3.0


def _assert_three_found(truths, signals, noise: float = 0.0) -> None:
    """Mix plane waves from ``truths`` (az, el degrees) and check every source is found within 5 degrees."""
    g = cube8()
    x = np.zeros((8, FS))
    for (az, el), s in zip(truths, signals):
        x += 0.05 * plane_wave(g.positions, direction_from_angles(np.deg2rad(az), np.deg2rad(el)), s, FS)
    x += noise * np.random.default_rng(5).standard_normal(x.shape)
    loc = Localizer(g, LocalizerConfig(n_sources=3, min_separation_deg=20.0, rel_threshold=0.2))
    res = loc.locate(x)
    assert len(res.detections) == 3
    for az, el in truths:
        u = direction_from_angles(np.deg2rad(az), np.deg2rad(el))
        assert min(deg_err(d, u) for d in res.detections) <= 5.0


def test_three_simultaneous_speech_sources_found():
    truths = [(-135.0, 35.0), (90.0, 45.0), (150.0, -10.0)]  # at least 30 degrees apart
    _assert_three_found(truths, [speech_like(FS, FS, seed=100 + k, f0=110 + 40 * k) for k in range(3)], noise=0.001)


def test_three_noise_sources_30_degrees_apart():
    truths = [(0.0, 0.0), (30.0, 0.0), (-30.0, 10.0)]
    _assert_three_found(truths, [np.random.default_rng(20 + k).standard_normal(FS) for k in range(3)])


def test_streaming_equals_batch(loc):
    g = cube8()
    u = direction_from_angles(1.0, 0.2)
    x = 0.1 * plane_wave(g.positions, u, speech_like(FS, FS, seed=1), FS)
    batch = loc.process_all(x)
    loc.reset()
    rng = np.random.default_rng(0)
    stream, pos = [], 0
    while pos < x.shape[1]:
        n = int(rng.integers(1, 3000))
        stream += loc.process(x[:, pos:pos + n])
        pos += n
    assert len(batch) == len(stream) == (1 + (FS - 512) // 256) // 8
    for a, b in zip(batch, stream):
        assert a.time == pytest.approx(b.time)
        assert len(a.detections) == len(b.detections)
        for da, db in zip(a.detections, b.detections):
            assert da.azimuth == pytest.approx(db.azimuth, abs=1e-9)
            assert da.elevation == pytest.approx(db.elevation, abs=1e-9)
            assert da.power == pytest.approx(db.power, rel=1e-4)
            assert da.significance == pytest.approx(db.significance, rel=1e-3)
    # window end times step by window_frames * hop / fs
    assert np.allclose(np.diff([r.time for r in batch]), 8 * 256 / FS)


def test_streaming_equals_batch_with_the_interference_rescan():
    """The rescan's state (covariance, summed GCC, per-bin onset mean) carries across blocks of any size."""
    g = cube8()
    rng = np.random.default_rng(3)
    talk = 0.05 * plane_wave(g.positions, direction_from_angles(1.0, 0.1), speech_like(2 * FS, FS, seed=2), FS)
    machine = 0.1 * plane_wave(g.positions, direction_from_angles(-1.5, 0.0), rng.standard_normal(2 * FS), FS)
    x = talk + machine + 1e-3 * rng.standard_normal(talk.shape)
    loc = Localizer(g, LocalizerConfig(n_sources=2, interference_rescan=True, noise_suppression=True,
                                       min_significance=5.0))
    batch = loc.process_all(x)
    loc.reset()
    stream, pos = [], 0
    while pos < x.shape[1]:
        n = int(rng.integers(1, 3000))
        stream += loc.process(x[:, pos:pos + n])
        pos += n
    assert len(batch) == len(stream) and sum(len(r.detections) == 2 for r in batch) > 0
    for a, b in zip(batch, stream):
        assert len(a.detections) == len(b.detections)
        for da, db in zip(a.detections, b.detections):
            assert (da.azimuth, da.elevation) == pytest.approx((db.azimuth, db.elevation), abs=1e-9)


def test_onset_weights_pass_the_start_of_a_burst_not_its_steady_part_nor_steady_noise():
    """The rescan's onset weight (precedence effect): a broadband burst starting in steady noise 20 dB below
    it is weighted ~1 in its first frame; its steady part and the noise before it ~0."""
    loc = Localizer(cube8(), LocalizerConfig(n_sources=2, interference_rescan=True))
    rng = np.random.default_rng(5)
    x = 0.01 * rng.standard_normal((8, FS))
    onset = FS // 2
    x[:, onset:] += 0.1 * rng.standard_normal((8, FS - onset))
    spec, _ = loc._analyse(x.astype(np.float32))
    w = loc._onset_weights(spec.transpose(2, 0, 1), loc._new_stream())   # (frames, bins)
    hop, frame = loc.config.hop, loc.config.frame_size
    first = onset // hop                       # the frame holding the onset (it starts < 1 hop before it)
    starts = np.arange(w.shape[0]) * hop
    before = w[(starts + frame <= onset) & (starts >= 8 * hop)]   # steady noise (after the mean settled)
    steady = w[starts >= onset + 0.2 * FS]                      # 200 ms into the burst
    assert w[first].mean() > 0.8, w[first].mean()
    assert before.mean() < 0.05 and steady.mean() < 0.05, (before.mean(), steady.mean())


def test_silence_and_incoherent_noise_give_no_detections(loc):
    assert loc.locate(np.zeros((8, FS))).detections == []
    noise = np.random.default_rng(2).standard_normal((8, FS)) * 0.01  # independent per mic: no source
    assert all(r.detections == [] for r in loc.process_all(noise))


def test_int16_input_and_beam_level():
    g = cube8()
    loc = Localizer(g, LocalizerConfig())
    u = direction_from_angles(-0.5, 0.1)
    s = np.random.default_rng(9).standard_normal(FS)
    x = 0.1 * plane_wave(g.positions, u, s, FS)
    d16 = loc.locate(np.round(x * 32767).astype(np.int16)).detections[0]
    assert deg_err(d16, u) < 1.5
    d_loud = loc.locate(x).detections[0]
    d_quiet = loc.locate(0.1 * x).detections[0]
    assert d_loud.level_db - d_quiet.level_db == pytest.approx(20.0, abs=0.1)


@pytest.mark.parametrize(
    "block, match",
    [
        (np.zeros((6, 4000)), "6 channels.*expects 8"),
        (np.zeros(4000), "2-D"),
        (np.full((8, 4000), np.nan), "non-finite"),
        (np.zeros((8, 100)), "too short"),
        (np.zeros((8, 4000), dtype=np.complex64), "dtype"),
    ],
)
def test_bad_input_is_named(loc, block, match):
    with pytest.raises(ValueError, match=match):
        loc.locate(block)


def test_sample_rate_mismatch(loc):
    with pytest.raises(ValueError, match="48000 Hz.*16000 Hz"):
        loc.process(np.zeros((8, 1000)), fs=48000)


@pytest.mark.parametrize(
    "kwargs, field",
    [
        (dict(n_sources=3, min_separation_deg=5.0), "min_separation_deg"),
        (dict(hop=0), "hop"),
        (dict(resolution_deg=6.0), "resolution_deg"),
        (dict(band_hz=(3000.0, 300.0)), "band_hz"),
        (dict(el_min_deg=50.0, el_max_deg=10.0), "elevation"),
        (dict(min_significance=-1.0), "min_significance"),
        (dict(min_power=1.5), "min_power"),
        (dict(interference_memory_s=0.0), "interference_memory_s"),
        (dict(rescan_memory_s=-1.0), "rescan_memory_s"),
        (dict(onset_memory_s=0.0), "onset_memory_s"),
        (dict(resolution_deg=0.1), "max_table_mb"),  # ~5.5 GB of tables: refused before anything is built
    ],
)
def test_bad_config_is_named(kwargs, field):
    with pytest.raises(ValueError, match=field):
        Localizer(cube8(), replace(LocalizerConfig(), **kwargs))


def test_elevation_limits_respected():
    loc = Localizer(cube8(), LocalizerConfig(el_min_deg=-10.0, el_max_deg=60.0))
    assert np.rad2deg(loc.fine_grid.elevation).min() >= -10.0 - 1e-9
    assert np.rad2deg(loc.coarse_grid.elevation).max() <= 60.0 + 1e-9


def test_noise_suppression_reveals_a_voice_under_steady_louder_noise():
    from scipy import signal as sps

    g = cube8()
    n = 3 * FS
    rng = np.random.default_rng(0)
    u_voice = direction_from_angles(np.deg2rad(30), np.deg2rad(10))
    u_pump = direction_from_angles(np.deg2rad(-120), 0.0)
    t = np.arange(n) / FS
    voice = speech_like(n, FS, seed=3) * (np.sin(2 * np.pi * 0.5 * t) > 0)  # talks 1 s, pauses 1 s
    pump = sps.lfilter([1.0], [1.0, -0.9], rng.standard_normal(n))
    pump /= pump.std()
    # the pump is 6 dB louder than the voice (while it talks)
    x = 0.05 * plane_wave(g.positions, u_voice, voice, FS) + 0.1 * plane_wave(g.positions, u_pump, pump, FS)
    x += 1e-4 * rng.standard_normal(x.shape)

    def voice_first_windows(suppress: bool) -> int:
        loc = Localizer(g, LocalizerConfig(noise_suppression=suppress))
        return sum(1 for r in loc.process_all(x) if r.detections and deg_err(r.detections[0], u_voice) < 3)

    plain, suppressed = voice_first_windows(False), voice_first_windows(True)
    n_windows = len(Localizer(g).process_all(x))
    assert plain <= 2  # plain SRP-PHAT: the steady pump wins nearly every window
    assert suppressed >= 0.35 * n_windows  # the voice talks in half of the windows
    # and streaming still equals batch with the stateful noise floor
    loc = Localizer(g, LocalizerConfig(noise_suppression=True))
    batch = [r.detections[0].azimuth if r.detections else None for r in loc.process_all(x)]
    loc.reset()
    stream = []
    for k in range(0, n, 1000):
        stream += [r.detections[0].azimuth if r.detections else None for r in loc.process(x[:, k:k + 1000])]
        if k == 20000:
            loc.locate(x[:, :FS])  # a whole-recording call in between must not disturb the stream's floor
    assert batch == stream


def test_peak_in_sector_finds_a_weak_source_beside_a_loud_one():
    """A source 6 dB under a louder one is no detection of a one-source search; its azimuth sector (as a
    voice scan gives it, 8 deg off) holds its direction, elevation included, within two fine grid spacings."""
    g, rng = cube8(), np.random.default_rng(3)
    loud = direction_from_angles(np.deg2rad(60.0), 0.0)
    weak = direction_from_angles(np.deg2rad(-100.0), np.deg2rad(-25.0))
    n = FS
    x = (0.04 * plane_wave(g.positions, loud, rng.standard_normal(n), FS)
         + 0.02 * plane_wave(g.positions, weak, speech_like(n, FS, seed=4), FS)
         + 1e-3 * rng.standard_normal((8, n)))
    loc1 = Localizer(cube8(), LocalizerConfig(n_sources=1))
    res = loc1.locate(x)
    assert len(res.detections) == 1 and deg_err(res.detections[0], loud) < 2.0
    peak = loc1.peak_in_sector(res, np.deg2rad(-92.0), np.deg2rad(15.0), x)
    assert peak is not None and deg_err(peak, weak) < 2 * loc1.config.resolution_deg, peak
    assert peak.significance >= loc1.config.min_significance
    assert peak.level_db < res.detections[0].level_db - 3.0      # its own beam's level (6 dB under), not the loud one's
    # without a sector around it there is no such peak: the sector 90 deg away holds only weaker directions
    other = loc1.peak_in_sector(res, np.deg2rad(170.0), np.deg2rad(15.0), x)
    assert other is None or other.power < 0.5 * peak.power


def test_peak_in_sector_of_silence_is_none():
    loc1 = Localizer(cube8(), LocalizerConfig())
    res = loc1.locate(np.zeros((8, FS), np.float32))
    assert loc1.peak_in_sector(res, 0.0, np.deg2rad(15.0)) is None
