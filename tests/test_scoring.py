"""The one scoring definition: finds are reports (within 0.5 m, base within 1.5 m), SPL on one free-space graph
without corner cutting, the same number from the runner, the sweep and the gym env's evaluation.

Scripted worlds: an empty 7 x 6 m lab, the robot parked at its start (3, 3), declarations injected at chosen
reported positions; distances checked against plane geometry.
"""
from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from robot.events import Decision, FindCriterion, FoundPayload, RescueEvent, RescueState
from ssl_sim.envs.evaluation import episode_spl
from ssl_sim.runner import RescueRun
from ssl_sim.scenario import ScenarioError, parse_scenario
from ssl_sim.scoring import FreeSpaceGraph, Judge, leg_spls, run_spl, victim_spl
from ssl_sim.sweep import row_from_result
from ssl_sim.world import Box, Room, World

START = np.array([3.0, 3.0])


def _scenario(victims: list[tuple[float, float]], time_limit_s: float = 60.0):
    text = (f'name = "scripted"\ntime_limit_s = {time_limit_s}\n[scene]\nname = "empty_lab"\n'
            '[robot]\nstart = [3.0, 3.0, 0.0]\n')
    for k, (x, y) in enumerate(victims):
        text += f'[[victims]]\nposition = [{x}, {y}, 0.1]\nsound = "continuous"\nname = "v{k}"\n'
    return parse_scenario(tomllib.loads(text))


def _declare(run: RescueRun, t: float, xy) -> None:
    found = FoundPayload((float(xy[0]), float(xy[1])), 0.1, 0, "scripted", FindCriterion.STEEP_BEARING, 0.1, 0.9)
    run._handle_events([RescueEvent(t, RescueState.LISTEN, Decision.VICTIM_FOUND, "scripted", found)])


@pytest.fixture(scope="module")
def near_run_factory():
    sc = _scenario([(4.2, 3.0)])    # 1.2 m ahead of the parked robot
    return lambda: RescueRun(sc)


def test_a_report_045_m_off_is_a_find_and_055_m_off_a_false_find(near_run_factory):
    victim = np.array([4.2, 3.0])
    run = near_run_factory()
    off = np.array([0.0, 0.45])                       # 0.45 m beside her, the robot 1.2 m away
    _declare(run, 1.0, victim + off)
    r = run._results("scripted", 0.0)
    assert r["n_found"] == 1 and r["success"] and not r["false_finds"]
    assert r["victims"][0]["estimate_error_m"] == pytest.approx(0.45, abs=1e-3)
    assert r["victims"][0]["robot_distance_m"] == pytest.approx(1.2, abs=0.02)
    assert not r["victims"][0]["reached"]             # the former criterion (0.75 m) would not have credited her
    run = near_run_factory()
    _declare(run, 1.0, victim + [0.0, 0.55])
    r = run._results("scripted", 0.0)
    assert r["n_found"] == 0 and len(r["false_finds"]) == 1
    assert r["false_finds"][0]["estimate_error_m"] == pytest.approx(0.55, abs=1e-3)


def test_a_robot_16_m_away_does_not_find_even_with_an_exact_report():
    run = RescueRun(_scenario([(4.6, 3.0)]))          # 1.6 m from the parked robot
    _declare(run, 1.0, (4.6, 3.0))
    r = run._results("scripted", 0.0)
    assert r["n_found"] == 0 and not r["false_finds"]  # right report, robot too far to confirm: neither
    assert [d["kind"] for d in r["declarations"]] == ["too_far"]
    assert r["declarations"][0]["robot_distance_m"] == pytest.approx(1.6, abs=0.02)


def test_judge_rules_duplicates_late_reports_and_the_nearest_victim():
    j = Judge([(0.0, 0.0), (0.8, 0.0)], time_limit_s=10.0)
    # report between two victims, both within 0.5 m: the nearer one to the report is credited
    assert j.declare(1.0, (0.5, 0.0), (0.0, 1.0)).victim == 1
    # the same victim again: > 0.5 m from every *unfound* victim -> false find
    dup = j.declare(2.0, (0.8, 0.1), (0.8, 1.0))
    assert dup.kind == "false_find"
    # after the time limit a right report is "late", not a find; a wrong one is still a false find
    assert j.declare(11.0, (0.0, 0.1), (0.0, 0.5)).kind == "late"
    assert j.declare(12.0, (3.0, 3.0), (0.0, 0.5)).kind == "false_find"
    assert sorted(j.found) == [1] and len(j.false_finds) == 2
    # reached: base within 0.75 m of a victim at an in-time declaration: the bases were 1.0 m or more away
    assert j.reached == {}


