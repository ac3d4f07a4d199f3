"""Microphone faults reach the robot log, ``ssl-robot`` and the simulator's rerun log and results, and the
faulty channel leaves the localization (robot.monitored_audio + ssl_core.health)."""
from __future__ import annotations

import io
import logging

import numpy as np
import pytest
from scipy.io import wavfile

from robot.cli import main
from robot.hal import AudioBlock, AudioSource
from signals import plane_wave, speech_like
from ssl_core.geometry import cube8
from ssl_core.grid import direction_from_angles

FS = 16000
DEAD = 3


class _DeadChannel(AudioSource):
    """``source`` with channel ``ch`` disconnected (zeros), the fault under test."""

    def __init__(self, source: AudioSource, ch: int) -> None:
        self.source, self.ch = source, ch

    sample_rate = property(lambda self: self.source.sample_rate)
    n_channels = property(lambda self: self.source.n_channels)

    def read(self, n: int) -> AudioBlock:
        b = self.source.read(n)
        x = b.samples.copy()
        x[self.ch] = 0
        return AudioBlock(x, b.sample_rate, b.timestamp)

    def flush(self) -> None:
        self.source.flush()


@pytest.fixture(scope="module")
def dead_mic_recording(tmp_path_factory):
    """12 s, 8 channels: a talker at azimuth -50 deg, elevation 10 deg (exact delays), mic 3 dead. (Long enough
    for two listens whatever the behaviour does between them: the replay's clock runs while it drives.)"""
    u = direction_from_angles(np.deg2rad(-50), np.deg2rad(10))
    x = 0.1 * plane_wave(cube8().positions, u, speech_like(12 * FS, FS, seed=3), FS)
    x += 0.002 * np.random.default_rng(1).standard_normal(x.shape)
    x[DEAD] = 0
    p = tmp_path_factory.mktemp("rec") / "dead3.wav"
    wavfile.write(p, FS, (x.T * 32767).astype(np.int16))
    return p


def test_ssl_robot_prints_the_fault_and_localizes_without_the_mic(dead_mic_recording, caplog):
    out = io.StringIO()
    with caplog.at_level(logging.WARNING, logger="robot.monitored_audio"):
        code = main(["--dry-run", "--replay", str(dead_mic_recording), "--max-time", "100"], out=out)
    text = out.getvalue()
    assert code == 0
    assert f"ssl-robot: microphone fault at 2.0 s: dead mic {DEAD}" in text  # after two 1 s listens
    assert f"dead mic {DEAD}" in caplog.text and f"localizing without microphone(s) [{DEAD}]" in caplog.text
    heard = [line for line in text.splitlines() if line.split()[3:5] == ["listen", "heard"]]  # the mapped sources
    assert heard and all(abs(float(h.split("az ")[1].split(" deg")[0]) + 50) <= 3 for h in heard)


def test_simulated_run_logs_the_fault_to_rerun_and_results():
    from ssl_sim.runner import RescueRun
    from ssl_sim.scenario import load_scenario
    from ssl_sim.viz import RunLogger

    class Events(RunLogger):
        enabled = True
        events: list = []

        def event(self, t, state, text, level="INFO"):
            self.events.append((state, text, level))

    logger = Events()
    run = RescueRun(load_scenario("paper_lab").with_overrides(time_limit_s=8.0), logger=logger)
    run.mic_health.source = _DeadChannel(run.audio, DEAD)
    result = run.run()
    faults = [(s, t, lvl) for s, t, lvl in logger.events if s == "health"]
    assert faults and faults[0][1].startswith(f"microphone fault: dead mic {DEAD}") and faults[0][2] == "WARN"
    assert result["microphone_faults"][0]["kind"] == "dead" and result["microphone_faults"][0]["channels"] == [DEAD]
    assert run.localizer._loc._pair_weights is not None  # mic 3's pairs left the SRP sum


