"""``ssl-robot``: replay end to end (real ssl_core localizer, dry-run drive) and clear errors."""
import io
import json
import math
import sys

import numpy as np
import pytest
from scipy.io import wavfile

from robot.cli import main
from ssl_core.geometry import cube8

FS = 16000


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """3 s, 8 channels: a harmonic 'voice' 2 m away at azimuth +60 deg, 0.2 m below the array, exact delays."""
    n = 3 * FS
    rng = np.random.default_rng(4)
    t = np.arange(n) / FS
    f0 = 140 * (1 + 0.05 * np.sin(2 * np.pi * 0.5 * t))
    phase = 2 * np.pi * np.cumsum(f0) / FS
    s = sum(np.sin(k * phase) / k for k in range(1, 25)) * (0.3 + np.clip(np.sin(2 * np.pi * 3 * t), 0, None))
    src = np.array([2 * math.cos(math.radians(60)), 2 * math.sin(math.radians(60)), -0.2])
    r = np.linalg.norm(cube8().positions - src, axis=1)
    f = np.fft.rfftfreq(n, 1 / FS)
    x = np.fft.irfft(np.fft.rfft(s)[None] * np.exp(-2j * np.pi * f[None] * (r / 343.0)[:, None]), n) / r[:, None]
    x += 0.005 * rng.standard_normal(x.shape)
    p = tmp_path_factory.mktemp("rec") / "rec.wav"
    wavfile.write(p, FS, (0.2 * x.T / np.abs(x).max() * 32767).astype(np.int16))
    return p


def run(args):
    out = io.StringIO()
    code = main(args, out=out)
    return code, out.getvalue()


def test_replay_dry_run_prints_decisions(recording):
    code, text = run(["--dry-run", "--replay", str(recording), "--max-time", "8"])
    assert code == 0
    assert "dry run (no motors)" in text
    heard = next(line for line in text.splitlines() if " heard " in line)
    az = float(heard.split("az ")[1].split(" deg")[0])
    assert az == pytest.approx(60, abs=5)
    assert " drive " in text       # the first move: a step across the bearing heard (triangulate) or toward it


def test_replay_json_lines_until_the_recording_ends(recording):
    code, text = run(["--dry-run", "--replay", str(recording), "--json", "--max-time", "1000", "--set", "listen_s=1.0"])
    assert code == 0
    events = [json.loads(line) for line in text.splitlines() if line.startswith("{")]
    assert {"time", "state", "decision", "reason", "data"} <= set(events[0])
    assert events[-1]["decision"] == "audio_ended"  # 3 s of audio = 3 listens of 1 s
    assert sum(e["decision"] == "heard" for e in events) == 3


def test_missing_serial_port_is_a_clear_error(recording, capsys):
    code, _ = run(["--serial", "/dev/ttyNOPE_ssl_robot", "--audio", "1,2"])
    assert code == 2
    err = capsys.readouterr().err
    assert "/dev/ttyNOPE_ssl_robot" in err and "cannot be opened" in err


def test_missing_audio_backend_is_a_clear_error(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "sounddevice", None)  # as on a machine without the hardware extra
    code, _ = run(["--dry-run", "--audio", "1,2"])
    assert code == 2
    assert "pip install 'ssl-rescue[hardware]'" in capsys.readouterr().err
    code, _ = run(["--list-audio"])
    assert code == 2


def test_set_reaches_the_behaviours_other_configs(recording, monkeypatch):
    """``--set SECTION.FIELD=VALUE``: the odometry's loaded-wheel threshold (to be measured on the robot's
    open-loop drive) and a planner field reach the behaviour that runs the mission."""
    import robot.rescue as rescue  # ssl-robot imports the behaviour from there once its arguments are parsed
    made = []

    class Recorded(rescue.RescueBehaviour):
        def __init__(self, *a, **kw):
            super().__init__(*a, **kw)
            made.append(self)

    monkeypatch.setattr(rescue, "RescueBehaviour", Recorded)
    code, _ = run(["--dry-run", "--replay", str(recording), "--max-time", "2", "--set", "travel.loaded_speed=5.0",
                   "--set", "planner.frontier_reach_m=0.8", "--set", "listen_s=0.5",
                   "--set", "coverage.area=-1,-3,6,3", "--set", "mount.height_m=0.25"])
    assert code == 0 and len(made) == 1
    b = made[0]
    assert b.odometry.travel.loaded_speed == 5.0 and b.planner.config.frontier_reach_m == 0.8
    assert b.coverage.config.area == (-1.0, -3.0, 6.0, 3.0) and b.coverage.in_area[b.grid.cell((5.9, 2.9))]
    assert not b.coverage.in_area[b.grid.cell((6.1, 0.0))]
    assert b.config.listen_s == 0.5
    # the array's height reaches both the behaviour and its sound map (one value for both)
    assert b.mount.height_m == 0.25 and b.map.mount.height_m == 0.25


