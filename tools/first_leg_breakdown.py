"""The first leg of stored rescue runs: where its metres went, and a paired comparison of two sets of runs.

Reads the ``results.json`` that ``ssl-rescue run SCENARIO --seed N --out DIR`` writes (``victims``, ``events`` as
strings, ``listens`` with the true pose of every listen), found anywhere below each directory given and matched by
the scenario and seed they record, so nothing is simulated again.
For each run the first leg (start -> first find) is cut at its listens; the straight distance between two listens'
true positions goes to what the behaviour decided after the first of them:

* ``toward next`` / ``toward other caller``: a ``target`` whose estimate lies, seen from the robot's true position,
  within 20 deg of the bearing to the caller found at the end of the leg / to another caller (a probe's estimate
  is a guess along the bearing, so the bearing decides, as in ``spl_breakdown.py``);
* ``ghost``: a target more than 20 deg from every caller (a mirror image, two callers' rays crossing);
* ``baseline step`` (a step across a bearing), ``explore``; the rest of the leg's true path (back-offs,
  escapes, detours between listens) is ``recoveries and detours``.

With a second directory: per-run SPL, the paired difference (mean and its standard error over the seeds), each
leg's mean SPL, finds and false founds. Prints one JSON line at the end.

Run: ``for s in $(seq 0 15); do ssl-rescue run light_rubble_three --seed $s -q --out runs/a/$s; done``, the same
for the other code into ``runs/b``, then ``python tools/first_leg_breakdown.py runs/a runs/b --seeds 0:16``
"""
from __future__ import annotations

import argparse
import json
import math
import re
from collections import defaultdict
from pathlib import Path

import numpy as np

NEAR_DEG = 20.0   # a target's bearing this close to a caller's is toward her (spl_breakdown's PROBE_BEARING_DEG)
TARGET = re.compile(r"\btarget\b.*#(\d+) at \(([-\d.]+), ([-\d.]+)\) m")


def _time(event: str) -> float:
    return float(event[1:event.index(" s]")])


def _legs(run: dict) -> list[dict]:
    return sorted((v for v in run["victims"] if v["found"]), key=lambda v: v["time_s"])


def first_leg(run: dict) -> dict[str, float]:
    """Metres of the first leg per category (see the module docstring); {} when nothing was found."""
    legs = _legs(run)
    if not legs:
        return {}
    end, name = legs[0]["time_s"], legs[0]["name"]
    callers = {v["name"]: v["position"][:2] for v in run["victims"]}
    listens = [rec for rec in run["listens"] if rec["time_s"] <= end + 1e-6]
    decided = defaultdict(list)
    for e in run["events"]:
        decided[round(_time(e), 2)].append(e)
    out: dict[str, float] = defaultdict(float)
    for a, b in zip(listens, listens[1:]):
        what = "other decisions"
        for e in decided.get(round(a["time_s"], 2), []):
            if "step across its bearing" in e:
                what = "baseline step"
            elif re.search(r"\bexplore\b", e[20:34]):
                what = "explore"
            elif (m := TARGET.search(e)) is not None:
                x, y = a["pose"][:2]
                toward = math.atan2(float(m.group(3)) - y, float(m.group(2)) - x)
                off = {n: abs(math.remainder(math.atan2(c[1] - y, c[0] - x) - toward, 2 * math.pi))
                       for n, c in callers.items()}
                near = min(off, key=off.get)
                what = ("ghost" if off[near] > math.radians(NEAR_DEG)
                        else "toward next" if near == name else "toward other caller")
        out[what] += math.dist(a["pose"][:2], b["pose"][:2])
    out["recoveries and detours"] = legs[0]["leg_path_m"] - sum(out.values())
    return dict(out)


def _load(directory: Path, scenario: str, seeds: range) -> dict[int, dict]:
    """The runs of ``scenario`` with a seed in ``seeds`` among the ``results.json`` files below ``directory``."""
    runs = {}
    for f in sorted(directory.rglob("results.json")):
        run = json.loads(f.read_text())
        if run.get("scenario") == scenario and run.get("seed") in seeds:
            if run["seed"] in runs:
                raise SystemExit(f"{f}: a second run of {scenario} seed {run['seed']} in {directory}")
            runs[run["seed"]] = run
    return runs


