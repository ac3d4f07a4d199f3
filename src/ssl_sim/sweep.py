"""Many scenario runs (scenarios x seeds) in parallel, locally or on a Dask cluster, one table out.

    rows = run_sweep(["paper_lab", "light_rubble_three"], range(10))                  # local processes
    rows = run_sweep([...], range(100), cluster="tcp://scheduler:8786")               # Dask distributed
    tables = summarize(rows); write_tables(rows, tables, "out/sweep")                 # CSV, markdown, PNG

One code path for both engines: anything with ``submit(fn, *args) -> future`` and
``future.result()`` (``concurrent.futures.ProcessPoolExecutor`` or ``distributed.Client``, whose
API mirrors it). Each task's World is built here on the client and shipped with the scenario, so
workers need the installed package but no scene or voice files. Every run is deterministic for its
seed; rows come back in (scenario, seed) order whatever order the workers finish in.

Scores come from the runner, i.e. ``ssl_sim.scoring`` (finds are reports, SPL on the one free-space graph);
the tables give every metric per scene family with its 95 % bootstrap interval over scenarios
(``ssl_sim.stats``), and the summary names the commit, package versions, BLAS kernel and CPU
(``ssl_sim.provenance``).
"""
from __future__ import annotations

import concurrent.futures as cf
import csv
import json
import math
import multiprocessing
import time
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from ssl_sim import stats
from ssl_sim.provenance import provenance
from ssl_sim.runner import RescueRun
from ssl_sim.scenario import Scenario, ScenarioError, load_scenario
from ssl_sim.world import World

__all__ = ["parse_seeds", "run_one", "row_from_result", "run_sweep", "summarize", "write_tables", "markdown_table",
           "interval_table", "DETERMINISTIC_RUN_COLUMNS"]

#: Run-table columns that depend only on (scenario, seed): equal across machines and engines.
DETERMINISTIC_RUN_COLUMNS = ("scenario", "seed", "success", "n_found", "n_victims", "n_reached", "end_reason",
                             "sim_time_s", "path_length_m", "collisions", "false_finds", "spl", "n_listens",
                             "ang_err_median_deg", "ang_err_mean_deg", "ang_err_p90_deg", "victim_times")


def parse_seeds(text: str) -> list[int]:
    """``"0:100"`` (start:stop, stop exclusive) | ``"0:100:10"`` | ``"1,5,9"`` | ``"7"`` -> seeds."""
    try:
        if ":" in text:
            parts = [int(p) for p in text.split(":")]
            if len(parts) not in (2, 3):
                raise ValueError
            seeds = list(range(*parts))
        else:
            seeds = [int(p) for p in text.split(",") if p.strip()]
    except ValueError:
        raise ValueError(f"--seeds: expected START:STOP[:STEP], a comma list or one integer, got {text!r}") from None
    if not seeds or min(seeds) < 0:
        raise ValueError(f"--seeds: expected at least one seed, all >= 0, got {text!r}")
    return seeds


def row_from_result(r: dict[str, Any], family: str | None = None) -> dict[str, Any]:
    """A runner result (results.json) -> a flat summary row (the full per-listen record stays out of the table).
    ``family``: the scene family the row is summarized under (default: the scenario name)."""
    ang = r["angular_error_deg"]["all_detections"]
    found = [v for v in r["victims"] if v["found"]]
    return {
        "scenario": r["scenario"], "family": family or r["scenario"], "seed": r["seed"], "success": r["success"],
        "n_found": r["n_found"], "n_victims": r["n_victims"], "n_reached": r["n_reached"],
        "end_reason": r["end_reason"], "sim_time_s": r["sim_time_s"],
        "path_length_m": r["path_length_m"], "collisions": r["collisions"],
        "false_finds": len(r["false_finds"]), "spl": r["spl"], "n_listens": r["n_listens"],
        "ang_err_median_deg": ang["median"], "ang_err_mean_deg": ang["mean"], "ang_err_p90_deg": ang["p90"],
        "victim_times": {v["name"]: v["time_s"] for v in r["victims"]},
        "victim_spl": {v["name"]: v["spl"] for v in r["victims"]},
        "found_victims": [v["name"] for v in found],
        "find_times_s": [v["time_s"] for v in found],
        "position_errors_m": [v["estimate_error_m"] for v in found],
        "detection_errors_deg": [d["error_deg"] for rec in r["listens"] for d in rec["detections"]
                                 if "error_deg" in d],
        "blas": r.get("provenance", {}).get("openblas_coretype", ""),
    }


