"""The runner's localization oracle (an ablation): the behaviour gets the true directions of the sounding sources."""
import warnings

import numpy as np

from ssl_sim.runner import RescueRun
from ssl_sim.scenario import load_scenario


def _run(scenario: str = "generator_louder", **ablation) -> RescueRun:
    sc = load_scenario(scenario).with_overrides(time_limit_s=15.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = RescueRun(sc, seed=1, **ablation)
    run.run()
    return run


def _listens(scenario: str = "generator_louder", **ablation) -> list[dict]:
    return _run(scenario, **ablation).listens


def test_oracle_detects_every_sounding_source_at_its_true_direction():
    run = _run(oracle_localization=True)
    assert run.listens
    for rec in run.listens:
        sounding = sorted(s["name"] for s in rec["sources"] if s["active"])
        # one detection per sounding source
        assert sorted(d["source"] for d in rec["detections"]) == sounding
        _assert_at_true_directions(run, rec)


def _assert_at_true_directions(run: RescueRun, rec: dict) -> None:
    """Every detection of listen ``rec`` lies at its source's direction from the robot's recorded pose (plane
    geometry, not the runner's own truth; the pose is rounded to 1 mm and the parked robot creeps by less than a
    millimetre)."""
    where = {s.name: np.asarray(s.position, float) for s in run.sources}
    h = run.robot.config.array_height   # the array's centre, on the robot's vertical axis
    x, y, yaw = rec["pose"]
    for d in rec["detections"]:
        p = where[d["source"]]
        az = np.degrees(np.arctan2(p[1] - y, p[0] - x) - yaw)
        el = np.degrees(np.arctan2(p[2] - h, np.hypot(p[0] - x, p[1] - y)))
        assert abs((d["azimuth_deg"] - az + 180.0) % 360.0 - 180.0) <= 0.1
        assert abs(d["elevation_deg"] - el) <= 0.2


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


def test_exact_directions_move_srp_phat_detections_of_sounding_sources_to_the_truth():
    # the first listen hears the same audio with and without the ablation: the same sources detected, now exactly
    plain = _listens("dense_pump")[0]
    run = _run("dense_pump", snap_detections=True)
    snapped = run.listens[0]
    near = sorted(d["source"] for d in plain["detections"] if d["error_deg"] <= 10.0)
    assert near and sorted(d["source"] for d in snapped["detections"]) == near
    _assert_at_true_directions(run, snapped)


def test_recorded_snr_puts_at_most_one_source_above_the_rest():
    # each source's band energy against all the others' and the ambient field: at most one can exceed the rest
    listens = _listens(record_snr=True)
    assert listens
    for rec in listens:
        snr = [s["snr_db"] for s in rec["sources"]]
        assert all(v is None or np.isfinite(v) for v in snr)
        assert sum(1 for v in snr if v is not None and v > 0.0) <= 1
    assert any(s["snr_db"] is not None and s["snr_db"] > 0.0 for rec in listens for s in rec["sources"])
