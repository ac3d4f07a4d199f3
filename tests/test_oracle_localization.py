"""The runner's localization oracle (an ablation): the behaviour gets the true directions of the sounding sources."""
import warnings

import numpy as np

from ssl_sim.runner import RescueRun
from ssl_sim.scenario import load_scenario


def _listens(scenario: str = "generator_louder", **ablation) -> list[dict]:
    sc = load_scenario(scenario).with_overrides(time_limit_s=15.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = RescueRun(sc, seed=1, **ablation)
    run.run()
    return run.listens


def test_oracle_detects_every_sounding_source_at_its_true_direction():
    listens = _listens(oracle_localization=True)
    assert listens
    for rec in listens:
        sounding = sorted(s["name"] for s in rec["sources"] if s["active"])
        # one detection per sounding source, each at that source (the runner matches detections to the truth by
        # the geometry of the array's pose at the window's middle, independently of the oracle)
        assert sorted(d["source"] for d in rec["detections"]) == sounding
        assert all(d["error_deg"] <= 0.01 for d in rec["detections"])


def test_without_the_oracle_the_same_listens_are_srp_phat_detections():
    errs = [d["error_deg"] for rec in _listens() for d in rec["detections"]]
    # the real localizer: errors of a few degrees, never exactly zero
    assert errs and min(errs) > 0.01 and np.median(errs) < 15.0


def test_dropping_false_detections_keeps_srp_phat_directions_near_a_sounding_source_only():
    # beside the pump some detections point at none of the sounding sources (reflections, the pump's lobes)
    errs = [d["error_deg"] for rec in _listens("dense_pump") for d in rec["detections"]]
    assert max(errs) > 10.0
    kept = [d["error_deg"] for rec in _listens("dense_pump", drop_false_detections=True) for d in rec["detections"]]
    assert kept and max(kept) <= 10.0 and min(kept) > 0.01


def test_voice_oracle_hears_speech_in_the_victims_beams_only():
    import math

    from robot.events import Decision
    sc = load_scenario("generator_louder").with_overrides(time_limit_s=12.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = RescueRun(sc, seed=1, oracle_localization=True, oracle_voice=True)
    run.run()
    truth = {rec["time_s"]: rec["sources"] for rec in run.listens}
    checked = 0
    for e in run.behaviour.events:
        if e.decision is not Decision.HEARD:
            continue
        for c in e.data.candidates:
            # the sounding source the candidate points at (array-frame azimuth), from the runner's own truth
            src = min((s for s in truth[round(e.time, 3)] if s["active"]),
                      key=lambda s: abs(math.remainder(c.azimuth - math.radians(s["azimuth_deg"]), 2 * math.pi)))
            assert c.voice == (1.0 if src["kind"] == "victim" else 0.0)
            checked += 1
    assert checked >= 4
