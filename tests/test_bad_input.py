"""Bad input to ``ssl-rescue`` and ``ssl-robot`` gives one line naming the field or option, exit code 2, and
before anything runs."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from robot.cli import main as robot_main
from robot.config_values import coerce, field_values
from robot.rescue import RescueConfig
from ssl_sim import cli as rescue_cli
from ssl_sim.physics.robot_model import RobotModelConfig
from ssl_sim.physics.scenes import load_scene
from ssl_sim.scenario import ScenarioError, _footprint_distance, load_scenario

GOOD = """
name = "t"
time_limit_s = 30.0
[scene]
name = "light_rubble"
[robot]
start = [1.0, 1.0, 0.0]
[[victims]]
position = [3.9, 2.2, 0.1]
"""


def _rescue(argv, capsys) -> tuple[int, str]:
    code = rescue_cli.main(argv)
    return code, capsys.readouterr().err.strip()


def _scenario(tmp_path: Path, text: str) -> Path:
    p = tmp_path / "s.toml"
    p.write_text(text)
    return p


def _nan_wav(tmp_path: Path) -> Path:
    x = np.sin(np.arange(16000) / 7.0).astype(np.float32)
    x[100] = np.nan
    p = tmp_path / "nan.wav"
    wavfile.write(p, 16000, x)
    return p


@pytest.mark.parametrize("edit, field", [
    (lambda t, d: t + "[localizer]\nfs = 8000\n", "localizer.fs: 8000 Hz, but the simulated audio is 16000 Hz"),
    (lambda t, d: t + "[localizer]\nband_hz = [6000.0, 300.0]\n", "localizer.band_hz: band_hz must satisfy"),
    (lambda t, d: t + "[localizer]\nband_hz = [300.0, 9000.0]\n", "localizer.band_hz"),
    (lambda t, d: t.replace("[3.9, 2.2, 0.1]", f"[3.9, 2.2, 0.1]\nsound = 'file'\nfile = '{_nan_wav(d)}'"),
     "victims[0].file: "),
    (lambda t, d: t + "[behaviour]\nfatal_faults = ['none']\n", "behaviour.fatal_faults"),
])
def test_scenario_values_that_failed_at_run_time_are_named_at_load_time(tmp_path, capsys, edit, field):
    path = _scenario(tmp_path, edit(GOOD, tmp_path))
    with pytest.raises(ScenarioError, match="^s.toml: ") as exc:
        load_scenario(path)
    assert field in str(exc.value)
    code, err = _rescue(["run", str(path), "-q", "--out", str(tmp_path / "o")], capsys)
    assert code == 2 and len(err.splitlines()) == 1 and field in err
    if "file" in field:
        assert "NaN" in err


def test_directory_and_unreadable_scenarios(tmp_path, capsys):
    code, err = _rescue(["run", str(tmp_path), "-q"], capsys)
    assert code == 2 and len(err.splitlines()) == 1 and "is a directory" in err and str(tmp_path) in err
    binary = tmp_path / "b.toml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    code, err = _rescue(["run", str(binary), "-q"], capsys)
    assert code == 2 and len(err.splitlines()) == 1 and "b.toml" in err


def test_a_start_on_drivable_debris_is_refused_naming_the_field(tmp_path):
    world = load_scene("light_rubble")
    k, debris = next((k, b) for k, b in enumerate(world.obstacles) if b.climbable)
    x, y = debris.center[0], debris.center[1]
    with pytest.raises(ScenarioError, match=rf"robot.start: .* on climbable debris \(obstacle {k}, debris"):
        load_scenario(_scenario(tmp_path, GOOD.replace("[1.0, 1.0, 0.0]", f"[{x}, {y}, 0.0]")))
    # Footprint geometry against hand-made truth: a 0.2 x 0.1 m box turned 90 degrees about z.
    box = type(debris)(center=(1.0, 2.0, 0.005), size=(0.2, 0.1, 0.01), yaw=np.pi / 2)
    assert _footprint_distance(box, 1.0, 2.0) == 0.0
    assert _footprint_distance(box, 1.0 + 0.05 + 0.3, 2.0) == pytest.approx(0.3)  # across: half width 0.05
    assert _footprint_distance(box, 1.0, 2.0 + 0.1 + 0.3) == pytest.approx(0.3)   # along: half length 0.1
    # Just clear of that debris (robot radius + 2 cm from its footprint) and of everything else: accepted.
    r = RobotModelConfig().bumper_radius
    reach = np.hypot(*debris.size[:2]) / 2 + r + 0.02
    clear = [(debris.center[0] + reach * np.cos(a), debris.center[1] + reach * np.sin(a))
             for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)]
    clear = [p for p in clear if world.inside_obstacle([*p, 0.05], margin=r) is None
             and all(_footprint_distance(b, *p) > r for b in world.obstacles if b.climbable)]
    assert clear
    load_scenario(_scenario(tmp_path, GOOD.replace("[1.0, 1.0, 0.0]", f"[{clear[0][0]:.4f}, {clear[0][1]:.4f}, 0.0]")))


def test_the_refused_starts_are_those_the_physics_moves():
    """Independent truth for the rule: 1 s of physics without a command. A start with a wheel on debris moves
    the robot; a start the rule accepts leaves it where it was put."""
    from dataclasses import replace

    from ssl_sim.physics import SimRobot

    world = load_scene("light_rubble")
    debris = world.obstacles[15]  # 1.5 cm debris in the open
    assert debris.climbable
    r = RobotModelConfig().bumper_radius

    def drift(x: float, y: float) -> float:
        robot = SimRobot(replace(world, robot_start=(x, y, 0.0)))
        robot.step(1.0)
        p = robot.pose()
        return float(np.hypot(p.x - x, p.y - y))

    on = (debris.center[0] + 0.1, debris.center[1])
    off = (debris.center[0] + 0.45, debris.center[1])
    assert _footprint_distance(debris, *on) < r < _footprint_distance(debris, *off)
    assert drift(*on) > 0.02 and drift(*off) < 0.005


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    p = tmp_path_factory.mktemp("rec") / "r.wav"
    wavfile.write(p, 16000, np.zeros((16000, 8), np.int16))
    return p


@pytest.mark.parametrize("args, option", [
    (["--max-time", "nan"], "--max-time"),
    (["--max-time", "-5"], "--max-time"),
    (["--sources", "-3"], "--sources"),
    (["--sources", "0"], "--sources"),
    (["--rel-threshold", "2"], "--rel-threshold"),
    (["--set", "fatal_faults=none"], "fatal_faults"),
    (["--set", "listen_s=abc"], "--set listen_s: expected a number"),
    (["--set", "listen_s=nan"], "--set listen_s: expected a finite number"),
    (["--set", "listen_s=-1"], "listen_s"),
    (["--set", "max_victims=2.5"], "--set max_victims: expected an integer"),
    (["--set", "colour=red"], "--set: unknown key(s) ['colour']"),
    (["--set", "listen_s"], "--set 'listen_s': expected FIELD=VALUE"),
])
def test_ssl_robot_bad_options_are_one_line_naming_the_option(recording, capsys, args, option):
    out = io.StringIO()
    code = robot_main(["--dry-run", "--replay", str(recording), *args], out=out)
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and err.startswith("ssl-robot: error: ") and option in err, err
    assert "rescue on" not in out.getvalue()  # refused before the mission started


def test_ssl_robot_retired_field_is_ignored_with_a_warning_naming_it(recording):
    # A field no decision reads any more (RescueConfig.RETIRED): old command lines still run, told what is ignored.
    out = io.StringIO()
    with pytest.warns(FutureWarning, match=r"--set require_voice: no longer a field .*ignored"):
        code = robot_main(["--dry-run", "--replay", str(recording), "--max-time", "2", "--set", "require_voice=maybe"],
                          out=out)
    assert code == 0 and "rescue on" in out.getvalue()


def test_one_coercion_for_text_and_toml():
    hints = {"listen_s": float, "max_victims": int | None, "fatal_faults": tuple[str, ...],
             "band_hz": tuple[float, float] | None}
    # command-line text
    assert coerce("2.5", hints["listen_s"], "x", text=True) == 2.5
    assert coerce("none", hints["max_victims"], "x", text=True) is None
    assert coerce("3", hints["max_victims"], "x", text=True) == 3
    assert coerce("", hints["fatal_faults"], "x", text=True) == ()
    assert coerce("stall, encoder_error", hints["fatal_faults"], "x", text=True) == ("stall", "encoder_error")
    assert coerce("300,4000", hints["band_hz"], "x", text=True) == (300.0, 4000.0)
    # typed (TOML) values: no text parsing, no null
    assert coerce([300, 4000], hints["band_hz"], "x") == (300.0, 4000.0)
    with pytest.raises(ValueError, match="x: expected a number, got '2.5'"):
        coerce("2.5", float, "x")
    with pytest.raises(ValueError, match="x: expected a list of 2 values"):
        coerce([1.0], hints["band_hz"], "x")
    # and with an empty list for "no fatal faults", the config accepts it
    assert RescueConfig(**field_values(RescueConfig, {"fatal_faults": ""}, "--set", text=True)).fatal_faults == ()
