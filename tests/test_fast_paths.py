"""The environment step's fast paths against the straightforward computations they replace, on the same inputs.

Each of them only reorganises work (copies fewer samples, keeps a pose-independent filter, stores a table in
another memory order, skips zeros), so the outputs must be equal to the bit (``np.array_equal``), not close:
the rescue loop and the gym environment share this code and a last-bit change would change later decisions.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy import fft as sfft

from ssl_core.srp import SteeringTable, tdoa_table
from ssl_sim.acoustics import AcousticConfig, AcousticSimulator, AmbientNoise, ShapedNoise, SoundSource
from ssl_sim.acoustics.noise import DiffuseNoiseField
from ssl_sim.acoustics.rir import _band_weights_fft, early_rir, tail_gain
from ssl_sim.acoustics.signals import TimeKeyedNoise
from ssl_sim.acoustics.simulator import _PoseRirs
from ssl_sim.world import Box, Room, VictimSite, World

FS = 16000


def _cube(centre, edge=0.15) -> np.ndarray:
    """Microphones (8, 3) m at the corners of a cube of ``edge`` around ``centre`` (world frame)."""
    s = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    return np.asarray(centre, float) + edge / 2 * s


# ------------------------------------------------------------------ time-keyed noise blocks
@pytest.mark.parametrize("n0, n", [(0, 50), (95, 10), (-130, 260), (300, 400), (199, 1), (200, 100)])
def test_noise_block_equals_the_joined_chunks(n0, n):
    noise = TimeKeyedNoise(seed=11, stream=3, channels=3, chunk=100)
    k0, k1 = n0 // 100, (n0 + n - 1) // 100
    joined = np.concatenate([noise._chunk(k) for k in range(k0, k1 + 1)], axis=1)
    want = joined[:, n0 - k0 * 100: n0 - k0 * 100 + n]
    got = noise.samples(n0, n)
    assert got.shape == (3, n) and np.array_equal(got, want)


def test_looped_ambient_field_block_equals_the_joined_frames():
    field = DiffuseNoiseField(AmbientNoise(40.0, "hvac"), FS, seed=5, loop_frames=3)
    mics = _cube((2.0, 2.0, 1.0))
    F = field.FRAME
    for n0, n in ((100, 4000), (F - 500, 4000), (2 * F + 10, 2 * F), (-F - 7, 300)):
        got = field.render(mics, n0, n)
        k0, k1 = n0 // F, (n0 + n - 1) // F
        joined = np.concatenate([field._frame(k, mics) for k in range(k0, k1 + 1)], axis=1)
        assert np.array_equal(got, joined[:, n0 - k0 * F: n0 - k0 * F + n])


# ------------------------------------------------------------------ early RIR
def _frac_kernel_reference(delay, half=32):
    """Hann-windowed sinc taps, written out per tap."""
    fl = np.floor(delay)
    base = fl.astype(np.int64)
    offs = np.arange(-half + 1, half + 1)
    pos = base[..., None] + offs
    frac = (delay - fl)[..., None]
    x = offs - frac
    sign = np.where(offs % 2, 1.0, -1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        sinc = np.where(x == 0, 1.0, sign * np.sin(np.pi * np.minimum(frac, 1.0 - frac)) / (np.pi * x))
    a, b = np.pi * offs / half, np.pi * frac / half
    hann = 0.5 + 0.5 * (np.cos(a) * np.cos(b) + np.sin(a) * np.sin(b))
    return pos, sinc * hann


def _early_rir_reference(images, reflection, mics, fs, c, n_pre, length):
    n_mics = mics.shape[0]
    dist = np.linalg.norm(images[:, None, :] - mics[None, :, :], axis=-1)
    pos, ker = _frac_kernel_reference(dist / c * fs + n_pre)
    valid = (pos >= 0) & (pos < length)
    ker = np.where(valid, ker / dist[..., None], 0.0)
    flat_idx = (np.arange(n_mics)[None, :, None] * length + np.where(valid, pos, 0)).ravel()
    if np.allclose(reflection, reflection[:, :1]):
        return np.bincount(flat_idx, (ker * reflection[:, :1, None]).ravel(),
                           minlength=n_mics * length).reshape(n_mics, length)
    n_fft = sfft.next_fast_len(length + 2 * n_pre)
    bw = _band_weights_fft(n_fft, fs)
    spec = np.zeros((n_mics, n_fft // 2 + 1), complex)
    for b in range(reflection.shape[1]):
        train = np.bincount(flat_idx, (ker * reflection[:, b, None, None]).ravel(),
                            minlength=n_mics * length).reshape(n_mics, length)
        spec += sfft.rfft(train, n_fft, axis=1) * bw[b]
    return sfft.irfft(spec, n_fft, axis=1)[:, :length]


@pytest.mark.parametrize("banded", [True, False])
def test_early_rir_equals_the_per_tap_reference(banded):
    rng = np.random.default_rng(4)
    mics = _cube((2.0, 1.5, 0.8))
    images = rng.uniform(-6, 10, (30, 3))
    images[0] = mics.mean(axis=0) + (0.0, 1.0, 0.0)          # a direct path 1 m away
    images[1] = mics[0] + (343.0 / FS * 7, 0.0, 0.0)          # an arrival on a whole sample at microphone 0
    refl = rng.uniform(0.2, 1.0, (30, 7)) if banded else np.repeat(rng.uniform(0.2, 1.0, (30, 1)), 7, axis=1)
    length = 1800
    got = early_rir(images, refl, mics, FS, 343.0, 256, length)
    assert np.array_equal(got, _early_rir_reference(images, refl, mics, FS, 343.0, 256, length))
    assert np.abs(got).max() > 0.5  # the 1 m direct path (amplitude 1/r) is in it


def test_tail_gain_from_the_early_span_equals_the_zero_padded_rir():
    rng = np.random.default_rng(8)
    padded = np.zeros((8, 6000))
    padded[:, :900] = rng.normal(0, 0.1, (8, 900))
    expected = np.exp(-np.arange(6000) / 1500.0) * 1e-3
    assert np.array_equal(tail_gain(padded[:, :900], expected, 400, FS), tail_gain(padded, expected, 400, FS))


# ------------------------------------------------------------------ acoustic simulator
def test_listen_with_a_buried_source_equals_the_fresh_spectrum_path():
    """Burial filters kept per FFT size give the spectrum a fresh computation gives, pose after pose;
    ``listen`` (microphones checked once) equals the public ``pressure`` digitised."""
    world = World(room=Room((6.0, 5.0, 2.8)), obstacles=(Box((3.0, 2.5, 0.4), (0.8, 0.6, 0.8)),),
                  victims=(VictimSite((4.5, 3.5, 0.3)),))
    src = SoundSource((4.5, 3.5, 0.3), ShapedNoise(FS, 2, "pink"), 65.0, buried=0.5)
    cfg = AcousticConfig(seed=3, rt60_s=0.5, ism_order=2, ambient=AmbientNoise(35.0, "hvac"), noise_loop_s=1.024)
    sim = AcousticSimulator(world, cfg, [src])
    n = 4000
    for i, centre in enumerate(((1.0, 1.0, 0.5), (1.3, 1.2, 0.5), (1.0, 1.0, 0.5))):
        mics = _cube(centre)
        pr = sim._pose_rirs(mics)
        n_fft = sfft.next_fast_len(n + sim.rir_length - 1)
        fresh = _PoseRirs(pr.rirs, pr.sources, FS)   # its own burial filters, computed here
        assert np.array_equal(pr.spectrum(n_fft), fresh.spectrum(n_fft))
        n0 = i * 5000
        assert np.array_equal(sim.listen(mics, n / FS, n0 / FS),
                              sim._sensor(8).digitise(sim.pressure(mics, n0, n), n0))
    # a subset of channels is the same rows
    mics = _cube((2.0, 1.0, 0.6))
    assert np.array_equal(sim.pressure(mics, 100, 500, channels=[2, 5]), sim.pressure(mics, 100, 500)[[2, 5]])


# ------------------------------------------------------------------ SRP steering table
def test_point_major_table_gives_the_pair_major_power():
    from ssl_core.geometry import get_array
    from ssl_core.grid import make_grid

    geo = get_array("cube8")
    grid = make_grid(np.deg2rad(3.0), np.deg2rad(-30.0), np.deg2rad(80.0), None)
    tdoa = tdoa_table(geo, grid)
    max_lag = int(np.ceil(np.abs(tdoa).max() * FS * 4)) + 2
    pair_major = SteeringTable(tdoa, FS, 4, max_lag)
    point_major = SteeringTable(tdoa, FS, 4, max_lag, by_point=True)
    assert np.array_equal(point_major.index, pair_major.index) and np.array_equal(point_major.frac, pair_major.frac)
    rng = np.random.default_rng(1)
    gcc = rng.normal(0, 0.3, (len(geo.pairs), 2 * max_lag + 1)).astype(np.float32)
    assert np.array_equal(point_major.power(gcc), pair_major.power(gcc))
    for cols in (np.array([5]), np.arange(40, 220), rng.choice(grid.n_points, 300, replace=False),
                 np.sort(rng.choice(grid.n_points, 700, replace=False))):
        assert np.array_equal(point_major.power(gcc, cols), pair_major.power(gcc, cols))
    rev = np.ascontiguousarray(gcc[:, ::-1])
    assert np.array_equal(point_major.power(rev, np.array([17])), pair_major.power(rev, np.array([17])))


# ------------------------------------------------------------------ rendering and the whole-recording map
def test_rendered_sources_equal_the_direct_convolution():
    """The sources' pressure (FFT convolution at a 5-smooth length, for speed) equals the time-domain convolution
    of each source's signal with its room impulse response, sample n at t = n / fs."""
    world = World(room=Room((6.0, 5.0, 2.8)), obstacles=(Box((3.0, 2.5, 0.4), (0.8, 0.6, 0.8)),),
                  victims=(VictimSite((4.5, 3.5, 0.3)),))
    srcs = [SoundSource((4.5, 3.5, 0.3), ShapedNoise(FS, 2, "pink"), 65.0),
            SoundSource((1.2, 4.0, 1.0), ShapedNoise(FS, 5, "white"), 60.0)]
    sim = AcousticSimulator(world, AcousticConfig(seed=1, rt60_s=0.3, ism_order=1, ambient=None), srcs)
    mics = _cube((1.5, 1.5, 0.5))
    n0, n = 3000, 2500
    got = sim.pressure(mics, n0, n)
    rirs = sim.impulse_responses(mics)            # (S, M, L), sample 0 = N_PRE samples before emission
    L, pre = rirs.shape[-1], sim.N_PRE
    want = np.zeros((8, n))
    for k, s in enumerate(srcs):
        x = s.signal.render(n0 + pre - L + 1, n + L - 1) * s.pressure_at_1m
        for m in range(8):
            want[m] += np.convolve(x, rirs[k, m], mode="valid")
    assert np.abs(want).max() > 1e-3
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9 * np.abs(want).max())


def test_whole_recording_map_equals_the_summed_search_map():
    """When the windows agree on sources, ``locate`` returns the summed GCC's coarse map without searching it for
    peaks: the same map the full search of that GCC gives."""
    from ssl_core.geometry import cube8
    from ssl_core.localizer import Localizer, LocalizerConfig
    from signals import plane_wave

    loc = Localizer(cube8(), LocalizerConfig())
    rng = np.random.default_rng(2)
    u = np.array([0.6, 0.7, 0.2]) / np.linalg.norm([0.6, 0.7, 0.2])
    res = loc.locate(0.1 * plane_wave(cube8().positions, u, rng.standard_normal(FS // 2), FS))
    assert res.detections
    assert np.array_equal(res.srp_map, loc._search(res.gcc, res.n_eff)[0])
