"""``ssl-rescue record``: the WAV it writes is what ``ssl-locate`` needs, and its truth JSON agrees with
the geometry (independent truth: the victims' world positions and the robot pose given on the command
line) and with what ``ssl-locate`` finds in the recording (within 5 deg)."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.io import wavfile

from ssl_core.cli import main as locate_main
from ssl_sim.cli import main as cli_main

TWO_CALLERS = """
name = "two_callers"
description = "Empty lab, two people calling continuously"
seed = 0
[scene]
name = "empty_lab"
[robot]
start = [3.0, 3.0, 0.0]
[[victims]]
position = [4.6, 3.9, 0.1]
sound = "continuous"
speaker = "male"
level_db_spl = 65.0
[[victims]]
position = [2.0, 1.4, 1.2]
sound = "continuous"
speaker = "female"
level_db_spl = 65.0
[noise]
level_db_spl = 30.0
[acoustics]
rt60_s = 0.3
max_rir_s = 0.5
"""


def _unit(az_deg: float, el_deg: float) -> np.ndarray:
    a, e = math.radians(az_deg), math.radians(el_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def _angle_deg(u: np.ndarray, v: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip(u @ v, -1.0, 1.0))))


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    (d / "two.toml").write_text(TWO_CALLERS)
    wav = d / "rec.wav"
    # A pose other than the scenario's start: the truth must follow it.
    assert cli_main(["record", str(d / "two.toml"), "--seed", "3", "--duration", "4", "--pose", "3.2,2.9,0.6",
                     "--out", str(wav)]) == 0
    return wav, json.loads(wav.with_suffix(".json").read_text())


def test_wav_is_8_channel_16_bit_at_the_stated_rate(recording):
    wav, truth = recording
    fs, x = wavfile.read(wav)
    assert fs == truth["fs"] == 16000
    assert x.dtype == np.int16 and x.shape == (4 * 16000, 8)
    assert np.all(np.std(x.astype(float), axis=0) > 5)  # every channel carries sound


def test_truth_matches_geometry_of_pose(recording):
    _, truth = recording
    assert truth["robot_start"] == {"x": 3.2, "y": 2.9, "yaw_rad": 0.6}
    assert len(truth["time_s"]) == 40
    for s in truth["sources"]:
        x, y, z = s["position_world_m"]
        dx, dy = x - 3.2, y - 2.9
        # Expected azimuth in the array frame: world bearing minus the robot's yaw (the robot stands level;
        # MuJoCo settles it within a fraction of a degree).
        az = math.degrees(math.atan2(dy, dx) - 0.6)
        az = (az + 180) % 360 - 180
        assert np.allclose(s["azimuth_deg"], az, atol=1.0)
        # The array centre stands ~0.27 m above the floor (RobotModelConfig.array_height).
        dz = z - 0.27
        r = math.sqrt(dx * dx + dy * dy + dz * dz)
        assert np.allclose(s["distance_m"], r, atol=0.02)
        assert np.allclose(s["elevation_deg"], math.degrees(math.asin(dz / r)), atol=1.0)
        assert 0.5 < s["sounding_fraction"] <= 1.0  # "continuous" talkers pause between phrases
        for lvl, on in zip(s["level_db_spl_at_array"], s["sounding"]):
            assert (lvl is None) == (not on)
            if on:
                assert lvl == pytest.approx(65.0 - 20 * math.log10(r), abs=0.2)


def test_ssl_locate_finds_the_recorded_sources(recording, capsys):
    """Per analysis window (``--stream``), as one would look at a recording with several talkers: every
    recorded source is found, the detections nearest to it lie within 5 deg (median) of its truth."""
    wav, truth = recording
    capsys.readouterr()
    assert locate_main([str(wav), "--array", "cube8", "--sources", "2", "--stream", "--window", "16", "--json"]) == 0
    windows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]  # one JSON line per window
    found = [_unit(d["azimuth_deg"], d["elevation_deg"]) for w in windows for d in w["detections"]]
    true_dirs = []
    for s in truth["sources"]:
        on = np.asarray(s["sounding"])
        true_dirs.append(_unit(np.mean(np.asarray(s["azimuth_deg"])[on]), np.mean(np.asarray(s["elevation_deg"])[on])))
    errs = np.array([[_angle_deg(t, f) for t in true_dirs] for f in found])  # (detections, sources)
    nearest = errs.argmin(axis=1)
    for k, s in enumerate(truth["sources"]):
        mine = errs[nearest == k, k]
        assert mine.size >= 3, f"{s['name']}: found in only {mine.size} windows"
        assert np.median(mine) < 5.0, f"{s['name']}: median error {np.median(mine):.1f} deg"


def test_bad_pose_names_the_option(tmp_path, capsys):
    assert cli_main(["record", "paper_lab", "--pose", "3,3", "--out", str(tmp_path / "x.wav")]) == 2
    assert "--pose" in capsys.readouterr().err
    assert cli_main(["record", "paper_lab", "--pose", "30,3,0", "--out", str(tmp_path / "x.wav")]) == 2
    assert "--pose" in capsys.readouterr().err
    assert cli_main(["record", "paper_lab", "--duration", "-1", "--out", str(tmp_path / "x.wav")]) == 2
    assert "--duration" in capsys.readouterr().err


def _never_simulated(monkeypatch):
    """Building the scenario's HAL fails the test: a refused --out must be found before anything is simulated."""
    from ssl_sim.scenario import Scenario

    monkeypatch.setattr(Scenario, "hal", lambda *a, **k: pytest.fail("simulated before --out was checked"))


