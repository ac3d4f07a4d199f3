"""What the generated suites cost: generating a split, and running its scenarios (CPU s per simulated s).

Generation: CPU time of ``ssl_sim.suite.generate`` for every scenario of the test split (scene, sounds, the
loader's checks), and what the split holds (families, victims, interferers, real recordings).

Runs: the given test scenarios (``--runs``), each through ``ssl_sim.runner.RescueRun`` to its own time limit (or
until every victim is found), one after the other in this process with BLAS on one thread, as a sweep worker
runs them. CPU time (``time.process_time``) per simulated second, and the estimate for the whole test split on
``--cores`` cores: the mean CPU per run x TEST_SIZE / cores (a LocalCluster keeps every core busy; runs that end
early make the real figure lower, and a loaded machine makes the wall time longer).

Run: ``nice -n 10 .venv/bin/python benchmarks/bench_suite.py --runs 0,1,2,3,5``.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _results import write_result  # noqa: E402

from ssl_sim import suite  # noqa: E402
from ssl_sim.runner import RescueRun  # noqa: E402
from ssl_sim.sweep import markdown_table  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--runs", default="0,1,2,3,5", help="test-split indices to run (comma list)")
    ap.add_argument("--cores", type=int, default=2, help="cores for the whole-split estimate (default 2)")
    args = ap.parse_args(argv)
    runs = [int(x) for x in args.runs.split(",") if x.strip()]

    # -- generation
    t0 = time.process_time()
    scs = [suite.generate("test", i) for i in suite.test_indices()]
    gen_cpu = (time.process_time() - t0) / len(scs)
    rows = [suite.summary_row(s) for s in scs]
    fam = Counter(r["family"] for r in rows)
    n_vict = Counter(r["victims"] for r in rows)
    n_int = Counter(r["interferers"] for r in rows)
    real_v = sum(v.sound == "file" for s in scs for v in s.victims)
    all_v = sum(len(s.victims) for s in scs)
    real_i = sum(i.kind == "file" for s in scs for i in s.interferers)
    all_i = sum(len(s.interferers) for s in scs)
    limits = np.array([s.time_limit_s for s in scs])
    print(f"test split: {len(scs)} scenarios, generated in {gen_cpu:.3f} s CPU each; families {dict(fam)}; "
          f"victims per scenario {dict(sorted(n_vict.items()))} ({real_v}/{all_v} real recordings); interferers "
          f"{dict(sorted(n_int.items()))} ({real_i}/{all_i} real recordings); time limits {limits.min():.0f}-"
          f"{limits.max():.0f} s (sum {limits.sum():.0f} s)")

    # -- runs
    table = []
    for i in runs:
        sc = scs[i]
        t0 = time.process_time()
        r = RescueRun(sc).run()
        cpu = time.process_time() - t0
        row = {"index": i, "name": sc.name, **{k: suite.summary_row(sc)[k] for k in ("room_m", "victims", "interferers",
                                                                                     "rt60_s")},
               "time_limit_s": sc.time_limit_s, "sim_s": r["sim_time_s"], "found": f"{r['n_found']}/{r['n_victims']}",
               "cpu_s": round(cpu, 1), "cpu_per_sim_s": round(cpu / max(r["sim_time_s"], 1e-9), 4)}
        table.append(row)
        print(row, flush=True)
    cpu_run = np.array([r["cpu_s"] for r in table])
    per_sim = np.array([r["cpu_per_sim_s"] for r in table])
    sim = np.array([r["sim_s"] for r in table])
    est_min = float(cpu_run.mean() * len(scs) / args.cores / 60.0)
    # upper bound: every test scenario runs to its time limit at the mean CPU per simulated second
    est_max = float(per_sim.mean() * limits.sum() / args.cores / 60.0)
    md = markdown_table(table)
    print(md)
    print(f"mean {per_sim.mean():.3f} CPU s per simulated s (range {per_sim.min():.3f}-{per_sim.max():.3f}); "
          f"mean {cpu_run.mean():.1f} CPU s per run of {sim.mean():.0f} simulated s; whole test split on "
          f"{args.cores} cores: ~{est_min:.0f} min (these runs' mean), at most ~{est_max:.0f} min (every run to its "
          "time limit)")
    write_result("bench_suite", {
        "generate_cpu_s_per_scenario": round(gen_cpu, 4), "test_scenarios": len(scs),
        "test_time_limit_sum_s": float(limits.sum()), "runs": len(table),
        "cpu_per_sim_s_mean": round(float(per_sim.mean()), 4), "cpu_per_sim_s_max": round(float(per_sim.max()), 4),
        "cpu_s_per_run_mean": round(float(cpu_run.mean()), 1),
        "test_split_min_estimate": round(est_min, 1), "test_split_min_upper_bound": round(est_max, 1),
        "cores": args.cores}, {"runs": md})
    return 0


if __name__ == "__main__":
    sys.exit(main())