def test_bad_arguments_are_named(recording, tmp_path, capsys):
    assert run(["--replay", str(recording)])[0] == 2
    assert "--serial PORT" in capsys.readouterr().err
    assert run(["--dry-run"])[0] == 2
    assert "--audio" in capsys.readouterr().err
    assert run(["--serial", "loop://", "--replay", str(recording)])[0] == 2
    assert "--dry-run" in capsys.readouterr().err
    assert run(["--dry-run", "--replay", str(recording), "--set", "bogus=1"])[0] == 2
    assert "bogus" in capsys.readouterr().err
    assert run(["--dry-run", "--replay", str(recording), "--set", "listen_s=fast"])[0] == 2
    assert "listen_s" in capsys.readouterr().err
    assert run(["--dry-run", "--replay", str(recording), "--set", "wheels.loaded_speed=5"])[0] == 2
    assert "unknown section 'wheels'" in capsys.readouterr().err
    assert run(["--dry-run", "--replay", str(recording), "--set", "travel.loaded_speed=-1"])[0] == 2
    assert "loaded_speed" in capsys.readouterr().err
    assert run(["--dry-run", "--replay", str(recording), "--set", "coverage.area=3,0,1,2"])[0] == 2
    assert "--set coverage.area=" in capsys.readouterr().err
    assert run(["--dry-run", "--replay", str(recording), "--set", "array_height_m=0.3"])[0] == 2
    assert "array_height_m: no longer a field" in (err := capsys.readouterr().err) and "mount.height_m" in err
    assert run(["--dry-run", "--replay", str(recording), "--set", "mount.height_m=0"])[0] == 2
    assert "mount.height_m" in capsys.readouterr().err
    four = tmp_path / "four.wav"
    wavfile.write(four, FS, np.zeros((100, 4), np.int16))
    assert run(["--dry-run", "--replay", str(four)])[0] == 2
    assert "has 4 channel(s), expected 8" in capsys.readouterr().err
    assert run(["--dry-run", "--replay", str(tmp_path / "none.wav")])[0] == 2
    assert "not found" in capsys.readouterr().err


def test_live_audio_path_with_a_fake_sounddevice(monkeypatch):
    """--audio end to end: two fake 4-channel devices with a 523-sample offset, calibrated at start."""
    import robot.hardware.audio as hw
    from test_audio_capture import _devices, _FakeSD, _plane_wave, _unit

    truth = 0.05 * _plane_wave(_unit(-150, 10), 12 * FS, seed=2)
    sd = _FakeSD(_devices(truth, 523), pace=0.25)  # audio arrives 4x faster than real time
    monkeypatch.setattr(hw, "import_sounddevice", lambda: sd)
    code, text = run(["--dry-run", "--audio", "1,2", "--calibrate", "1.0", "--max-time", "1.5",
                      "--set", "listen_s=0.5", "--set", "settle_s=0", "--set", "step_m=0.05"])
    assert code == 0, text
    assert "device offset: offset 523 samples" in text and "- applied" in text
    heard = next(line for line in text.splitlines() if " heard " in line)
    assert float(heard.split("az ")[1].split(" deg")[0]) == pytest.approx(-150, abs=5)
    assert sd.opened == []  # streams closed at exit


def test_a_failed_stop_is_reported_not_hidden(recording, monkeypatch, capsys):
    """Issue 14: "(robot stopped)" only when the stop worked; otherwise say that it failed."""
    from robot import cli
    from robot.replay import DryRunDrive

    class DeadDrive(DryRunDrive):
        def set_twist(self, vx, vy, omega):
            raise RuntimeError("drive link lost")

        def stop(self):
            raise RuntimeError("drive link lost")

    monkeypatch.setattr(cli, "_open_drive", lambda args, clock: DeadDrive(clock))
    code, text = run(["--dry-run", "--replay", str(recording), "--max-time", "8"])
    err = capsys.readouterr().err
    assert code == 1
    assert "stopping the robot FAILED: RuntimeError: drive link lost" in err and "robot stopped" not in err