@pytest.mark.parametrize("case", ["json_name", "directory", "directory_slash", "empty", "parent_is_a_file"])
def test_bad_out_is_refused_before_recording(case, tmp_path, capsys, monkeypatch):
    (tmp_path / "notes.txt").write_text("a file")
    out, expected = {
        "json_name": (str(tmp_path / "take.json"), "would overwrite the recording"),
        "directory": (str(tmp_path), "is a directory"),
        "directory_slash": (str(tmp_path / "new") + "/", "is a directory"),
        "empty": ("", "expected a WAV file name"),
        # root may write anywhere: a path under a regular file is what nobody can create
        "parent_is_a_file": (str(tmp_path / "notes.txt" / "take.wav"), "notes.txt is a file, not a directory"),
    }[case]
    _never_simulated(monkeypatch)
    before = sorted(tmp_path.rglob("*"))
    assert cli_main(["record", "paper_lab", "--duration", "2", "--out", out]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ssl-rescue: error: --out") and expected in err and "Traceback" not in err, err
    assert sorted(tmp_path.rglob("*")) == before   # nothing written or created


def test_interrupted_recording_leaves_a_valid_shorter_wav_and_json(tmp_path):
    """Ctrl-C 2 s of audio into a 60 s recording: exit 130, and the WAV and truth JSON hold the same, shorter
    duration (a WAV whose header matches its data; truth frames covering it)."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    src = Path(__file__).resolve().parents[1] / "src"
    out = tmp_path / "take.wav"
    partial = tmp_path / ".take.wav.partial"
    p = subprocess.Popen([sys.executable, "-m", "ssl_sim.cli", "record", "paper_lab", "--duration", "60",
                          "--out", str(out)], env=dict(os.environ, PYTHONPATH=str(src)), stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True,
                         preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and p.poll() is None:
            if partial.exists() and partial.stat().st_size > 44 + 2 * 8 * 16000 * 2:   # 2 s of audio written
                break
            time.sleep(0.05)
        assert p.poll() is None, p.communicate()
        p.send_signal(signal.SIGINT)
        stdout, stderr = p.communicate(timeout=120)
    finally:
        p.kill()
    assert p.returncode == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr, stderr
    fs, data = wavfile.read(out)   # a valid WAV: its header's length is its data's
    assert fs == 16000 and data.dtype == np.int16 and data.shape[1] == 8
    assert out.stat().st_size == 44 + data.size * 2
    truth = json.loads(out.with_suffix(".json").read_text())
    assert truth["interrupted"] is True
    assert 2.0 <= truth["duration_s"] < 60 and data.shape[0] == round(truth["duration_s"] * fs)
    assert truth["time_s"][-1] <= truth["duration_s"] and len(truth["sources"][0]["azimuth_deg"]) == len(truth["time_s"])
    assert not partial.exists()
