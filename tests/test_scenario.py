"""Scenario files -> runs: the shipped scenarios are solved, results agree with the truth, bad files
give errors naming the field.

Seeds: paper_lab seed 0 (the default), light_rubble_three seed 0.
"""
from __future__ import annotations

import json
import math
import re
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.io import wavfile

from ssl_sim.acoustics.signals import LoopedSignal
from ssl_sim.cli import main as cli_main
from ssl_sim.runner import RescueRun, run_scenario
from ssl_sim.scenario import ScenarioError, load_scenario, parse_scenario, parse_setting, scenario_names
from ssl_sim.scoring import FreeSpaceGraph
from ssl_sim.world import Box, Room, World


@pytest.fixture(scope="module")
def paper_lab_result():
    return run_scenario("paper_lab", seed=0)


def test_shipped_scenarios_load_and_build():
    assert {"paper_lab", "light_rubble_three", "dense_pump"} <= set(scenario_names())
    lab = load_scenario("paper_lab")
    w = lab.world()
    assert w.name == "empty_lab" and len(w.victims) == 1
    # The paper's geometry: the caller 1.5 m from the robot at -4 degrees.
    dx, dy = np.subtract(w.victims[0].position[:2], w.robot_start[:2])
    assert math.hypot(dx, dy) == pytest.approx(1.5, abs=0.01)
    assert math.degrees(math.atan2(dy, dx)) == pytest.approx(-4.0, abs=0.2)
    three = load_scenario("light_rubble_three")
    assert len(three.world().victims) == 3 and len(three.sources(three.world())) == 3
    dense = load_scenario("dense_pump")
    kinds = [s.kind for s in dense.sources(dense.world())]
    assert kinds == ["victim", "victim", "interferer"]


def test_default_scenario_finds_its_victim(paper_lab_result):
    r = paper_lab_result
    assert r["success"] and r["n_found"] == 1 and r["end_reason"] == "all_found"
    # The behaviour takes the simulated robot's array height: the MuJoCo cube sits 0.27 m above the floor.
    assert r["config"]["mount"] == {"height_m": pytest.approx(0.27)}
    v = r["victims"][0]
    assert v["found"] and v["time_s"] <= r["time_limit_s"]
    # Truth: the robot really is next to the caller, and its own estimate of where she lies is close.
    # (the find's definition: the base within 1.5 m of her, the report within 0.5 m)
    assert v["robot_distance_m"] <= 1.5
    assert v["estimate_error_m"] < 0.3
    # It drove roughly straight at her, less than the 1.5 m between them. She is 1.4997 m from the start, inside
    # the 1.5 m a find may be confirmed from: the shortest path is 0, so any driving scores SPL 0.
    start = np.array([3.0, 3.0])
    assert np.hypot(*(np.array(v["position"][:2]) - start)) < 1.5
    assert 0.2 < v["leg_path_m"] < 2.0 and v["leg_shortest_path_m"] == 0.0 and v["spl"] == 0.0
    assert r["collisions"] == 0 and not r["false_finds"]
    assert [d["kind"] for d in r["declarations"]] == ["find"]
    # Every listen's detections were scored against the true direction; the lab is easy.
    assert r["n_listens"] >= 2
    assert r["angular_error_deg"]["strongest_detection"]["median"] < 5.0
    first = r["listens"][0]
    assert first["sources"][0]["azimuth_deg"] == pytest.approx(-4.0, abs=1.0)  # truth in the array frame
    assert first["detections"][0]["source"] == "caller"


def test_runs_are_deterministic_for_a_seed(paper_lab_result):
    again = run_scenario("paper_lab", seed=0)
    strip = ("wall_clock_s", "provenance")
    a = {k: v for k, v in paper_lab_result.items() if k not in strip}
    b = {k: v for k, v in again.items() if k not in strip}
    assert json.dumps(a, sort_keys=True, default=str) == json.dumps(b, sort_keys=True, default=str)


