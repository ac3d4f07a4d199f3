"""The hearing-misses tool's classifier on hand-made listens: which sounding victim a listen detected, and the
signed direction errors of the detection that found her (no simulation)."""
from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

_SPEC = importlib.util.spec_from_file_location(
    "hearing_misses", Path(__file__).resolve().parents[1] / "tools" / "hearing_misses.py")
hm = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(hm)


def _listen(dets, moving=False, her=(30.0, -5.0), distance=1.5):
    return {"moving": moving,
            "sources": [{"name": "v0", "kind": "victim", "active": True, "azimuth_deg": her[0],
                         "elevation_deg": her[1], "distance_m": distance, "snr_db": 8.0, "line_of_sight": True},
                        {"name": "i0", "kind": "interferer", "active": True, "azimuth_deg": -90.0,
                         "elevation_deg": 0.0, "distance_m": 3.0}],
            "detections": [{"azimuth_deg": a, "elevation_deg": e} for a, e in dets]}


def test_a_detection_near_her_is_a_hit_with_its_signed_errors():
    # two detections within 10 deg of her: the closer one's errors count (detection - truth, deg)
    [row] = hm.classify([_listen([(37.0, -5.0), (32.0, -8.0)], moving=True)])
    assert row["detected"] and row["moving"] and row["miss"] is None
    assert row["az_err_deg"] == pytest.approx(2.0) and row["el_err_deg"] == pytest.approx(-3.0)
    # across the +-180 deg seam the azimuth error is the short way round
    [row] = hm.classify([_listen([(-178.0, 0.0)], her=(179.0, 0.0))])
    assert row["az_err_deg"] == pytest.approx(3.0)


def test_a_miss_names_what_the_strongest_detection_pointed_at():
    [row] = hm.classify([_listen([(-91.0, 1.0)])])
    assert not row["detected"] and row["miss"] == "another sounding interferer" and row["az_err_deg"] is None
    [row] = hm.classify([_listen([(30.0, 40.0)])])
    assert row["miss"] == "her azimuth, not her elevation"


def test_errors_by_distance_average_the_hits_only():
    rows = hm.classify([_listen([(32.0, -7.0)], distance=0.5), _listen([(28.0, -9.0)], distance=0.8),
                        _listen([], distance=0.6), _listen([(30.0, -4.0)], distance=2.5)])
    by = {b["bin"]: b for b in hm.errors(rows)}
    assert by["0 .. 1 m"]["n"] == 2 and by["0 .. 1 m"]["el_mean"] == pytest.approx(-3.0)
    assert by["0 .. 1 m"]["az_mean"] == pytest.approx(0.0) and by["0 .. 1 m"]["abs_az_median"] == pytest.approx(2.0)
    assert by["2 .. 3 m"]["el_median"] == pytest.approx(1.0)