def test_no_corner_cutting_on_a_hand_computed_grid():
    """1 m cells; cell (1, 1) blocked. From (0, 0) to (2, 1): the knight move crosses (1, 0) and (1, 1), the
    diagonal from (1, 0) crosses the corner of (1, 1): both refused, so the path is three axis moves (3 m);
    a graph that cut the corner would give sqrt(5) = 2.236 m."""
    free = np.ones((4, 3), bool)
    free[1, 1] = False
    g = FreeSpaceGraph.from_grid(free, 1.0)
    assert g.shortest_path((0.5, 0.5), (2.5, 1.5), 0.0) == pytest.approx(3.0)
    # with the cell free, the knight move is allowed: sqrt(5)
    assert FreeSpaceGraph.from_grid(np.ones((4, 3), bool), 1.0).shortest_path((0.5, 0.5), (2.5, 1.5), 0.0) == \
        pytest.approx(math.sqrt(5))
    # a pinch between two blocked cells that only touch at a corner is not a passage
    pinch = np.array([[True, False], [False, True]])
    assert math.isinf(FreeSpaceGraph.from_grid(pinch, 1.0).shortest_path((0.5, 0.5), (1.5, 1.5), 0.0))
    # one side blocked: around it, 2 m instead of the 1.41 m diagonal
    side = np.ones((2, 2), bool)
    side[1, 0] = False
    assert FreeSpaceGraph.from_grid(side, 1.0).shortest_path((0.5, 0.5), (1.5, 1.5), 0.0) == pytest.approx(2.0)


def test_two_boxes_meeting_at_a_corner_are_a_wall_for_the_robot():
    """Two 1 m boxes touching corner to corner across the middle of a 4 x 2 m room, rest of the room closed off
    by walls: the only way from left to right would squeeze diagonally through their touching corners."""
    room = Room(size=(4.0, 2.0, 2.0))
    boxes = (Box((1.5, 0.5, 0.5), (1.0, 1.0, 1.0)), Box((2.5, 1.5, 0.5), (1.0, 1.0, 1.0)))
    w = World(room=room, obstacles=boxes, robot_start=(0.5, 1.5, 0.0))
    g = FreeSpaceGraph(w, inflate=0.0)
    assert math.isinf(g.shortest_path((0.5, 1.5), (3.5, 0.5), 0.1))


def test_spl_agrees_between_runner_sweep_and_env_evaluation():
    """One world, one driven path, two finds: results.json, the sweep's row and the env's episode SPL agree to
    1e-9, and match plane geometry (empty room: shortest = straight line - 1.5 m, within the grid's 3 %)."""
    victims = [(6.0, 3.0), (6.0, 5.5)]
    run = RescueRun(_scenario(victims))
    # a scripted drive: out to (4.4, 4.2), then to (5.2, 3.2) (declares v0, 0.8 m from her), then up to
    # (5.5, 4.6) (declares v1, 0.98 m from her)
    pts = np.array([[3.0, 3.0], [4.4, 4.2], [5.2, 3.2], [5.5, 4.6]])
    times = [0.0, 10.0, 20.0, 30.0]
    run.trajectory = [(t, x, y, 0.0, 0.0) for t, (x, y) in zip(times, pts)]
    seg = np.hypot(*np.diff(pts, axis=0).T)
    run.cum_path = list(np.concatenate([[0.0], np.cumsum(seg)]))
    _declare(run, 20.0, (6.1, 3.1))
    _declare(run, 30.0, (5.9, 5.3))
    r = run._results("scripted", 0.0)
    assert r["n_found"] == 2
    row = row_from_result(r)
    finds = [(0, tuple(pts[2]), seg[:2].sum(), 20.0), (1, tuple(pts[3]), seg.sum(), 30.0)]
    env_spl = episode_spl(FreeSpaceGraph(run.world), run.world, finds)
    assert r["spl"] == pytest.approx(row["spl"], abs=1e-9) and r["spl"] == pytest.approx(env_spl, abs=1e-9)
    # plane geometry: leg 1 from the start, leg 2 from where v0 was declared
    l1 = math.hypot(*(np.array(victims[0]) - START)) - 1.5
    l2 = max(0.0, math.hypot(*(np.array(victims[1]) - pts[2])) - 1.5)
    want = (l1 / max(seg[:2].sum(), l1) + l2 / max(seg[2], l2)) / 2
    assert r["spl"] == pytest.approx(want, rel=0.03)
    assert [v["leg_shortest_path_m"] for v in r["victims"]] == pytest.approx([l1, l2], rel=0.03, abs=0.02)


def test_spl_building_blocks():
    assert victim_spl(2.0, 4.0) == 0.5 and victim_spl(2.0, 1.0) == 1.0     # a path shorter than l: capped at 1
    assert victim_spl(0.0, 0.0) == 1.0 and victim_spl(0.0, 1.0) == 0.0     # nothing to drive / drove anyway
    assert victim_spl(math.inf, 3.0) == 0.0
    g = FreeSpaceGraph(World(room=Room(size=(6.0, 4.0, 3.0)), robot_start=(1.0, 1.0, 0.0)))
    legs = leg_spls(g, [(5.0, 1.0)], (1.0, 1.0), [(0, (4.0, 1.0), 5.0)])
    assert legs[0].shortest_m == pytest.approx(2.5, rel=0.03) and legs[0].spl == pytest.approx(0.5, rel=0.03)
    assert run_spl(2, legs) == pytest.approx(legs[0].spl / 2)     # the unfound victim counts 0


def test_success_radius_is_no_longer_a_scenario_setting():
    base = '[scene]\nname = "empty_lab"\n[[victims]]\nposition = [5.5, 3.0, 0.1]\n'
    # older files load
    assert parse_scenario(tomllib.loads('name = "a"\nsuccess_radius_m = 0.75\n' + base)).name == "a"
    with pytest.raises(ScenarioError, match="success_radius_m: no longer a scenario setting"):
        parse_scenario(tomllib.loads('name = "a"\nsuccess_radius_m = 1.0\n' + base))
