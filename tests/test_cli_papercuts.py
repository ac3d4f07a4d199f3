"""What a user of the three command-line programs meets first: --help answers without loading the numerical
stack, a closed pipe (``| head``) ends a program quietly, JSON on stdout is JSON alone and streams as it comes,
and a file at too low a sample rate is blamed on its rate, not on an option the user never gave."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from signals import plane_wave
from ssl_core.broken_pipe import EXIT_BROKEN_PIPE
from ssl_core.geometry import cube8
from ssl_core.grid import direction_from_angles

SRC = Path(__file__).resolve().parents[1] / "src"
FS = 16000
PROGRAMS = {"ssl-locate": "ssl_core.cli", "ssl-robot": "robot.cli", "ssl-rescue": "ssl_sim.cli"}


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=str(SRC))


@pytest.fixture(scope="module")
def talker(tmp_path_factory) -> Path:
    """6 s, 8 channels: white noise arriving as a plane wave from azimuth -60 deg, elevation 20 deg."""
    u = direction_from_angles(np.deg2rad(-60), np.deg2rad(20))
    x = 0.2 * plane_wave(cube8().positions, u, np.random.default_rng(0).standard_normal(6 * FS), FS)
    path = tmp_path_factory.mktemp("talker") / "talker.wav"
    wavfile.write(path, FS, np.round(x.T * 32767).astype(np.int16))
    return path


@pytest.mark.parametrize("prog", sorted(PROGRAMS))
def test_help_loads_neither_scipy_signal_nor_the_simulator(prog):
    """--help parses before the numerical stack is imported (scipy.signal and scipy.stats alone take seconds)."""
    probe = (f"import sys\nfrom {PROGRAMS[prog]} import main\n"
             "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
             "heavy = sorted(m for m in sys.modules if m.startswith(('scipy', 'mujoco', 'pyroomacoustics', "
             "'onnxruntime', 'rerun', 'ssl_sim.scenario', 'robot.rescue', 'ssl_core.localizer')))\n"
             "print(heavy, file=sys.stderr)\nsys.exit(1 if heavy else 0)\n")
    p = subprocess.run([sys.executable, "-c", probe], env=_env(), capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    assert "usage:" in p.stdout


@pytest.mark.parametrize("prog,args", [
    ("ssl-locate", ["{talker}", "--stream"]),
    ("ssl-locate", ["{talker}", "--stream", "--json"]),
    ("ssl-robot", ["--dry-run", "--replay", "{talker}", "--max-time", "5"]),
    ("ssl-rescue", ["list"]),
])
def test_a_closed_pipe_ends_the_program_quietly(prog, args, talker):
    """As ``prog ... | head -0``: the reader is gone before the first line; no traceback, no "Exception ignored",
    exit status 141 (128 + SIGPIPE) as for a program SIGPIPE ended."""
    cmd = [sys.executable, "-m", PROGRAMS[prog], *[a.format(talker=talker) for a in args]]
    p = subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    p.stdout.close()
    err = p.stderr.read()
    assert p.wait(timeout=300) == EXIT_BROKEN_PIPE, err
    assert "Traceback" not in err and "BrokenPipe" not in err and "Exception ignored" not in err, err


def test_stream_json_prints_each_window_as_it_is_done(talker, monkeypatch):
    """--stream --json: one JSON object per window and line, each written (and flushed) before the next window
    is analysed, not one document at the end."""
    from ssl_core import cli
    from ssl_core.localizer import Localizer

    windows_done = []
    process = Localizer.process

    def counted(self, block, fs=None):
        out = process(self, block, fs)
        windows_done.append(len(out))
        return out

    class Lines:
        def __init__(self):
            self.lines, self.at = [], []

        def write(self, s):
            self.lines.append(s)

        def flush(self):
            self.at.append(sum(windows_done))   # windows analysed when this much had been written

    out = Lines()
    monkeypatch.setattr(Localizer, "process", counted)
    monkeypatch.setattr(sys, "stdout", out)
    assert cli.main([str(talker), "--stream", "--json"]) == 0
    monkeypatch.undo()
    records = [json.loads(line) for line in "".join(out.lines).splitlines()]
    n = sum(windows_done)
    assert len(records) == n >= 40
    assert all(set(r) == {"time_s", "detections"} for r in records)
    assert abs(records[5]["detections"][0]["azimuth_deg"] + 60) < 2.0
    assert out.at[0] <= 8 < n   # the first line left within the first block of windows (1 s)


def test_an_8khz_file_is_blamed_on_its_rate(tmp_path, capsys):
    from ssl_core.cli import main

    x = np.random.default_rng(1).standard_normal((8000, 8)) * 0.1
    path = tmp_path / "phone.wav"
    wavfile.write(path, 8000, np.round(x * 32767).astype(np.int16))
    assert main([str(path)]) == 2
    err = capsys.readouterr().err
    assert "sample rate 8000 Hz" in err and "12000 Hz" in err and "--band 300 6000" not in err
    assert main([str(path), "--band", "300", "3400"]) == 0  # a band the file holds: analysed
    capsys.readouterr()
    assert main([str(path), "--band", "300", "6000"]) == 2   # a band the user gave and the file lacks
    err = capsys.readouterr().err
    assert err.startswith("ssl-locate: --band 300 6000") and "sampled at 8000 Hz" in err


def test_run_json_is_alone_on_stdout(tmp_path, capsys):
    from ssl_sim.cli import main

    assert main(["run", "paper_lab", "--time-limit", "3", "-q", "--json", "--out", str(tmp_path / "run")]) == 0
    cap = capsys.readouterr()
    summary = json.loads(cap.out)   # the whole of stdout is the one JSON line
    # the run ends with the cycle in which the limit passes (a settle and a 1 s listen)
    assert summary["scenario"] == "paper_lab" and 3.0 <= summary["sim_time_s"] <= 4.5
    assert "scenario paper_lab" in cap.err and "wrote" in cap.err