def run_one(scenario: Scenario, seed: int, world: World | None = None) -> dict[str, Any]:
    """One run -> :func:`row_from_result` plus its wall-clock time."""
    t0 = time.perf_counter()
    r = RescueRun(scenario, seed=seed, world=world).run()
    wall = time.perf_counter() - t0
    return {**row_from_result(r, getattr(scenario, "family", None)), "wall_s": round(wall, 3),
            "wall_per_sim_s": round(wall / max(r["sim_time_s"], 1e-9), 4)}


def _is_dask(executor) -> bool:
    return hasattr(executor, "scheduler_info") and hasattr(executor, "gather")


def _key(future) -> Any:
    return getattr(future, "key", None) or id(future)  # Dask futures are re-wrapped; their key is stable


def _as_completed(executor, futures):
    if _is_dask(executor):
        from distributed import as_completed
        return as_completed(futures)
    return cf.as_completed(futures)


def run_sweep(scenarios: Sequence[Scenario | str | Path], seeds: Iterable[int] | None, *, executor=None,
              cluster: str | None = None, workers: int | None = None, time_limit_s: float | None = None,
              progress: bool = False) -> list[dict[str, Any]]:
    """Run every scenario with every seed (``seeds=None``: each once with its own seed, as a generated suite
    runs); returns run rows in (scenario, seed) order.

    ``executor``: an existing ``concurrent.futures.Executor`` or ``distributed.Client`` to use.
    Otherwise ``cluster`` (``tcp://HOST:PORT`` of a Dask scheduler) connects a Client, or else a
    local ProcessPoolExecutor with ``workers`` processes (default: CPU count) is started."""
    scs = [s if isinstance(s, Scenario) else load_scenario(s) for s in scenarios]
    scs = [s.with_overrides(time_limit_s=time_limit_s) for s in scs]
    seeds = list(seeds) if seeds is not None else None
    if not scs or seeds == []:
        raise ValueError("run_sweep: need at least one scenario and one seed")
    # Build (and validate) every run's World here: errors surface before any work is sent.
    tasks = []
    for s in scs:
        for seed in (seeds if seeds is not None else [s.seed]):
            try:
                tasks.append((s, seed, s.world(seed)))
            except ScenarioError as exc:
                raise ScenarioError(f"{exc} (seed {seed})") from None
    own = None
    if executor is None:
        if cluster:
            from distributed import Client  # optional 'cluster' extra
            executor = own = Client(cluster)
        else:
            n = workers or multiprocessing.cpu_count()
            executor = own = cf.ProcessPoolExecutor(max_workers=min(n, len(tasks)),
                                                    mp_context=multiprocessing.get_context("spawn"))
    try:
        futures = [executor.submit(run_one, s, seed, w) for s, seed, w in tasks]
        index = {_key(f): k for k, f in enumerate(futures)}
        rows: list[dict | None] = [None] * len(futures)
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=len(futures), unit="run", desc="sweep")
        try:
            for f in _as_completed(executor, futures):
                rows[index[_key(f)]] = f.result()
                if bar is not None:
                    bar.update(1)
                    done = [r for r in rows if r is not None]
                    bar.set_postfix_str(f"success {sum(r['success'] for r in done)}/{len(done)}")
        finally:
            if bar is not None:
                bar.close()
    finally:
        if own is not None:
            if _is_dask(own):
                own.close()
            else:
                own.shutdown()
    return rows  # type: ignore[return-value]