def test_path_length_matches_the_physics_trajectory():
    sc = load_scenario("paper_lab").with_overrides(time_limit_s=6.0)
    run = RescueRun(sc, seed=2)
    r = run.run()
    traj = np.array(run.trajectory)
    assert np.all(np.diff(traj[:, 0]) >= -1e-9)  # time-ordered samples
    seg = np.hypot(np.diff(traj[:, 1]), np.diff(traj[:, 2])).sum()
    assert r["path_length_m"] == pytest.approx(seg, abs=1e-3)
    # It drove (toward the caller or across her bearing: either way more than a step's worth in 6 s).
    assert seg > 0.3
    assert r["sim_time_s"] >= 6.0 and r["end_reason"] == "time_up"


def test_a_runs_fingerprint_changes_with_the_last_bit_of_what_it_did(paper_lab_result):
    """results.json's fingerprint is the run's: another seed gives another; a trajectory sample moved by one ulp,
    or a decision's payload changed, gives another (so equal fingerprints mean the same run to the bit)."""
    run = RescueRun(load_scenario("paper_lab").with_overrides(time_limit_s=6.0), seed=2)
    r = run.run()
    assert r["fingerprint"] == run.fingerprint() != paper_lab_result["fingerprint"]
    t, x, *rest = run.trajectory[-1]
    run.trajectory[-1] = (t, float(np.nextafter(x, np.inf)), *rest)
    assert run.fingerprint() != r["fingerprint"]
    run.trajectory[-1] = (t, x, *rest)
    assert run.fingerprint() == r["fingerprint"]
    run.events[0] = replace(run.events[0], reason=run.events[0].reason + " ")
    assert run.fingerprint() != r["fingerprint"]


def test_three_callers_in_light_rubble_found_over_four_seeds():
    """Seeds 0-3 of the shipped scenario (240 s): at least 9 of the 12 callers found, at most 7 false finds. Over
    seeds, not one run: a run is chaotic (one different listen changes the path). Measured: 9 of 12 and 7 false
    finds with the robot's relative threshold of 0.5; 9 and 5 with 0.3, which over all the shipped scenes made as
    many false finds per run (0.58) and found fewer victims (docs/design/behaviour.md)."""
    found, false = 0, 0
    for seed in range(4):
        r = run_scenario("light_rubble_three", seed=seed)
        hits = [v for v in r["victims"] if v["found"]]
        found += len(hits)
        false += len(r["false_finds"])
        assert all(v["time_s"] <= r["time_limit_s"] for v in hits)
        assert all(v["robot_distance_m"] <= 1.5 and v["estimate_error_m"] <= 0.5 for v in hits)
        assert all(0 < v["spl"] <= 1 for v in hits)
        assert r["angular_error_deg"]["all_detections"]["median"] < 10.0
        costs = r["wall_clock_s"]
        assert costs["physics"] > 0 and costs["acoustics"] > 0 and costs["localization"] > 0
    # False finds: the fitted found model's measured limit (docs/design/behaviour.md, "What the fit says"):
    # 5-7 in these 4 runs (reports 0.5-1.5 m from a caller); the behaviour tuned on this scene had none.
    assert found >= 9 and false <= 7, (found, false)


def test_grid_geodesic_goes_around_a_wall():
    # A 0.4 m thick wall from y=0 to y=3 in a 6 x 4 m room; the robot (16 cm bumper) must pass its end.
    w = World(room=Room(size=(6.0, 4.0, 3.0)), obstacles=(Box((3.0, 1.5, 0.5), (0.4, 3.0, 1.0)),),
              robot_start=(1.0, 1.0, 0.0))
    p = FreeSpaceGraph(w)
    r = 0.16  # inflation = bumper radius
    c1, c2 = np.array([2.8 - r, 3.0 + r]), np.array([3.2 + r, 3.0 + r])
    exact = np.linalg.norm(c1 - [1, 1]) + np.linalg.norm(c2 - c1) + np.linalg.norm([5, 1] - c2) - 0.1
    d = p.shortest_path((1.0, 1.0), (5.0, 1.0), 0.1)
    assert exact <= d <= 1.03 * exact
    free_room = World(room=Room(size=(6.0, 4.0, 3.0)), robot_start=(1.0, 1.0, 0.0))
    assert FreeSpaceGraph(free_room).shortest_path((1, 1), (5, 3), 0.5) == pytest.approx(math.hypot(4, 2) - 0.5,
                                                                                         rel=0.03)