def test_a_one_sample_device_slip_is_seen_by_the_monitor_and_resynced():
    """Two-device capture whose device B slips by one sample 2 s in, with scheduled tracking off: the health
    monitor names the slip and the capture re-measures its offset at once; the fault then clears."""
    from test_audio_capture import _devices, _FakeSD, _plane_wave, _unit

    from robot.hardware.audio import ArrayCapture
    from robot.monitored_audio import MonitoredAudio
    from ssl_core.health import MicHealth

    g = cube8()
    truth = 0.3 * _plane_wave(_unit(35, 15), 6 * FS, seed=12) / 4
    before, after = _devices(truth, 300), _devices(truth, 301)
    at = 2 * FS
    cap = ArrayCapture((1, 2), FS, positions=g.positions, blocksize=512, track_every_s=None,
                       backend=_FakeSD([before[0], np.concatenate([before[1][:, :at], after[1][:, at:]], axis=1)],
                                       pace=0.15))
    cap.merger.set_offset(300)
    seen = []
    audio = MonitoredAudio(cap, MicHealth(g, devices=[0] * 4 + [1] * 4),
                           on_change=lambda t, new, cleared: seen.extend((t, f.kind, f.value) for f in new))
    fixed_at = None
    while cap.merger.cursor < 5 * FS:
        audio.read(1024)
        if fixed_at is None and cap.merger.offset == 301:
            fixed_at = cap.merger.cursor
    cap.close()
    slips = [(t, v) for t, kind, v in seen if kind == "device_slip"]
    assert len(slips) == 1 and slips[0][1] == pytest.approx(1.0, abs=0.4)
    assert fixed_at is not None and fixed_at - (at - 300) <= 2 * FS  # within 2 s of audio after the slip
    assert not audio.report.faults                                     # and the fault has cleared


@pytest.mark.parametrize("slip", [80, -80, 2000])
def test_a_large_device_slip_is_named_and_corrected_within_2_s(slip):
    """A talker in a reverberant room; device B's stream slips by 80 samples (5 ms, ten times the pair delays'
    own search) or 2000 (125 ms) 2 s in, scheduled tracking off: the monitor names the slip with its size, the
    capture re-aligns within 2 s of audio, and the bearings after it are as good as those of the same audio never
    slipped."""
    from signals import room_talker
    from test_audio_capture import _devices, _FakeSD, _unit

    from robot.hardware.audio import ArrayCapture
    from robot.monitored_audio import MonitoredAudio
    from ssl_core.grid import angular_distance
    from ssl_core.health import MicHealth
    from ssl_core.localizer import Localizer, LocalizerConfig

    g = cube8()
    u = _unit(-70, 20)
    truth = 0.5 * room_talker(g.positions, u, 7.0, FS, seed=5)
    before, after = _devices(truth, 300), _devices(truth, 300 + slip)
    at = 2 * FS
    cap = ArrayCapture((1, 2), FS, positions=g.positions, blocksize=512, track_every_s=None,
                       backend=_FakeSD([before[0], np.concatenate([before[1][:, :at], after[1][:, at:]], axis=1)],
                                       pace=0.15))
    cap.merger.set_offset(300)
    seen = []
    audio = MonitoredAudio(cap, MicHealth(g, devices=[0] * 4 + [1] * 4),
                           on_change=lambda t, new, cleared: seen.extend((f.kind, f.value) for f in new))
    loc = Localizer(g, LocalizerConfig(fs=FS, n_sources=1))
    fixed_at, late = None, []
    while cap.merger.cursor < 6 * FS:
        block = audio.read(1600)
        if fixed_at is None and cap.merger.offset == 300 + slip:
            fixed_at = cap.merger.cursor
        if fixed_at is not None and cap.merger.cursor - 1600 >= fixed_at:
            late.append((cap.merger.cursor - 1600, block.samples))
    cap.close()
    slips = [v for kind, v in seen if kind == "device_slip"]
    assert len(slips) == 1 and slips[0] == pytest.approx(slip, abs=0.5)
    assert fixed_at is not None and fixed_at - (at - 300) <= 2 * FS   # within 2 s of audio after the slip
    assert len(late) >= 10

    def error(samples) -> float:
        r = loc.locate(samples)
        return float(np.rad2deg(angular_distance(r.detections[0].direction, u))) if r.detections else 180.0

    # the same instants of the audio as never slipped (array truth), localized the same way
    got = np.mean([error(s) for _, s in late])
    ref = np.mean([error((truth[:, c:c + 1600] * 32767).astype(np.int16)) for c, _ in late])
    print(f"slip {slip}: mean bearing error after correction {got:.2f} deg, never slipped {ref:.2f} deg")
    assert got <= ref + 0.5
