"""A sweep of 2 scenarios x 3 seeds gives the same table on local processes and on a Dask LocalCluster.

Kept short: 14 s of simulated time per run (paper_lab is usually solved by then, so the table mixes
successes and failures) and a tiny generated-scene scenario whose layout changes with the seed.
"""
from __future__ import annotations

import csv

import pytest

from ssl_sim.scenario import load_scenario
from ssl_sim.sweep import (DETERMINISTIC_RUN_COLUMNS, markdown_table, parse_seeds, run_sweep, summarize,
                           write_tables)

SEEDS = [0, 1, 2]
TIME_LIMIT = 14.0

TINY = """
name = "tiny_generated"
description = "generated light rubble, the scene's own victim, short"
[scene]
generate = "light_rubble"      # scene seed = run seed: a different layout per seed
[[victims]]
scene_victim = 0
sound = "continuous"
level_db_spl = 68.0
[acoustics]
rt60_s = 0.4
max_rir_s = 0.5
"""


@pytest.fixture(scope="module")
def scenarios(tmp_path_factory):
    p = tmp_path_factory.mktemp("sweep") / "tiny.toml"
    p.write_text(TINY)
    return [load_scenario("paper_lab"), load_scenario(p)]


@pytest.fixture(scope="module")
def local_rows(scenarios):
    return run_sweep(scenarios, SEEDS, workers=2, time_limit_s=TIME_LIMIT)


def _det(rows):
    return [{k: r[k] for k in DETERMINISTIC_RUN_COLUMNS} for r in rows]


def test_local_sweep_table(local_rows, tmp_path):
    rows = local_rows
    assert [(r["scenario"], r["seed"]) for r in rows] == [(s, k) for s in ("paper_lab", "tiny_generated")
                                                          for k in SEEDS]
    for r in rows:  # every run either used its time or found everyone before
        assert (r["end_reason"] == "time_up" and r["sim_time_s"] >= TIME_LIMIT) or \
            (r["end_reason"] == "all_found" and r["success"] and r["sim_time_s"] <= TIME_LIMIT + 5)
    tiny = [r for r in rows if r["scenario"] == "tiny_generated"]
    assert len({r["path_length_m"] for r in tiny}) > 1  # different seeds, different scenes and runs
    lab = [r for r in rows if r["scenario"] == "paper_lab"]
    assert sum(r["success"] for r in lab) >= 2  # the lab caller is usually found within 14 s
    tables = summarize(rows)
    s = {t["scenario"]: t for t in tables["scenarios"]}
    assert s["paper_lab"]["runs"] == 3
    assert s["paper_lab"]["success_rate"] == pytest.approx(sum(r["success"] for r in lab) / 3)
    found_t = [r["victim_times"]["caller"] for r in lab if r["victim_times"]["caller"] is not None]
    v = [t for t in tables["victims"] if t["scenario"] == "paper_lab"][0]
    assert v["mean_time_to_find_s"] == pytest.approx(sum(found_t) / len(found_t), abs=1e-3)
    spl = [r["spl"] for r in lab]
    assert s["paper_lab"]["mean_spl"] == pytest.approx(sum(spl) / 3, abs=1e-3)
    assert all(0 <= x <= 1 for x in spl)
    paths = write_tables(rows, tables, tmp_path)
    with paths["runs"].open() as f:
        runs = list(csv.DictReader(f))
    assert len(runs) == 6 and "t_caller_s" in runs[0]
    md = paths["markdown"].read_text()
    assert "| paper_lab |" in md and "success_rate" in md
    assert markdown_table([]) == "(no rows)\n"


def test_dask_local_cluster_gives_the_same_table(local_rows, scenarios):
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cl, \
            distributed.Client(cl) as client:
        dask_rows = run_sweep(scenarios, SEEDS, executor=client, time_limit_s=TIME_LIMIT)
    assert _det(dask_rows) == _det(local_rows)
    a, b = summarize(local_rows), summarize(dask_rows)
    drop = ("wall_per_sim_s",)
    assert [{k: v for k, v in t.items() if k not in drop} for t in a["scenarios"]] == \
           [{k: v for k, v in t.items() if k not in drop} for t in b["scenarios"]]
    assert a["victims"] == b["victims"]


def test_seed_parsing():
    assert parse_seeds("0:5") == [0, 1, 2, 3, 4]
    assert parse_seeds("0:10:5") == [0, 5]
    assert parse_seeds("3,1") == [3, 1]
    assert parse_seeds("7") == [7]
    for bad in ("a:b", "5:0", "-1", "1:2:3:4"):
        with pytest.raises(ValueError, match="--seeds"):
            parse_seeds(bad)
