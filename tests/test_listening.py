"""robot.listening: one listen standing still, with the voice scan of longer listens. Truth: plane waves of known
direction (a real talker and a real machine recording 6 dB louder, data set test part) and a localizer that, as
SRP-PHAT beside a louder machine often does, reports only the machine."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from robot.hal import AudioBlock, AudioSource, ManualClock
from robot.listening import NON_VOICE_P, SCAN_MERGE_DEG, VOICE_P, Listener
from signals import plane_wave
from sound_dataset import FS, recordings
from ssl_core.geometry import cube8

POS = cube8().positions
HER_DEG, MACHINE_DEG = 40.0, -60.0


def _unit(az_deg):
    a = math.radians(az_deg)
    return np.array([math.cos(a), math.sin(a), 0.0])


class Stream(AudioSource):
    """A fixed 8-channel float signal served in order; reading takes the block's duration on the clock."""

    def __init__(self, x, clock):
        self.x, self.clock, self.pos = x, clock, 0

    sample_rate = FS
    n_channels = 8

    def read(self, n):
        t = self.clock.now()
        self.clock.sleep(n / FS)
        out = self.x[:, self.pos:self.pos + n]
        self.pos += n
        return AudioBlock(out, FS, t)


@dataclass
class Det:
    azimuth: float
    elevation: float
    power: float
    level_db: float


class MachineOnly:
    """The SRP-PHAT map's single peak: the machine's direction."""

    def locate(self, samples):
        return type("R", (), {"detections": [Det(math.radians(MACHINE_DEG), 0.0, 0.5, -30.0)]})()


def _mixture(with_her: bool, seconds: int = 3) -> np.ndarray:
    n = seconds * FS
    rec = {r.name: r.samples for r in recordings("test")}
    talk, machine = np.resize(rec["it_carlo"], n), np.resize(rec["ore_mine"], n)
    machine = machine * 2 * np.sqrt(np.mean(talk**2) / np.mean(machine**2))   # 6 dB louder
    x = plane_wave(POS, _unit(MACHINE_DEG), machine, FS) + 1e-4 * np.random.default_rng(3).standard_normal((8, n))
    return x + plane_wave(POS, _unit(HER_DEG), talk, FS) if with_her else x


def _listen(x, scan_s):
    clock = ManualClock()
    return Listener(Stream(x, clock), clock, MachineOnly(), POS, voice_threshold=0.1).listen(1.0, 0.0, 0.0, scan_s)


def test_a_scanning_listen_adds_her_voice_bearing_the_localizer_missed():
    res = _listen(_mixture(True), 3.0)
    assert res.block.samples.shape[1] == 3 * FS          # 3 s heard, the localizer the last 1 s
    machine = [e for e in res.evidence if abs(math.degrees(e.azimuth) - MACHINE_DEG) < 1.0]
    assert len(machine) == 1 and machine[0].voice_probability == NON_VOICE_P
    scan = [e for e in res.evidence if e is not machine[0]]
    assert len(scan) == 1 and scan[0].voice_probability == VOICE_P
    assert abs(math.degrees(math.remainder(scan[0].azimuth - math.radians(HER_DEG), 2 * math.pi))) <= 10.0
    assert scan[0].elevation == 0.0


def test_without_her_or_without_scan_s_no_bearing_is_added():
    assert [round(math.degrees(e.azimuth)) for e in _listen(_mixture(False), 3.0).evidence] == [MACHINE_DEG]
    res = _listen(_mixture(True), 0.0)
    assert res.block.samples.shape[1] == FS and not res.scan
    assert [round(math.degrees(e.azimuth)) for e in res.evidence] == [MACHINE_DEG]


def test_a_scan_direction_beside_a_detection_adds_nothing():
    clock = ManualClock()
    lis = Listener(Stream(np.zeros((8, FS)), clock), clock, MachineOnly(), POS)
    ev = _listen(_mixture(False), 0.0).evidence
    near = math.radians(MACHINE_DEG + SCAN_MERGE_DEG - 1)
    assert lis._merge_scan(ev, near, np.zeros((8, FS))) == ev
    far = lis._merge_scan(ev, math.radians(HER_DEG), 1e-3 * np.ones((8, FS)))
    assert len(far) == 2 and far[1].voice_probability == VOICE_P
