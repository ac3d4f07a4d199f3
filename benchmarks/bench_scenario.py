"""Wall-clock cost of a whole rescue run per simulated second, split into physics, acoustics,
localization and the rest (behaviour logic incl. voice scoring, truth bookkeeping).

Runs ``scenarios/light_rubble_three.toml`` (three callers in light rubble) headless, without
rerun logging, on one core (the run is single-threaded; BLAS threads are capped at 1 before numpy
loads). Instrumentation is ``time.perf_counter`` around the three parts (see ``ssl_sim.runner``):
physics = MuJoCo stepping in clock sleeps and audio reads, acoustics = rendering the microphone
signals, localization = ``Localizer.locate``.

Prints a table and one JSON line. Run: ``.venv/bin/python benchmarks/bench_scenario.py [--seeds 0,1]``.
Target: the whole loop faster than real time (wall s per simulated s < 1).
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

from ssl_sim.runner import RescueRun  # noqa: E402
from ssl_sim.scenario import load_scenario  # noqa: E402

PARTS = ("physics", "acoustics", "localization", "other")
#: The runner's "other" is the behaviour: its decisions, voice scoring, truth bookkeeping.
LABELS = {"physics": "physics", "acoustics": "acoustics", "localization": "localization", "other": "behaviour"}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default="light_rubble_three")
    ap.add_argument("--seeds", default="0", help="comma list of run seeds")
    ap.add_argument("--time-limit", type=float, default=None, help="simulated seconds (default: the scenario's)")
    args = ap.parse_args(argv)
    sc = load_scenario(args.scenario).with_overrides(time_limit_s=args.time_limit)
    rows = []
    for seed in [int(s) for s in args.seeds.split(",")]:
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = RescueRun(sc, seed=seed)
        setup = time.perf_counter() - t
        c = time.process_time()
        r = run.run()
        cpu = time.process_time() - c
        w = r["wall_clock_s"]
        rows.append({"seed": seed, "sim_s": r["sim_time_s"], "setup_s": round(setup, 3), "loop_s": w["loop"],
                     **{p: w[p] for p in PARTS}, "found": f"{r['n_found']}/{r['n_victims']}",
                     "listens": r["n_listens"], "cpu_s": cpu})
    sim = sum(r["sim_s"] for r in rows)
    loop = sum(r["loop_s"] for r in rows)
    per = {p: sum(r[p] for r in rows) / sim for p in PARTS}
    print(f"bench_scenario: {sc.name}, {len(rows)} run(s), {sim:.1f} s simulated, python {platform.python_version()}")
    print(f"{'seed':>4} {'sim s':>7} {'found':>6} {'listens':>7} {'loop s':>7} " +
          " ".join(f"{LABELS[p] + ' s':>14}" for p in PARTS))
    for r in rows:
        print(f"{r['seed']:>4} {r['sim_s']:>7.1f} {r['found']:>6} {r['listens']:>7} {r['loop_s']:>7.1f} " +
              " ".join(f"{r[p]:>14.2f}" for p in PARTS))
    cpu = sum(r["cpu_s"] for r in rows)
    print(f"wall s per simulated s: total {loop / sim:.3f} ({sim / loop:.1f}x faster than real time); " +
          ", ".join(f"{LABELS[p]} {per[p]:.3f} ({100 * per[p] * sim / loop:.0f} %)" for p in PARTS))
    print(f"CPU s per simulated s (this process; the wall clock includes waiting for a shared CPU): "
          f"{cpu / sim:.3f} ({sim / cpu:.1f}x faster than real time); load average {os.getloadavg()[0]:.2f} "
          f"on {os.cpu_count()} cores")
    print(json.dumps({"bench": "scenario", "scenario": sc.name, "seeds": [r["seed"] for r in rows],
                      "sim_s": round(sim, 2), "wall_per_sim_s": round(loop / sim, 4),
                      "realtime_factor": round(sim / loop, 2), "cpu_per_sim_s": round(cpu / sim, 4),
                      "cpu_realtime_factor": round(sim / cpu, 2), "loadavg_1min": os.getloadavg()[0],
                      "per_sim_s": {p: round(per[p], 4) for p in PARTS},
                      "found": [r["found"] for r in rows], "setup_s": [r["setup_s"] for r in rows]}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
