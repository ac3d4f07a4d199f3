"""Statistics of runs: bootstrap intervals cover what they should, the paired comparison tells a planted
difference from chance, kernel divergence counts differing outcomes, and a sweep's summary carries intervals,
provenance and a plot. Every random sample is seeded."""
from __future__ import annotations

import math

import numpy as np
import pytest

from ssl_sim import stats
from ssl_sim.sweep import interval_table, write_tables


def _row(scenario, seed, spl, success=True, n_found=1, n_victims=1, false_finds=0, times=(10.0,), errs=(0.1,),
         blas="", family=None):
    return {"scenario": scenario, "seed": seed, "spl": spl, "success": success, "n_found": n_found,
            "n_victims": n_victims, "false_finds": false_finds, "find_times_s": list(times),
            "position_errors_m": list(errs), "blas": blas, "family": family,
            "found_victims": ["v"] * n_found}


def test_bootstrap_interval_of_a_bernoulli_sample_covers_its_mean():
    rng = np.random.default_rng(7)
    p, n = 0.3, 400
    x = (rng.random(n) < p).astype(float)
    iv = stats.bootstrap_mean(x, seed=1)
    assert iv.n == n and iv.mean == pytest.approx(x.mean())
    assert iv.lo < x.mean() < iv.hi and iv.lo < p < iv.hi
    # width as the normal approximation of a binomial proportion gives it: 2 x 1.96 sqrt(p (1-p) / n)
    assert iv.hi - iv.lo == pytest.approx(2 * 1.96 * math.sqrt(x.mean() * (1 - x.mean()) / n), rel=0.15)
    # the same rows and seed give the same interval; nan and None are left out
    assert stats.bootstrap_mean(list(x) + [math.nan, None], seed=1) == iv
    assert stats.bootstrap_mean([]).n == 0


def test_paired_comparison_flags_a_planted_difference_and_not_a_null_one():
    rng = np.random.default_rng(3)
    base = rng.uniform(0.1, 0.9, 48)         # per-scenario SPL varies a lot between scenarios ...
    old = [_row("s", k, v) for k, v in enumerate(base)]
    planted = [_row("s", k, v + 0.04 + rng.normal(0, 0.03)) for k, v in enumerate(base)]   # ... +0.04 each
    null = [_row("s", k, v + rng.normal(0, 0.03)) for k, v in enumerate(base)]
    up = {c["metric"]: c for c in stats.paired_comparison(planted, old)}["spl"]
    assert up["pairs"] == 48 and up["outside_chance"] and up["difference_lo"] > 0
    assert up["difference"] == pytest.approx(0.04, abs=0.015)
    same = {c["metric"]: c for c in stats.paired_comparison(null, old)}["spl"]
    assert not same["outside_chance"] and same["difference_lo"] < 0 < same["difference_hi"]
    # unpaired, the planted gain hides in the spread between scenarios: the two intervals overlap
    a, b = stats.bootstrap_mean([r["spl"] for r in planted]), stats.bootstrap_mean(base)
    assert a.lo < b.hi


def test_kernel_repeats_are_one_unit_and_divergence_counts_changed_outcomes():
    rows = []
    for k in range(4):
        rows.append(_row("s", k, 0.5, blas="Haswell"))
        # the kernels agree on seeds 0-2; on seed 3 the other kernel misses the victim
        other = _row("s", k, 0.5, blas="Sandybridge") if k < 3 else \
            _row("s", k, 0.0, success=False, n_found=0, times=(), errs=(), blas="Sandybridge")
        rows.append(other)
    div = stats.kernel_divergence(rows)
    assert div == [{"kernels": "Haswell vs Sandybridge", "runs": 4, "outcome_differs": 0.25, "spl_differs": 0.25}]
    units = stats.units(rows)
    assert len(units) == 4 and units[("s", 3)]["spl"] == pytest.approx(0.25)   # averaged over the kernels


def test_summary_per_family_with_intervals_and_the_sweep_files(tmp_path):
    rows = [_row("a", k, 0.2 * (k % 3), success=k % 2 == 0, family="rubble") for k in range(6)] + \
           [_row("b", k, 0.9, family="open") for k in range(4)]
    for r in rows:
        r.update({"victim_times": {"v": r["find_times_s"][0] if r["find_times_s"] else None},
                  "victim_spl": {"v": r["spl"]}, "n_reached": r["n_found"], "end_reason": "all_found",
                  "sim_time_s": 20.0, "path_length_m": 2.0, "collisions": 0, "n_listens": 3,
                  "detection_errors_deg": [1.0], "wall_per_sim_s": 0.1})
    s = {r["family"]: r for r in stats.summarize(rows)}
    assert set(s) == {"rubble", "open", "all"} and s["rubble"]["scenarios"] == 6 and s["all"]["scenarios"] == 10
    assert s["rubble"]["success"] == pytest.approx(0.5) and s["rubble"]["success_lo"] < 0.5 < s["rubble"]["success_hi"]
    assert s["open"]["spl"] == s["open"]["spl_lo"] == s["open"]["spl_hi"] == pytest.approx(0.9)
    assert "0.500 [" in interval_table(list(s.values()))
    from ssl_sim.sweep import summarize
    paths = write_tables(rows, summarize(rows), tmp_path)
    assert paths["plot"].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import json
    summary = json.loads(paths["json"].read_text())
    assert summary["provenance"]["machine"]["packages"]["numpy"] == np.__version__
    assert "rubble" in paths["families"].read_text()