# ----------------------------------------------------------------------------- tables
def _mean(xs) -> float | None:
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return round(float(np.mean(xs)), 4) if xs else None


def summarize(rows: Sequence[dict]) -> dict[str, list[dict]]:
    """Per-family, per-scenario and per-victim tables from run rows.

    ``families`` (``ssl_sim.stats.summarize``): per scene family and over all, success rate, victims found,
    SPL, time to find, false finds per run and position error, each with its 95 % bootstrap interval over
    scenarios. ``scenarios``: runs, success rate (all victims found), victims found rate, victims reached rate
    (base within 0.75 m at a declaration), mean SPL, mean path, mean collisions, false finds per run, angular
    error of all detections (median, mean, p90, pooled over runs), mean wall-clock per simulated second.
    ``victims``: per scenario and victim, found rate, mean/median time to find (over the runs that found it),
    mean SPL."""
    by: dict[str, list[dict]] = {}
    for r in rows:
        by.setdefault(r["scenario"], []).append(r)
    scen, vict = [], []
    for name, rs in by.items():
        errs = np.array([e for r in rs for e in r["detection_errors_deg"]])
        scen.append({
            "scenario": name, "runs": len(rs), "seeds": f"{min(r['seed'] for r in rs)}..{max(r['seed'] for r in rs)}",
            "success_rate": round(sum(r["success"] for r in rs) / len(rs), 4),
            "victims_found_rate": round(sum(r["n_found"] for r in rs) / max(sum(r["n_victims"] for r in rs), 1), 4),
            "victims_reached_rate": round(sum(r["n_reached"] for r in rs) / max(sum(r["n_victims"] for r in rs), 1),
                                          4),
            "mean_spl": _mean(r["spl"] for r in rs),
            "mean_sim_time_s": _mean(r["sim_time_s"] for r in rs),
            "mean_path_m": _mean(r["path_length_m"] for r in rs),
            "mean_collisions": _mean(r["collisions"] for r in rs),
            "false_finds_per_run": _mean(r["false_finds"] for r in rs),
            "ang_err_median_deg": round(float(np.median(errs)), 2) if errs.size else None,
            "ang_err_mean_deg": round(float(errs.mean()), 2) if errs.size else None,
            "ang_err_p90_deg": round(float(np.percentile(errs, 90)), 2) if errs.size else None,
            "n_detections": int(errs.size),
            "wall_per_sim_s": _mean(r["wall_per_sim_s"] for r in rs),
        })
        names = list(dict.fromkeys(v for r in rs for v in r["victim_times"]))
        for v in names:
            times = [r["victim_times"].get(v) for r in rs]
            found = [t for t in times if t is not None]
            vict.append({"scenario": name, "victim": v, "runs": len(rs),
                         "found_rate": round(len(found) / len(rs), 4),
                         "mean_time_to_find_s": _mean(found),
                         "median_time_to_find_s": round(float(np.median(found)), 2) if found else None,
                         "mean_spl": _mean(r["victim_spl"].get(v) for r in rs)})
    return {"families": stats.summarize(rows), "scenarios": scen, "victims": vict}


def _cell(v) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, float):
        return f"{v:.3g}" if abs(v) < 1000 else f"{v:.0f}"
    return str(v)


def markdown_table(rows: Sequence[dict], columns: Sequence[str] | None = None) -> str:
    if not rows:
        return "(no rows)\n"
    cols = list(columns or rows[0].keys())
    out = ["| " + " | ".join(cols) + " |", "|" + "|".join("---" for _ in cols) + "|"]
    out += ["| " + " | ".join(_cell(r.get(c)) for c in cols) + " |" for r in rows]
    return "\n".join(out) + "\n"


_RUN_CSV_COLUMNS = ("scenario", "family", "seed", "blas", "success", "n_found", "n_victims", "n_reached", "end_reason",
                    "sim_time_s", "path_length_m", "collisions", "false_finds", "spl", "n_listens",
                    "ang_err_median_deg", "ang_err_mean_deg", "ang_err_p90_deg", "wall_s", "wall_per_sim_s")