def test_reachable_floor_near_a_victim_counts_only_floor_the_robot_can_reach():
    """In the open: the whole disc. Boxed in by four walls: none. Against one wall (0.4 m thick, its face
    0.2 m from her): the disc minus the wall and the band the 16 cm bumper keeps off it."""
    room = Room(size=(6.0, 4.0, 3.0))
    open_ = FreeSpaceGraph(World(room=room, robot_start=(1.0, 1.0, 0.0)))
    assert open_.reachable_area((1, 1), (4.0, 2.0), 0.75) == pytest.approx(math.pi * 0.75 ** 2, rel=0.03)
    walls = (Box((4.0, 2.6, 0.5), (1.4, 0.2, 1.0)), Box((4.0, 1.4, 0.5), (1.4, 0.2, 1.0)),
             Box((3.4, 2.0, 0.5), (0.2, 1.4, 1.0)), Box((4.6, 2.0, 0.5), (0.2, 1.4, 1.0)))
    boxed = FreeSpaceGraph(World(room=room, obstacles=walls, robot_start=(1.0, 1.0, 0.0)))
    assert boxed.reachable_area((1, 1), (4.0, 2.0), 0.75) == 0.0          # free inside the box, but unreachable
    wall = FreeSpaceGraph(World(room=room, obstacles=(Box((4.0, 2.4, 0.5), (2.0, 0.4, 1.0)),),
                                robot_start=(1.0, 1.0, 0.0)))
    d = 0.2 - 0.16                          # from her to the line the robot centre may come up to
    segment = 0.75 ** 2 * math.acos(d / 0.75) - d * math.sqrt(0.75 ** 2 - d ** 2)   # the disc beyond that line
    assert wall.reachable_area((1, 1), (4.0, 2.0), 0.75) == pytest.approx(math.pi * 0.75 ** 2 - segment, rel=0.05)


def test_cli_run_writes_results(tmp_path, capsys):
    out = tmp_path / "run"
    assert cli_main(["run", "paper_lab", "--seed", "1", "--time-limit", "4", "--out", str(out), "--quiet"]) == 0
    data = json.loads((out / "results.json").read_text())
    assert data["scenario"] == "paper_lab" and data["seed"] == 1 and data["time_limit_s"] == 4.0
    # the lab's caller lies in the open: the whole 1.5 m disc (where a find is confirmed) is floor the robot can use
    assert data["victims"][0]["reachable_floor_m2"] == pytest.approx(math.pi * 1.5 ** 2, rel=0.03)
    assert data["scoring"]["find_report_radius_m"] == 0.5 and data["provenance"]["commit"]
    assert set(data["provenance"]["machine"]["packages"]) >= {"numpy", "scipy", "mujoco", "pyroomacoustics",
                                                              "onnxruntime"}
    printed = capsys.readouterr().out
    assert "found 0/1" in printed and "m^2 of reachable floor within 1.5 m" in printed