def _summary(label: str, runs: dict[int, dict]) -> dict:
    metres: dict[str, float] = defaultdict(float)
    for r in runs.values():
        for k, m in first_leg(r).items():
            metres[k] += m
    legs = [[(_legs(r)[k]["spl"] if k < len(_legs(r)) else 0.0) for r in runs.values()] for k in range(3)]
    firsts = [_legs(r)[0] for r in runs.values() if _legs(r)]
    out = {"label": label, "runs": len(runs), "spl": float(np.mean([r["spl"] for r in runs.values()])),
           "leg_spl": [round(float(np.mean(x)), 3) for x in legs],
           "found": sum(r["n_found"] for r in runs.values()), "victims": sum(r["n_victims"] for r in runs.values()),
           "false_found": sum(len(r["false_finds"]) for r in runs.values()),
           "first_find_s": round(float(np.mean([v["time_s"] for v in firsts])), 1),
           "first_leg_m": {k: round(m, 1) for k, m in sorted(metres.items())},
           "first_leg_shortest_m": round(sum(v["leg_shortest_path_m"] for v in firsts), 1)}
    print(f"{label}: {out['runs']} runs, SPL {out['spl']:.3f}, legs {out['leg_spl']}, found {out['found']}/"
          f"{out['victims']}, false found {out['false_found']}, first find at {out['first_find_s']} s")
    print("  first-leg metres: " + ", ".join(f"{k} {m}" for k, m in out["first_leg_m"].items())
          + f" (shortest {out['first_leg_shortest_m']})")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("base", type=Path, help="directory of stored runs (results.json of ssl-rescue run, any depth)")
    ap.add_argument("new", type=Path, nargs="?", help="a second directory, compared seed by seed with the first")
    ap.add_argument("--scenario", default="light_rubble_three")
    ap.add_argument("--seeds", default="0:16", help="START:STOP (stop exclusive)")
    args = ap.parse_args()
    a, b = (int(v) for v in args.seeds.split(":"))
    base = _load(args.base, args.scenario, range(a, b))
    if not base:
        ap.error(f"base: no results.json of {args.scenario} seeds {a}-{b - 1} in {args.base}")
    result = {"bench": "first_leg", "scenario": args.scenario, "seeds": [a, b],
              "base": _summary(str(args.base), base)}
    if args.new is not None:
        new = _load(args.new, args.scenario, range(a, b))
        seeds = sorted(set(base) & set(new))
        if not seeds:
            ap.error(f"new: no results.json of {args.scenario} with a seed of {args.base} in {args.new}")
        result["new"] = _summary(str(args.new), {s: new[s] for s in seeds})
        d = np.array([new[s]["spl"] - base[s]["spl"] for s in seeds])
        f = np.array([_legs(new[s])[0]["spl"] if _legs(new[s]) else 0.0 for s in seeds]) \
            - np.array([_legs(base[s])[0]["spl"] if _legs(base[s]) else 0.0 for s in seeds])
        se = float(d.std(ddof=1) / math.sqrt(len(d))) if len(d) > 1 else math.nan
        print(f"paired over {len(seeds)} seeds: SPL {d.mean():+.3f} (standard error {se:.3f}); first leg "
              f"{f.mean():+.3f}, better in {int((f > 0.005).sum())}, worse in {int((f < -0.005).sum())}")
        for s in seeds:
            print(f"  seed {s:2d}: SPL {base[s]['spl']:.3f} -> {new[s]['spl']:.3f}, found {base[s]['n_found']} -> "
                  f"{new[s]['n_found']}")
        result["paired"] = {"seeds": len(seeds), "spl_diff": round(float(d.mean()), 4), "spl_diff_se": round(se, 4),
                            "first_leg_diff": round(float(f.mean()), 4)}
    print(json.dumps(result))


if __name__ == "__main__":
    main()
