"""Where the path goes: the true metres of each SPL leg split by what the behaviour was doing while it drove them.

SPL (``ssl_sim.runner``) scores each victim's leg: from the start or the previous find to her find, grid-geodesic
shortest path over the true path driven. Every metre that does not lead to her costs. For each run (one process per
run, deterministic per seed) the behaviour's events cut the true trajectory into moves, each put in one category:

* ``toward next victim``: a ``drive`` at a target whose estimate lies within ``--near`` m of the caller found at
  the end of this leg; ``toward other unfound victim`` / ``toward found victim``: near another caller, not yet /
  already found; ``ghost/reflection``: near no caller. A target whose range is unknown (1-sigma over 1 m: heard from
  one place, driven at by a probe) is judged by its bearing from the robot (within 20 deg of a caller's) and tagged
  ``(probe)``;
* ``baseline step`` (a step across a bearing to triangulate it), ``explore``, ``recover`` (contacts, back-offs,
  escapes), ``other``;
* apart, overlapping those: ``[inside the find radius]``, the metres driven within the find radius (1.5 m) of the
  caller before she was declared found.

Prints the metres per category over all legs that end in a find, the worst legs, and one JSON line.

Run: ``nice .venv/bin/python tools/spl_breakdown.py --scenario light_rubble_three --seeds 0:16
--time-limit 180 --workers 2``
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import concurrent.futures as cf  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import multiprocessing  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402

import numpy as np  # noqa: E402

PROBE_SIGMA_M = 1.0        # planner.PlannerConfig.probe_sigma_m: above it a target is driven at by a probe
PROBE_BEARING_DEG = 20.0   # a probe's bearing this close to a caller's is toward her
INSIDE = "[inside the find radius]"


def _run(scenario: str, seed: int, time_limit: float | None) -> dict:
    from ssl_sim.runner import RescueRun
    from ssl_sim.scenario import load_scenario
    from ssl_sim.scoring import FIND_BASE_RADIUS_M
    t0 = time.process_time()
    run = RescueRun(load_scenario(scenario).with_overrides(time_limit_s=time_limit), seed=seed)
    res = run.run()
    traj = np.array(run.trajectory)[:, :3]
    return {"seed": seed, "n_found": res["n_found"], "n_victims": res["n_victims"], "spl": res["spl"],
            "false_found": len(res["false_finds"]), "end": res["sim_time_s"], "victims": res["victims"],
            "callers": [tuple(s.position[:2]) for s in run.sources[:run.n_victims]],
            "radius": FIND_BASE_RADIUS_M, "t": traj[:, 0], "xy": traj[:, 1:], "cum": np.array(run.cum_path),
            "events": [(e.time, e.decision.value, e.reason, e.data.to_dict()) for e in run.events],
            "cpu_s": time.process_time() - t0}


def _moves(r: dict, near: float) -> list[tuple[float, float, object]]:
    """(t0, t1, what) per move: what is a category, or ("target", position, sigma) for a drive at a target."""
    out, target = [], None
    ev = r["events"]
    for k, (t, decision, reason, data) in enumerate(ev):
        t1 = ev[k + 1][0] if k + 1 < len(ev) else r["end"]
        if decision == "target":
            target = data
        elif decision == "drive":
            what = "baseline step" if "step across its bearing" in reason else ("target", target["position"],
                                                                                   target["sigma_m"])
            out.append((t, t1, what))
        elif decision in ("explore", "recover"):
            out.append((t, t1, {"explore": "explore", "recover": "recover"}[decision]))
        else:
            out.append((t, t1, f"other ({decision})"))
    return out


def _category(r: dict, what, t: float, leg_victim: int, found_at: dict, near: float) -> str:
    if isinstance(what, str):
        return what
    _, pos, sigma = what
    callers = [np.asarray(c) for c in r["callers"]]
    probe = sigma > PROBE_SIGMA_M
    if probe:   # range unknown: the bearing from the robot says which caller it is toward
        x, y = (np.interp(t, r["t"], r["xy"][:, i]) for i in (0, 1))
        a = math.atan2(pos[1] - y, pos[0] - x)
        off = [abs(math.remainder(math.atan2(c[1] - y, c[0] - x) - a, 2 * math.pi)) for c in callers]
        k = int(np.argmin(off))
        hit = off[k] <= math.radians(PROBE_BEARING_DEG)
    else:
        d = [math.hypot(pos[0] - c[0], pos[1] - c[1]) for c in callers]
        k = int(np.argmin(d))
        hit = d[k] <= near
    tag = " (probe)" if probe else ""
    if not hit:
        return "ghost/reflection" + tag
    if k in found_at and found_at[k] < t:
        return "toward found victim" + tag
    return ("toward next victim" if k == leg_victim else "toward other unfound victim") + tag


def breakdown(r: dict, near: float) -> list[dict]:
    """One dict per leg that ends in a find: victim, spl, path, shortest, metres per category."""
    found_at = {i: v["time_s"] for i, v in enumerate(r["victims"]) if v["found"]}
    moves = _moves(r, near)
    legs, t_prev = [], 0.0
    for i in sorted(found_at, key=found_at.get):
        t_end, cats = found_at[i], defaultdict(float)
        c = r["callers"][i]
        for t0, t1, what in moves:
            a, b = max(t0, t_prev), min(t1, t_end)
            if b <= a:
                continue
            ts = np.linspace(a, b, 41)
            cum = np.interp(ts, r["t"], r["cum"])
            cats[_category(r, what, a, i, found_at, near)] += float(cum[-1] - cum[0])
            inside = np.hypot(np.interp(ts, r["t"], r["xy"][:, 0]) - c[0],
                              np.interp(ts, r["t"], r["xy"][:, 1]) - c[1]) <= r["radius"]
            cats[INSIDE] += float(np.sum(np.diff(cum) * inside[1:]))
        v = r["victims"][i]
        legs.append({"seed": r["seed"], "victim": v["name"], "spl": v["spl"], "path": v["leg_path_m"],
                     "shortest": v["leg_shortest_path_m"], "metres": dict(cats)})
        t_prev = t_end
    return legs


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="light_rubble_three")
    ap.add_argument("--seeds", default="0:16", help="START:STOP (stop exclusive)")
    ap.add_argument("--time-limit", type=float, default=180.0, help="simulated s (default 180, the target's limit)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--near", type=float, default=1.0, help="a target estimate this close to a caller is toward her (m)")
    args = ap.parse_args()
    a, b = (int(v) for v in args.seeds.split(":"))
    ctx = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(args.workers, mp_context=ctx) as ex:
        runs = list(ex.map(_run, [args.scenario] * (b - a), range(a, b), [args.time_limit] * (b - a)))
    legs = [leg for r in runs for leg in breakdown(r, args.near)]
    total = defaultdict(float)
    for leg in legs:
        for k, m in leg["metres"].items():
            total[k] += m
    driven, shortest = sum(leg["path"] for leg in legs), sum(leg["shortest"] for leg in legs)
    found, n = sum(r["n_found"] for r in runs), sum(r["n_victims"] for r in runs)
    spl = float(np.mean([r["spl"] for r in runs]))
    ff = sum(r["false_found"] for r in runs) / len(runs)
    print(f"{args.scenario}, seeds {a}-{b - 1}, {args.time_limit:g} s: found {found}/{n}, SPL {spl:.3f}, "
          f"false found {ff:.2f} per run")
    print(f"{len(legs)} legs ending in a find: driven {driven:.1f} m, shortest {shortest:.1f} m")
    for k, m in sorted(total.items(), key=lambda kv: (kv[0] == INSIDE, -kv[1])):
        print(f"  {k:45s} {m:7.1f} m  {100 * m / max(driven, 1e-9):4.0f} %")
    print("worst legs:")
    for leg in sorted(legs, key=lambda g: g["spl"])[:8]:
        top = ", ".join(f"{k} {m:.1f}" for k, m in sorted(leg["metres"].items(), key=lambda kv: -kv[1]) if m >= 0.1)
        print(f"  seed {leg['seed']:2d} {leg['victim']:14s} SPL {leg['spl']:.2f}, {leg['path']:.1f} m for "
              f"{leg['shortest']:.1f} m: {top}")
    print(json.dumps({"bench": "spl_breakdown", "scenario": args.scenario, "seeds": [a, b], "found": found,
                      "victims": n, "spl": round(spl, 4), "false_found_per_run": round(ff, 3),
                      "driven_m": round(driven, 2), "shortest_m": round(shortest, 2),
                      "metres": {k: round(m, 2) for k, m in total.items()},
                      "cpu_s_per_run": round(float(np.mean([r["cpu_s"] for r in runs])), 2)}))


if __name__ == "__main__":
    main()