def _resampled(recording, tmp_path, rate):
    from scipy.signal import resample_poly
    fs, x = wavfile.read(recording)
    g = math.gcd(rate, fs)
    y = resample_poly(x.astype(float), rate // g, fs // g, axis=0)
    p = tmp_path / f"rec_{rate}.wav"
    wavfile.write(p, rate, np.clip(np.round(y), -32768, 32767).astype(np.int16))
    return p


def test_a_48khz_replay_is_resampled_and_an_8khz_one_refused_at_start(recording, tmp_path, capsys):
    """ssl-locate analyses a 48 kHz recording; the behaviour hears at 16 kHz: the replay is resampled as it is
    read, from the start of the mission on, and the talker is heard where the 16 kHz file puts it. Below 12 kHz the
    localizer's band (to 6 kHz) is missing: refused before the mission starts, naming the rate."""
    code, text = run(["--dry-run", "--replay", str(_resampled(recording, tmp_path, 48000)), "--max-time", "8"])
    assert code == 0, text
    heard = next(line for line in text.splitlines() if " heard " in line)
    assert float(heard.split("az ")[1].split(" deg")[0]) == pytest.approx(60, abs=5)
    code, text = run(["--dry-run", "--replay", str(_resampled(recording, tmp_path, 8000)), "--max-time", "8"])
    err = capsys.readouterr().err
    assert code == 2 and "rescue on" not in text
    assert "sample rate 8000 Hz is too low" in err and "12000 Hz" in err


def test_json_lines_alone_on_stdout(recording, capsys):
    """--json: stdout holds JSON lines only; the banner and the end of the mission go to stderr."""
    code, text = run(["--dry-run", "--replay", str(recording), "--json", "--max-time", "4"])
    assert code == 0
    lines = text.splitlines()
    assert lines and all(json.loads(line)["decision"] for line in lines)
    err = capsys.readouterr().err
    assert "ssl-robot: rescue on" in err


def test_a_recorded_mission_replays_to_the_same_decisions(recording, tmp_path):
    """--record DIR on a replayed mission (ideal dry-run drive); --replay DIR then feeds the behaviour the same
    audio, drive readings and times: the same decisions, the same sources heard in the same directions. The
    audio written is the audio the behaviour read (the recording's first seconds, sample for sample)."""
    mission = tmp_path / "mission"
    code, first = run(["--dry-run", "--replay", str(recording), "--json", "--max-time", "20", "--record", str(mission)])
    assert code == 0
    code, again = run(["--dry-run", "--replay", str(mission), "--json", "--max-time", "20"])
    assert code == 0
    a, b = [json.loads(x) for x in first.splitlines()], [json.loads(x) for x in again.splitlines()]
    assert sum(e["decision"] == "heard" for e in a) >= 2
    assert a == b
    meta = json.loads((mission / "mission.json").read_text())
    assert meta["sample_rate"] == FS and meta["n_channels"] == 8 and meta["sample_format"] == "int16"
    fs, original = wavfile.read(recording)
    fs2, written = wavfile.read(mission / "audio.wav")
    assert fs2 == fs and written.shape[1] == 8 and 0 < len(written) <= len(original)
    assert np.array_equal(written, original[:len(written)])   # listens read the file from its start, in order
    # a second mission cannot overwrite the first
    code, _ = run(["--dry-run", "--replay", str(recording), "--max-time", "2", "--record", str(mission)])
    assert code == 2


def test_a_replay_with_other_options_stops_at_the_first_difference(recording, tmp_path, capsys):
    mission = tmp_path / "mission"
    assert run(["--dry-run", "--replay", str(recording), "--max-time", "10", "--record", str(mission)])[0] == 0
    code, _ = run(["--dry-run", "--replay", str(mission), "--max-time", "10", "--set", "listen_s=0.5"])
    err = capsys.readouterr().err
    assert code == 1 and "MissionDiverged" in err and "the behaviour read 8000 samples" in err


def test_ego_noise_template_reaches_the_localizer_and_a_bad_one_is_named(recording, tmp_path, monkeypatch, capsys):
    from ssl_core.ego_noise import EgoNoiseTemplate
    from ssl_core.localizer import Localizer

    freqs = np.linspace(0, FS / 2, 257)
    good = tmp_path / "ego.npz"
    EgoNoiseTemplate(FS, freqs, np.array([1.0, 2.0]), np.ones((2, 257)), np.array([-60.0, -55.0]), 8).save(good)
    built = []
    real_init = Localizer.__init__

    def spy(self, *a, **kw):
        real_init(self, *a, **kw)
        built.append(self.ego_noise)

    monkeypatch.setattr(Localizer, "__init__", spy)
    code, _ = run(["--dry-run", "--replay", str(recording), "--max-time", "2", "--ego-noise", str(good)])
    assert code == 0
    sup = built[-1]
    assert sup is not None and sup.template.fs == FS
    # the motors sit below the array by the mount's height less their axle height (robot.ego_calibration)
    assert np.allclose([m[2] for m in sup.config.motor_positions], 0.05 - 0.30)
    assert run(["--dry-run", "--replay", str(recording), "--ego-noise", str(tmp_path / "none.npz")])[0] == 2
    assert "--ego-noise" in capsys.readouterr().err
    slow = tmp_path / "ego8k.npz"
    EgoNoiseTemplate(8000, freqs / 2, np.array([1.0, 2.0]), np.ones((2, 257)), np.array([-60.0, -55.0]), 8).save(slow)
    assert run(["--dry-run", "--replay", str(recording), "--ego-noise", str(slow)])[0] == 2
    assert "recorded at 8000 Hz" in capsys.readouterr().err
    four = tmp_path / "ego4.npz"
    EgoNoiseTemplate(FS, freqs, np.array([1.0, 2.0]), np.ones((2, 257)), np.array([-60.0, -55.0]), 4).save(four)
    assert run(["--dry-run", "--replay", str(recording), "--ego-noise", str(four)])[0] == 2
    assert "4 microphones" in capsys.readouterr().err
