"""Damaged model files stop a program at its start, naming the file, before any device opens; a model failing
at run time fails the run, and only the audio source's own end of stream ends a mission as ``audio_ended``."""
from __future__ import annotations

import gzip
import json
import math

import numpy as np
import pytest

import robot.vad as vad
from robot.hal import AudioBlock, AudioSource, EndOfAudio, ManualClock
from robot.vad import ModelError, check_model

FILES = {"encoder": "SPLIT_8K_ENCODER_PATH", "lstm": "SPLIT_8K_LSTM_PATH"}


def _damaged(data: bytes, how: str) -> bytes:
    if how == "truncated":
        return data[:len(data) // 2]
    if how == "empty":
        return b""
    if how == "random":
        return np.random.default_rng(7).bytes(len(data))
    flipped = bytearray(data)
    flipped[len(data) // 2] ^= 0x04   # one bit in the middle of the payload
    return bytes(flipped)


CASES = [(f, how) for f in FILES for how in ("truncated", "empty", "random", "bit_flipped")]


@pytest.fixture(params=CASES, ids=[f"{f}-{h}" for f, h in CASES])
def damaged_model(request, tmp_path, monkeypatch):
    """One shipped model file replaced by a damaged copy; returns its path."""
    which, how = request.param
    original = getattr(vad, FILES[which])
    bad = tmp_path / original.name
    bad.write_bytes(_damaged(original.read_bytes(), how))
    monkeypatch.setattr(vad, FILES[which], bad)
    return bad


def test_check_model_names_the_damaged_file(damaged_model):
    with pytest.raises(ModelError) as err:
        check_model(8000)
    msg = str(err.value)
    assert str(damaged_model) in msg and "\n" not in msg
    assert not isinstance(err.value, EOFError)   # never to be taken for the end of the audio


def test_the_shipped_models_pass_the_check():
    v = check_model(8000)
    assert v.sample_rate == 8000 and v.split
    assert check_model(16000).model_path == vad.MODEL_PATH


def _opened(monkeypatch, module, names):
    """Replace ``module``'s device openers by recorders: what a program opened, in order."""
    opened = []
    for name in names:
        monkeypatch.setattr(module, name, lambda *a, _n=name, **k: opened.append(_n) or pytest.fail(f"{_n} called"))
    return opened


@pytest.mark.parametrize("mode", [["--serial", "/dev/ttyUSB0", "--audio", "1,2"], ["--dry-run", "--replay", "rec.wav"]])
def test_ssl_robot_stops_before_opening_the_drive_or_audio(damaged_model, monkeypatch, capsys, mode):
    import robot.cli as cli

    opened = _opened(monkeypatch, cli, ["_open_drive", "_open_audio"])
    assert cli.main(mode) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(damaged_model) in err[0], err
    assert opened == []


def test_ssl_rescue_run_stops_before_simulating_or_writing(damaged_model, monkeypatch, capsys, tmp_path):
    import ssl_sim.runner as runner
    from ssl_sim.cli import main

    opened = _opened(monkeypatch, runner, ["RescueRun", "SimAudioSource"])
    out = tmp_path / "runs" / "x"
    assert main(["run", "paper_lab", "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(damaged_model) in err[0], err
    assert opened == [] and not (tmp_path / "runs").exists()


# ---------------------------------------------------------------- at run time
class _Quiet(AudioSource):
    """8 channels of low noise; ``end`` raises at the given read (None: never ends)."""

    def __init__(self, clock, end: BaseException | None = None) -> None:
        self.clock, self.end, self.rng = clock, end, np.random.default_rng(0)

    sample_rate = property(lambda self: 16000)
    n_channels = property(lambda self: 8)

    def read(self, n):
        if self.end is not None:
            raise self.end
        self.clock.sleep(n / 16000)
        return AudioBlock((1e-3 * self.rng.standard_normal((8, n))).astype(np.float32), 16000, self.clock.now())


def _behaviour(audio, clock):
    from robot.rescue import RescueBehaviour
    from robot.replay import DryRunDrive
    from ssl_core.geometry import cube8
    from ssl_core.localizer import Localizer, LocalizerConfig

    return RescueBehaviour(audio, DryRunDrive(clock), clock, Localizer(cube8(), LocalizerConfig()),
                           speech=lambda *a: 0.0)


def test_only_the_sources_end_of_stream_ends_a_mission_as_audio_ended():
    from robot.rescue import Decision

    clock = ManualClock()
    b = _behaviour(_Quiet(clock, EndOfAudio("rec.wav: end reached")), clock)
    assert b.step()[-1].decision is Decision.AUDIO_ENDED and b.done
    # a gzip stream cut short raises a plain EOFError: a failure of the run, not the end of the audio
    try:
        gzip.decompress(gzip.compress(b"model" * 100)[:20])
    except EOFError as exc:
        gzip_eof = exc
    clock = ManualClock()
    b = _behaviour(_Quiet(clock, gzip_eof), clock)
    with pytest.raises(EOFError):
        b.step()
    assert not b.done and b.events[-1].decision is Decision.ERROR


def test_a_model_failing_at_run_time_fails_the_behaviour_step(monkeypatch):
    from robot.rescue import Decision, RescueBehaviour
    from robot.replay import DryRunDrive
    from ssl_core.geometry import cube8
    from ssl_core.localizer import Localizer, LocalizerConfig

    def broken(self, inputs, state):
        raise EOFError("Compressed file ended before the end-of-stream marker was reached")

    check_model(8000)   # checked at the start, as a program does; the model breaks afterwards
    monkeypatch.setattr(vad.SileroVad, "_run_split", broken)
    clock = ManualClock()
    talker = _Talker(clock)
    b = RescueBehaviour(talker, DryRunDrive(clock), clock, Localizer(cube8(), LocalizerConfig(n_sources=1)))
    with pytest.raises(ModelError, match="silero_vad_8k_encoder.onnx.gz: failed at run time"):
        for _ in range(3):
            b.step()
    assert not b.done and b.events[-1].decision is Decision.ERROR


class _Talker(_Quiet):
    """A harmonic 'voice' 2 m away at azimuth 60 deg (exact delays), so that a listen hears a source."""

    def read(self, n):
        from ssl_core.geometry import cube8

        t = (np.arange(n) + round(self.clock.now() * 16000)) / 16000
        s = sum(np.sin(2 * np.pi * k * 150 * t) / k for k in range(1, 20))
        src = np.array([2 * math.cos(math.radians(60)), 2 * math.sin(math.radians(60)), 0.0])
        r = np.linalg.norm(cube8().positions - src, axis=1)
        f = np.fft.rfftfreq(n, 1 / 16000)
        x = np.fft.irfft(np.fft.rfft(s)[None] * np.exp(-2j * np.pi * f[None] * (r / 343.0)[:, None]), n)
        self.clock.sleep(n / 16000)
        return AudioBlock((0.1 * x).astype(np.float32), 16000, self.clock.now())


def test_a_run_whose_model_fails_says_so_in_its_results_and_exit_code(monkeypatch, tmp_path, capsys):
    from ssl_sim.cli import main

    def broken(self, inputs, state):
        raise RuntimeError("[ONNXRuntimeError] : 6 : RUNTIME_EXCEPTION : Non-zero status code")

    check_model(8000)   # checked at the start, as a program does; the model breaks afterwards
    monkeypatch.setattr(vad.SileroVad, "_run_split", broken)
    out = tmp_path / "run"
    assert main(["run", "paper_lab", "--time-limit", "20", "--out", str(out), "-q"]) == 1
    result = json.loads((out / "results.json").read_text())
    assert result["end_reason"] == "failed_model"
    assert result["failure"]["part"] == "model" and "silero_vad_8k_encoder" in result["failure"]["file"]
    assert "failed_model" in capsys.readouterr().err


def test_ssl_robot_exits_1_naming_the_model_that_failed_while_running(monkeypatch, tmp_path, capsys):
    """A replay with a talker: the model breaks after the start check; the mission fails (exit 1, the file named),
    it does not end as audio_ended."""
    from scipy.io import wavfile

    import robot.cli as cli

    clock = ManualClock()
    x = np.concatenate([_Talker(clock).read(16000).samples for _ in range(3)], axis=1)
    rec = tmp_path / "rec.wav"
    wavfile.write(rec, 16000, (0.3 * x.T / np.abs(x).max() * 32767).astype(np.int16))

    def broken(self, inputs, state):
        raise EOFError("Compressed file ended before the end-of-stream marker was reached")

    check_model(8000)   # checked at the start, as a program does; the model breaks afterwards
    monkeypatch.setattr(vad.SileroVad, "_run_split", broken)
    assert cli.main(["--dry-run", "--replay", str(rec), "--json", "--max-time", "100"]) == 1
    got = capsys.readouterr()
    assert "silero_vad_8k_encoder.onnx.gz: failed at run time" in got.err
    assert '"audio_ended"' not in got.out
