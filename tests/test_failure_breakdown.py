"""The failure breakdown's classifier on hand-made results: each link of the rescue chain broken by a constructed
run whose geometry decides the stage (no simulation)."""
from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import pytest

_SPEC = importlib.util.spec_from_file_location(
    "failure_breakdown", Path(__file__).resolve().parents[1] / "tools" / "failure_breakdown.py")
fb = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(fb)

VICTIM = (4.0, 2.0)      # the one victim, 0.2 m above the floor
MACHINE = (1.0, 4.0)
START = (1.0, 1.0)


def _listen(t, pose, victim_err_deg=None, calling=True):
    """A listen at ``pose`` (x, y): the victim calling (or not) and at most one detection matched to her."""
    d = math.hypot(VICTIM[0] - pose[0], VICTIM[1] - pose[1])
    dets = [] if victim_err_deg is None else [
        {"source": "v0", "source_kind": "victim", "error_deg": victim_err_deg, "azimuth_error_deg": victim_err_deg}]
    return {"time_s": t, "pose": [pose[0], pose[1], 0.0], "level_db": -60.0,
            "sources": [{"name": "v0", "kind": "victim", "distance_m": d, "active": calling},
                        {"name": "i0", "kind": "interferer", "distance_m": 3.0, "active": True}],
            "detections": dets}


def _event(t, decision, **data):
    return {"time_s": t, "state": "listen", "decision": decision, "reason": "", "data": data}


def _run(level_db=65.0, err=None, map_xy=None, cls="victim", target=False, bases=(START,), declare=None,
         found=False, name="train_000_light_rubble"):
    """A one-victim run reaching as far as the arguments say (``declare``: reported xy and base xy)."""
    listens = [_listen(1.3 * (k + 1), b, err) for k, b in enumerate(bases)]
    events, maps = [], []
    for rec in listens:
        events.append(_event(rec["time_s"], "heard"))
        if map_xy is not None:
            maps.append({"time_s": rec["time_s"], "sources": [{"id": 1, "x": map_xy[0], "y": map_xy[1], "z": 0.2,
                                                               "sigma_m": 0.3, "p_victim": 0.9, "cls": cls,
                                                               "state": "unvisited", "n_listens": 3}]})
        if target:
            events.append(_event(rec["time_s"], "target", source=1, position=list(map_xy)))
            events.append(_event(rec["time_s"], "drive"))
    decl = []
    if declare is not None:
        rep, base = declare
        err_m, base_m = math.dist(rep, VICTIM), math.dist(base, VICTIM)
        kind = "find" if found else ("too_far" if err_m <= 0.5 else "false_find")
        events.append(_event(listens[-1]["time_s"] + 0.1, "victim_found", source=1, position=list(rep)))
        decl.append({"time_s": listens[-1]["time_s"] + 0.1, "kind": kind, "estimate": list(rep),
                     "robot_position": list(base), "victim": "v0", "estimate_error_m": err_m,
                     "robot_distance_m": base_m, "criterion": "test"})
    return {"scenario": name, "n_victims": 1, "n_found": int(found), "end_reason": "time_up", "sim_time_s": 60.0,
            "config": {"noise": {"level_db_spl": 40.0}, "behaviour": {"listen_s": 1.0, "settle_s": 0.3}},
            "victims": [{"name": "v0", "position": [*VICTIM, 0.2], "level_db_spl": level_db, "buried": 0.0,
                         "found": found}],
            "sources_truth": [{"name": "v0", "kind": "victim", "position": [*VICTIM, 0.2], "level_db_spl": level_db,
                               "buried": 0.0},
                              {"name": "i0", "kind": "interferer", "position": [*MACHINE, 0.5], "level_db_spl": 70.0,
                               "buried": 0.0}],
            "room_size": [6.0, 5.0], "listens": listens, "declarations": decl, "event_log": events,
            "map_log": maps}


NEAR = (3.5, 2.0)    # a base position 0.5 m from her
CASES = {
    # 3.16 m away at 45 dB SPL at 1 m: 45 - 20 log10(3.16) = 35 dB < 40 dB of noise (a detection near her
    # direction then is chance, not hearing)
    "silent": dict(level_db=45.0, err=1.0, map_xy=VICTIM),
    "undetected": dict(err=25.0),
    "unmapped": dict(err=3.0, map_xy=(2.5, 2.0)),            # the map's source 1.5 m off her
    "not_targeted": dict(err=3.0, map_xy=(4.3, 2.0)),
    "not_approached": dict(err=3.0, map_xy=(4.3, 2.0), target=True, bases=(START, (2.0, 2.0))),
    "not_declared": dict(err=3.0, map_xy=(4.3, 2.0), target=True, bases=(START, NEAR)),
    "declared_off": dict(err=3.0, map_xy=(4.3, 2.0), target=True, bases=(START, NEAR),
                         declare=((4.9, 2.0), NEAR)),        # report 0.9 m off
    "found": dict(err=3.0, map_xy=(4.3, 2.0), target=True, bases=(START, NEAR), declare=((4.3, 2.0), NEAR),
                  found=True),
}


