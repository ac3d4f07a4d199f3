"""Odometry drift of the rescue behaviour in light rubble: gyro-aided vs wheels alone, against MuJoCo's truth.

Each seed runs ``ssl_sim/scenarios/light_rubble_three.toml`` for 200 simulated seconds (the behaviour keeps exploring after
its last find, so every run lasts the whole time, bumps and recoveries included; ``ssl_sim.runner.odometry_drift``).
At the end: the behaviour's gyro-aided pose and a wheels-only odometry fed the same encoder readings, each against
the true pose; the simulated gyro's bias (it drifts) and the odometry's standstill estimate of it. Seeds run one
after the other on one core (BLAS threads capped at 1).

Prints a table and one JSON line. Run: ``.venv/bin/python benchmarks/bench_odometry.py [--seeds 0,1,2,3,4,5,6,7]``.
Target: heading error <= 3 deg and position error <= 0.3 m after 200 s on every seed.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import warnings  # noqa: E402

from _results import write_result  # noqa: E402
from ssl_sim.runner import odometry_drift  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="0,1,2,3,4,5,6,7", help="comma-separated seeds")
    ap.add_argument("--duration", type=float, default=200.0, help="simulated seconds per run")
    ap.add_argument("--scenario", default="light_rubble_three")
    args = ap.parse_args(argv)
    seeds = [int(s) for s in args.seeds.split(",")]
    rows = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for seed in seeds:
            rows.append(odometry_drift(args.scenario, seed, args.duration))
    print(f"bench_odometry: {args.scenario}, {args.duration:g} s per seed, end pose against MuJoCo truth")
    print(f"{'seed':>4} {'bumps':>5} {'heading deg':>11} {'pos m':>6} {'wheels deg':>10} {'wheels m':>8} "
          f"{'bias deg/s':>10} {'estimate':>8} {'ZUPTs':>5} {'slips':>5} {'loaded':>6} {'CPU s':>6}")
    for r in rows:
        print(f"{r['seed']:>4} {r['bumper_recoveries']:>5} {r['heading_error_deg']:>11.2f} "
              f"{r['position_error_m']:>6.3f} {r['wheels_heading_error_deg']:>10.2f} "
              f"{r['wheels_position_error_m']:>8.3f} {r['gyro_bias_deg_s']:>10.4f} "
              f"{r['gyro_bias_estimate_deg_s']:>8.4f} {r['bias_updates']:>5} {r['slip_intervals']:>5} "
              f"{r['loaded_intervals']:>6} "
              f"{r['cpu_s']:>6.1f}")
    met = all(r["heading_error_deg"] <= 3.0 and r["position_error_m"] <= 0.3 for r in rows)
    print(f"target (<= 3 deg and <= 0.3 m on every seed): {'met' if met else 'NOT met'}")
    keys = ("seed", "sim_time_s", "bumper_recoveries", "heading_error_deg", "position_error_m",
            "wheels_heading_error_deg", "wheels_position_error_m", "gyro_bias_deg_s", "gyro_bias_estimate_deg_s",
            "bias_updates", "slip_intervals", "loaded_intervals", "cpu_s")
    print(json.dumps({"bench": "odometry", "scenario": args.scenario, "duration_s": args.duration, "target_met": met,
                      "runs": [{k: (round(r[k], 4) if isinstance(r[k], float) else r[k]) for k in keys}
                               for r in rows]}))
    md = ["| seed | heading error (deg) | position error (m) | bumper recoveries |", "|---|---|---|---|"]
    md += [f"| {r['seed']} | {r['heading_error_deg']:.2f} | {r['position_error_m']:.3f} | {r['bumper_recoveries']} |"
           for r in rows]
    write_result("odometry", {"seeds": len(rows), "duration_s": args.duration, "target_met": int(met),
                              "max_heading_error_deg": max(r["heading_error_deg"] for r in rows),
                              "max_position_error_m": max(r["position_error_m"] for r in rows),
                              "mean_position_error_m": sum(r["position_error_m"] for r in rows) / len(rows)},
                 {f"Odometry end-pose error after {args.duration:g} s in {args.scenario} (gyro + free wheels)":
                  "\n".join(md) + "\n"})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