def test_cli_run_set_replaces_a_config_field_and_records_it(tmp_path, capsys):
    """``--set`` changes what the run does (a 0.5 s settle and a 2 s listen: the first listen ends at 2.5 s, not 1.3 s)
    and results.json carries the config the run used; a malformed or invalid setting is refused by name."""
    out = tmp_path / "run"
    assert cli_main(["run", "paper_lab", "--seed", "1", "--time-limit", "4", "--out", str(out), "--quiet",
                     "--set", "behaviour.listen_s=2.0", "--set", "behaviour.settle_s=0.5"]) == 0
    data = json.loads((out / "results.json").read_text())
    assert data["config"]["behaviour"]["listen_s"] == 2.0 and data["config"]["behaviour"]["settle_s"] == 0.5
    assert data["listens"][0]["time_s"] == pytest.approx(0.5 + 2.0, abs=0.02)   # settle, then listen (default 1.3 s)
    capsys.readouterr()
    assert cli_main(["run", "paper_lab", "--out", str(tmp_path / "bad"), "--set", "behaviour.p_find=1.5"]) == 2
    assert "behaviour.p_find: expected a probability in (0, 1), got 1.5" in capsys.readouterr().err
    assert cli_main(["run", "paper_lab", "--out", str(tmp_path / "bad"), "--set", "p_find=0.5"]) == 2
    assert "--set: setting 'p_find=0.5': expected SECTION.FIELD=VALUE" in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()