@pytest.mark.parametrize("stage", fb.STAGES)
def test_each_stage_is_reached_by_its_constructed_run(stage):
    got = fb.classify_run(_run(**CASES[stage]))
    assert got["victims"][0]["stage"] == stage


def test_direct_level_is_spherical_spreading_and_covering_loss():
    assert fb.direct_snr_db(65.0, 0.0, 2.0, 40.0) == pytest.approx(25.0 - 20 * math.log10(2.0))
    assert fb.direct_snr_db(65.0, 0.4, 1.0, 40.0) == pytest.approx(25.0 - 6.0)


def test_causes_within_stages():
    v = fb.classify_run(_run(**CASES["not_targeted"], cls="interferer"))["victims"][0]
    assert v["not_targeted_cause"] == "classified interferer"
    v = fb.classify_run(_run(**{**CASES["not_declared"], "map_xy": (4.8, 2.0)}))["victims"][0]
    assert v["stage"] == "not_declared" and v["not_declared_cause"] == "map estimate never within 0.5 m"
    v = fb.classify_run(_run(**{**CASES["declared_off"], "declare": ((4.2, 2.0), (1.0, 2.0))}))["victims"][0]
    assert v["stage"] == "declared_off" and v["declared_off_cause"] == "base too far"


@pytest.mark.parametrize("report, t, cause", [((4.1, 2.1), 20.0, "re-declared found victim"),
                                               ((1.2, 3.8), 20.0, "machine"),
                                               ((7.5, 2.0), 20.0, "mirror outside the room"),
                                               ((2.0, 0.5), 20.0, "ghost inside the room")])
def test_false_find_causes(report, t, cause):
    run = _run(**CASES["found"])
    run["declarations"].append({"time_s": t, "kind": "false_find", "estimate": list(report),
                                "robot_position": list(NEAR), "victim": "v0",
                                "estimate_error_m": math.dist(report, VICTIM), "robot_distance_m": 0.5})
    assert [f["cause"] for f in fb.false_find_causes(run)] == [cause]


def test_time_split_follows_the_decisions():
    ev = [_event(1.3, "heard"), _event(1.3, "target", source=1, position=[4.0, 2.0]), _event(1.3, "drive"),
          _event(5.0, "heard"), _event(5.0, "explore"), _event(8.0, "heard"), _event(8.0, "recover")]
    run = {"sim_time_s": 10.0, "config": {"behaviour": {"listen_s": 1.0, "settle_s": 0.3}}, "event_log": ev}
    got = fb.time_split(run)
    assert got == {"listening": pytest.approx(3.9), "driving": pytest.approx(2.4), "exploring": pytest.approx(1.7),
                   "recovering": pytest.approx(2.0), "other": 0.0}
    assert sum(got.values()) == pytest.approx(10.0)


def test_share_interval_resamples_runs():
    iv = fb.share_interval([1, 1, 1], [2, 2, 2])
    assert (iv.mean, iv.lo, iv.hi) == (0.5, 0.5, 0.5)
    iv = fb.share_interval([0, 2], [2, 2])
    assert iv.mean == 0.5 and iv.lo == 0.0 and iv.hi == 1.0


def test_test_split_runs_are_refused():
    with pytest.raises(ValueError, match="test-split"):
        fb.classify_run(_run(name="test_003_voids"))


def test_undetected_cause_compares_direct_levels_with_the_interferer():
    # machine 70 dB at 1 m heard from 3 m: 60.5 dB; she (65 dB at 1 m) from 3.16 m: 55 dB, below it
    v = fb.classify_run(_run(**CASES["undetected"]))["victims"][0]
    assert v["best_direct_sir_db"] == pytest.approx(65 - 20 * math.log10(math.dist(START, VICTIM))
                                                    - (70 - 20 * math.log10(3.0)), abs=0.05)
    assert v["undetected_cause"] == "below an interferer at every listen"
    v = fb.classify_run(_run(**{**CASES["undetected"], "level_db": 80.0}))["victims"][0]
    assert v["undetected_cause"] == "above every interferer at some listen"


def test_typed_event_payloads_are_logged_as_their_fields():
    """The tool's own runs log each event's typed payload as a dict the classifier reads by key, not its repr."""
    from robot.events import HeardCandidate, HeardPayload, TargetPayload
    t = fb._jsonable(TargetPayload(3, [1.0, 2.0, 0.3], 0.2, 0.9, 0.1, -0.2, 1.5, [[1.0, 1.0]]))
    assert t["source"] == 3 and t["position"] == [1.0, 2.0, 0.3] and t["waypoints"] == [[1.0, 1.0]]
    h = fb._jsonable(HeardPayload(1, [HeardCandidate(2, 0.5, -0.1, -50.0, 0.3, False, "victim", "unvisited")], [],
                                  [0.0, 0.0, 0.0]))
    assert h["candidates"][0]["source"] == 2 and h["candidates"][0]["class"] == "victim"
