"""Surface materials come from pyroomacoustics' database (``ssl_sim.acoustics.materials``) and shape the
reverberation: a concrete shoebox decays as Sabine's and Eyring's formulas predict from the database's
absorption coefficients (independent truth: the formulas evaluated here, the decay measured on the
simulated impulse response by Schroeder backward integration)."""
from __future__ import annotations

import math

import numpy as np
import pyroomacoustics as pra
import pytest
from scipy import signal

from ssl_sim.acoustics import AcousticConfig, AcousticSimulator, SoundSource, get_material
from ssl_sim.acoustics.signals import ShapedNoise
from ssl_sim.world import Room, World

FS = 16000


def _database_alpha(name: str, f: float) -> float:
    """Absorption of database entry ``name`` at octave centre ``f`` (Hz), read straight from pyroomacoustics."""
    for group in pra.materials_data["absorption"].values():
        if name in group:
            centres = group[name].get("center_freqs", pra.materials_data["center_freqs"])
            return float(group[name]["coeffs"][list(centres).index(f)])
    raise KeyError(name)


def _t20(h: np.ndarray, f: float) -> float:
    """Reverberation time (s) from the -5..-25 dB part of the Schroeder decay of ``h`` in the octave at ``f``."""
    sos = signal.butter(4, [f / math.sqrt(2), f * math.sqrt(2)], "bandpass", fs=FS, output="sos")
    e = np.cumsum(signal.sosfilt(sos, h)[::-1] ** 2)[::-1]
    db = 10 * np.log10(e / e[0])
    sel = (db <= -5) & (db >= -25)
    t = np.arange(h.size) / FS
    slope = np.polyfit(t[sel], db[sel], 1)[0]
    return -60.0 / slope


@pytest.mark.parametrize("f", [500.0, 1000.0, 2000.0])
def test_concrete_shoebox_rt60_matches_sabine_and_eyring(f):
    size = (4.0, 3.0, 2.5)
    world = World(room=Room(size, "concrete", "concrete", "concrete"))
    assert get_material("concrete").name == "concrete"  # alias of the database's rough_concrete
    alpha = _database_alpha("rough_concrete", f)
    v = math.prod(size)
    s = 2 * (size[0] * size[1] + size[0] * size[2] + size[1] * size[2])
    sabine = 24 * math.log(10) * v / (343.0 * s * alpha)
    eyring = 24 * math.log(10) * v / (343.0 * s * -math.log(1 - alpha))
    sim = AcousticSimulator(world, AcousticConfig(ambient=None, seed=2, max_rir_s=4.5),
                            sources=[SoundSource((1.1, 0.9, 1.2), ShapedNoise(FS, 0))])
    h = sim.impulse_responses(np.array([[2.9, 2.2, 1.4]]))[0, 0]
    t = _t20(h, f)
    print(f"{f:.0f} Hz: measured T20 {t:.2f} s, Sabine {sabine:.2f} s, Eyring {eyring:.2f} s")
    assert t == pytest.approx(eyring, rel=0.15)
    assert t == pytest.approx(sabine, rel=0.15)


def test_open_walls_absorb_like_holes():
    """Brick walls with 20 % of their area open (doorways, broken windows: alpha = 1), concrete floor and
    ceiling: the decay follows Eyring with the area-weighted absorption of wall and hole."""
    size = (5.0, 4.0, 3.0)
    f, freq = 0.2, 1000.0
    world = World(room=Room(size, "brickwork", "concrete", "concrete", wall_open_fraction=f))
    a_wall = f + (1 - f) * _database_alpha("brickwork", freq)
    a_conc = _database_alpha("rough_concrete", freq)
    s_wall = 2 * (size[0] + size[1]) * size[2]
    s_fc = 2 * size[0] * size[1]
    mean_a = (s_wall * a_wall + s_fc * a_conc) / (s_wall + s_fc)
    eyring = 24 * math.log(10) * math.prod(size) / (343.0 * (s_wall + s_fc) * -math.log(1 - mean_a))
    sim = AcousticSimulator(world, AcousticConfig(ambient=None, seed=4, max_rir_s=2.0),
                            sources=[SoundSource((1.2, 1.1, 1.3), ShapedNoise(FS, 0))])
    t = _t20(sim.impulse_responses(np.array([[3.7, 2.6, 1.5]]))[0, 0], freq)
    assert t == pytest.approx(eyring, rel=0.15)


def test_open_fraction_is_validated():
    with pytest.raises(ValueError, match="wall_open_fraction"):
        Room((5.0, 4.0, 3.0), wall_open_fraction=1.0)