# ---------------------------------------------------------------------------- bad files
def _write(tmp_path: Path, text: str, name: str = "s.toml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


GOOD = """
name = "t"
time_limit_s = 30.0
[scene]
name = "light_rubble"
[[victims]]
position = [3.9, 2.2, 0.1]
"""


def test_a_minimal_file_loads(tmp_path):
    sc = load_scenario(_write(tmp_path, GOOD))
    assert sc.name == "t" and sc.time_limit_s == 30.0 and len(sc.world().victims) == 1


@pytest.mark.parametrize("text, field", [
    ("colour = 'red'\n" + GOOD, "unknown key(s) ['colour'] at the top level"),
    (GOOD + "[robot]\nspeed = 3\n", "robot: unknown key(s) ['speed']"),
    (GOOD.replace("position = [3.9, 2.2, 0.1]", "position = [3.9, 2.2, 0.1]\nvolume = 3"),
     "victims[0]: unknown key(s) ['volume']"),
    (GOOD + "[behaviour]\nlisten_secs = 1.0\n", "behaviour: unknown key(s) ['listen_secs']"),
    (GOOD + "[localizer]\nn_sources = 'three'\n", "localizer.n_sources: expected an integer"),
    (GOOD + "[behaviour]\nlisten_s = -1.0\n", "behaviour.listen_s"),
    (GOOD.replace("time_limit_s = 30.0", "time_limit_s = 'long'"), "time_limit_s: expected a number"),
    (GOOD.replace("[3.9, 2.2, 0.1]", "[3.9, 2.2]"), "victims[0].position: expected a list of 3 numbers"),
    # (3.0, 2.87) is the pillar of light_rubble
    (GOOD.replace("[3.9, 2.2, 0.1]", "[2.9967, 2.8673, 0.5]"), "victims[0].position: [2.9967, 2.8673, 0.5] is inside "
                                                              "obstacle 0 (pillar"),
    (GOOD.replace("[3.9, 2.2, 0.1]", "[9.0, 2.2, 0.1]"), "victims[0].position: [9.0, 2.2, 0.1] is outside the room"),
    (GOOD.replace("[3.9, 2.2, 0.1]", "[3.9, 2.2, 0.1]\nsound = 'file'\nfile = 'nope.wav'"),
     "victims[0].file: voice file not found"),
    (GOOD.replace("[3.9, 2.2, 0.1]", "[3.9, 2.2, 0.1]\nspeaker = 'robot'"), "victims[0].speaker: expected one of"),
    (GOOD.replace('name = "light_rubble"', 'name = "moon_base"'), "scene.name: unknown scene 'moon_base'"),
    (GOOD.replace('name = "light_rubble"', 'generate = "light_rubble"\nname = "light_rubble"'),
     "scene: expected exactly one of"),
    (GOOD + "[[interferers]]\nkind = 'jackhammer'\nposition = [1, 1, 0.3]\n", "interferers[0].kind: expected one of"),
    (GOOD + "[robot]\nstart = [2.9967, 2.8673, 0.0]\n", "robot.start: (2.9967, 2.8673) overlaps obstacle 0"),
    ("name = 't'\n[[victims]]\nposition = [1, 1, 0.1]\n", "scene: missing [scene] table"),
    (GOOD + "[acoustics]\nism_order = 40\n", "acoustics.ism_order"),
])
def test_bad_files_name_the_field(tmp_path, text, field):
    with pytest.raises(ScenarioError) as exc:
        load_scenario(_write(tmp_path, text))
    msg = str(exc.value)
    assert msg.startswith("s.toml: ") and field in msg, msg


def test_settings_replace_config_fields_as_the_file_would(tmp_path):
    """A setting is the same as the field written in the file: validated by the loader, named when wrong."""
    path = _write(tmp_path, GOOD + "[behaviour]\nlisten_s = 1.5\n")
    sc = load_scenario(path, dict([parse_setting("behaviour.listen_s=2.0"),
                                   parse_setting("localizer.band_hz = [300, 4000]"),
                                   parse_setting("planner.keep_factor=1.25")]))
    in_file = load_scenario(_write(tmp_path, GOOD + "[behaviour]\nlisten_s = 2.0\n[localizer]\nband_hz = [300, 4000]\n"
                                              "[planner]\nkeep_factor = 1.25\n", name="in_file.toml"))
    assert sc.behaviour == in_file.behaviour and sc.localizer == in_file.localizer and sc.planner == in_file.planner
    assert sc.behaviour.listen_s == 2.0 and sc.localizer.band_hz == (300.0, 4000.0)
    assert load_scenario(path).behaviour.listen_s == 1.5   # the file itself is not changed
    for setting, field in (("behaviour.listen_secs=1", "behaviour: unknown key(s) ['listen_secs']"),
                           ("behaviour.listen_s=-1", "behaviour.listen_s"),
                           ("localizer.n_sources='three'", "localizer.n_sources: expected an integer")):
        with pytest.raises(ScenarioError, match=re.escape(field)):
            load_scenario(path, dict([parse_setting(setting)]))
    for text, expected in (("scene.name='x'", "section 'scene' cannot be set"),
                           ("listen_s=2", "expected SECTION.FIELD=VALUE"),
                           ("behaviour.listen_s=two", "expected a TOML value")):
        with pytest.raises(ValueError, match=re.escape(expected)):
            parse_setting(text)


def test_unreachable_victim_is_rejected(tmp_path):
    # Enclose a victim in four walls 1.6 m from her: in air, but the robot cannot come within the 1.5 m a find
    # is confirmed from (outside, its centre stays 1.6 + 0.05 + 0.16 m away).
    walls = "".join(f"""
[[obstacles]]
center = {c}
size = {s}
kind = "wall"
""" for c, s in (([3.0, 1.9, 0.5], [3.3, 0.1, 1.0]), ([3.0, 5.1, 0.5], [3.3, 0.1, 1.0]),
                   ([1.4, 3.5, 0.5], [0.1, 3.3, 1.0]), ([4.6, 3.5, 0.5], [0.1, 3.3, 1.0])))
    _write(tmp_path, f'name = "boxed"\nrobot_start = [6.5, 3.5, 0.0]\n[room]\nsize = [8.0, 7.0, 2.5]\n{walls}',
           "boxed_scene.toml")
    text = '[scene]\nfile = "boxed_scene.toml"\n[[victims]]\nposition = [3.0, 3.5, 0.1]\n'
    with pytest.raises(ScenarioError, match=r"victims\[0\].position: .* cannot be reached"):
        load_scenario(_write(tmp_path, text))
    # 1.2 m from her the walls leave floor within 1.5 m outside them: that victim can be confirmed, and loads
    near = text.replace("[3.0, 3.5, 0.1]", "[3.0, 2.3, 0.1]")
    assert load_scenario(_write(tmp_path, near, "near.toml")).victims[0].position[1] == 2.3


def test_voice_file_and_generated_scene(tmp_path):
    fs = 8000
    t = np.arange(fs) / fs
    wavfile.write(tmp_path / "call.wav", fs, (0.3 * np.sin(2 * np.pi * 300 * t) * 32767).astype(np.int16))
    text = """
name = "gen"
[scene]
generate = "light_rubble"
[[victims]]
scene_victim = 0
sound = "file"
file = "call.wav"
level_db_spl = 70.0
"""
    sc = load_scenario(_write(tmp_path, text))
    w3, w4 = sc.world(3), sc.world(4)
    assert w3.victims != w4.victims  # the run seed draws the generated scene
    src = sc.sources(w3, fs=16000)
    assert isinstance(src[0].signal, LoopedSignal) and src[0].level_db_spl == 70.0
    x = src[0].signal.render(0, 16000)  # resampled to 16 kHz: still a 300 Hz tone, unit RMS
    f = np.fft.rfftfreq(x.size, 1 / 16000)[np.argmax(np.abs(np.fft.rfft(x)))]
    assert f == pytest.approx(300.0, abs=2.0) and np.sqrt(np.mean(x**2)) == pytest.approx(1.0, rel=0.05)


def test_parse_errors_without_a_file():
    with pytest.raises(ScenarioError, match="victims: no victims"):
        parse_scenario({"scene": {"name": "empty_lab", "use_scene_victims": False}})
    with pytest.raises(ScenarioError, match=r"seed: expected an integer >= 0"):
        load_scenario("paper_lab").with_overrides(seed=-1)


def test_driving_into_a_wall_is_one_collision_at_the_wall(tmp_path):
    text = """
name = "wall"
[scene]
name = "empty_lab"             # 7 x 6 m
[robot]
start = [6.4, 3.0, 0.0]        # 0.6 m from the x = 7 m wall, facing it
[[victims]]
position = [1.0, 1.0, 0.1]
[acoustics]
rt60_s = 0.3
max_rir_s = 0.4
"""
    run = RescueRun(load_scenario(_write(tmp_path, text)))
    run.drive.set_twist(0.25, 0.0, 0.0)
    for _ in range(80):  # 4 s: reaches the wall after ~1.8 s, then keeps pushing
        run.clock.sleep(0.05)
    run.drive.stop()
    assert len(run.collisions) == 1
    c = run.collisions[0]
    assert c["obstacle"] is None and c["position"][0] == pytest.approx(7.0, abs=0.02)
    # The bumper (radius 0.16 m) touches first: the robot centre stops ~0.16 m short of the wall.
    assert run.trajectory[-1][1] == pytest.approx(7.0 - 0.16, abs=0.03)
    assert 1.0 < c["time_s"] < 3.0


def test_retired_config_fields_load_with_a_warning_or_say_where_they_went():
    base = ('name = "old"\ntime_limit_s = 30\n[scene]\nname = "empty_lab"\n[robot]\nstart = [3.0, 3.0, 0.0]\n'
            '[[victims]]\nposition = [4.0, 3.0, 0.1]\nsound = "continuous"\n')
    with pytest.warns(FutureWarning, match=r"behaviour.min_step_m: no longer a field"):
        old = parse_scenario(tomllib.loads(base + "[behaviour]\nmin_step_m = 0.1\nstep_m = 0.5\n"))
    assert old.behaviour.step_m == 0.5 and not hasattr(old.behaviour, "min_step_m")
    with pytest.warns(FutureWarning, match=r"motion.turn_tolerance_deg: no longer a field"):
        parse_scenario(tomllib.loads(base + "[motion]\nturn_tolerance_deg = 6.0\n"))
    for section in ("behaviour", "sound_map"):
        with pytest.raises(ScenarioError, match=rf"{section}.array_height_m: no longer a field.*ArrayMount.height_m"):
            parse_scenario(tomllib.loads(base + f"[{section}]\narray_height_m = 0.3\n"))