def _write_csv(path: Path, rows: Sequence[dict], columns: Sequence[str]) -> None:
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(columns), extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({c: ("" if r.get(c) is None else r.get(c)) for c in columns})


def interval_table(rows: Sequence[dict]) -> str:
    """The families table as "mean [lo, hi]" cells."""
    out = []
    for r in rows:
        row = {"family": r["family"], "scenarios": r["scenarios"]}
        for m, (label, unit) in stats.METRICS.items():
            iv = stats.Interval(*(math.nan if r[k] is None else r[k] for k in (m, f"{m}_lo", f"{m}_hi")),
                                n=r["scenarios"])
            row[f"{label}{f' ({unit})' if unit else ''}"] = iv.fmt(1 if unit == "s" else 2 if unit == "m" else 3)
        out.append(row)
    return markdown_table(out)


def write_tables(rows: Sequence[dict], tables: dict[str, list[dict]], out_dir: str | Path) -> dict[str, Path]:
    """``runs.csv`` (one row per run, victim times as ``t_<name>_s`` columns), ``families.csv`` (metrics with
    95 % intervals), ``scenarios.csv``, ``victims.csv``, ``summary.md`` (the tables), ``summary.json``
    (the tables and the provenance: commit, package versions, BLAS kernel, CPU) and ``sweep.png`` (success and
    SPL per family with intervals, histogram of time to find) in ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    names = list(dict.fromkeys(v for r in rows for v in r["victim_times"]))
    flat = [{**r, **{f"t_{v}_s": r["victim_times"].get(v) for v in names}} for r in rows]
    paths = {"runs": out / "runs.csv", "families": out / "families.csv", "scenarios": out / "scenarios.csv",
             "victims": out / "victims.csv", "markdown": out / "summary.md", "json": out / "summary.json",
             "plot": out / "sweep.png"}
    _write_csv(paths["runs"], flat, list(_RUN_CSV_COLUMNS) + [f"t_{v}_s" for v in names])
    for key in ("families", "scenarios", "victims"):
        if tables.get(key):
            _write_csv(paths[key], tables[key], list(tables[key][0]))
    prov = provenance()
    pk = prov["machine"]["packages"]
    md = ["# Rescue sweep", "", f"{len(rows)} runs. Scored by ssl_sim.scoring: a find is a declaration whose "
          "reported position is within 0.5 m of an unfound victim with the robot base within 1.5 m of her; "
          "false finds report > 0.5 m from every unfound victim; SPL = found x shortest path (to within 1.5 m, "
          "16-connected free-space graph, no corner cutting) / max(driven, shortest) per leg, averaged over "
          "victims; \"reached\" = base within 0.75 m at a declaration. Intervals: 95 % bootstrap over scenarios; "
          "angular errors pool every detection against the nearest sounding source (array frame).", "",
          f"Commit {prov['commit'] or '?'}{' (uncommitted changes)' if prov['dirty'] else ''}; "
          + ", ".join(f"{k} {v}" for k, v in pk.items())
          + f"; OpenBLAS kernel {prov['openblas_coretype'] or 'CPU default'}"
          f" ({'; '.join(prov['machine']['blas'])}); CPU {prov['machine']['cpu']} x {prov['machine']['cores']}.", "",
          "## Scene families", "", interval_table(tables.get("families", [])),
          "## Scenarios", "", markdown_table(tables["scenarios"]), "## Victims", "", markdown_table(tables["victims"])]
    paths["markdown"].write_text("\n".join(md))
    paths["json"].write_text(json.dumps({"provenance": prov, **tables}, indent=1, default=float))
    from ssl_sim.plots import sweep_figure
    sweep_figure(tables.get("families", []), [t for r in rows for t in r.get("find_times_s", [])], paths["plot"],
                 title=f"Rescue sweep: {len(rows)} runs")
    return paths
