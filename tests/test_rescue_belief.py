"""The rescue behaviour on its belief in scripted worlds (the fake HAL of ``test_rescue``: ideal drive, detections
from the true pose), checked against the world's truth with the scoring's find: the report within
``FIND_RADIUS_M`` of a caller, the robot's base within ``BASE_RADIUS_M`` of her.

Behavioural tests: whether and where the robot declares depends on the fitted found model
(robot/models/found_model.json) and on the options' values, not on a rule; they must hold for the fitted weights."""
import math

import pytest

from robot.coverage import CoverageConfig
from robot.found import BASE_RADIUS_M, FIND_RADIUS_M
from robot.rescue import Decision, RescueConfig
from test_rescue import Source, World, always_speech, found_events, make


def _first_declaration(b, w, steps):
    """Step ``b`` up to ``steps`` cycles; (the first VICTIM_FOUND event, the robot's true (x, y) then) or None."""
    for _ in range(steps):
        found = found_events(b.step())
        if found:
            return found[0], w.pose()[:2]
        if b.done:
            break
    return None


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_caller_is_found_and_reported_where_she_is(seed):
    caller = Source((3.0, -1.0, 0.12), 64.0)        # 3.2 m away, calling with pauses (the stand-in VAD)
    w = World([caller], seed=seed)
    b = make(w, RescueConfig(max_victims=1))
    got = _first_declaration(b, w, 60)
    assert got is not None, [e.reason for e in b.events if e.decision is not Decision.HEARD][-8:]
    ev, xy = got
    assert math.dist(ev.data.position, caller.position[:2]) <= FIND_RADIUS_M
    assert math.dist(xy, caller.position[:2]) <= BASE_RADIUS_M
    assert b.done and b.events[-1].decision is Decision.ALL_FOUND
    assert w.drive.commands[-1].twist == (0.0, 0.0, 0.0)


def test_a_found_caller_is_never_declared_again():
    # She keeps calling after the find; the robot runs on (no max_victims) in a 4 x 4 m room (the search area) and
    # hears her from many places, near and far.
    caller = Source((2.0, 1.0, 0.1), 64.0)
    w = World([caller], seed=3)
    b = make(w, speech=always_speech, coverage=CoverageConfig(area=(-1.0, -1.5, 3.0, 2.5)))
    ev = b.run(max_time=90.0)
    found = found_events(ev)
    assert found and math.dist(found[0].data.position, caller.position[:2]) <= FIND_RADIUS_M
    first = found[0].data.position
    assert not [e for e in found[1:] if math.dist(e.data.position, first) <= 1.0], [str(e) for e in found]
    assert len(b.victims) == len(found)
    # she was heard after the find and ignored as found, not judged again
    after = ev[ev.index(found[0]) + 1:]
    again = [e for e in after if e.decision in (Decision.HEARD, Decision.NO_SOURCE)
             and any(f"is found source #{found[0].data.source}" in s for s in e.data.ignored)]
    assert len(again) >= 5


@pytest.mark.parametrize("where, seed", [((1.5, 0.5, 0.3), 0), ((2.5, -1.0, 0.25), 1), ((0.8, 0.0, 0.2), 2)])
def test_a_voiceless_machine_is_never_declared_found(where, seed):
    # Loud, low (a pump on the floor: heard steeply when near), never a speech frame; 90 s of listening.
    w = World([Source(where, 75.0, voice=False)], seed=seed)
    b = make(w, speech=always_speech)
    ev = b.run(max_time=90.0)
    assert not found_events(ev) and not b.victims, [e.reason for e in found_events(ev)]
    assert ev[-1].decision is Decision.TIME_UP
