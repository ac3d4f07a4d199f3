"""How often SRP-PHAT detects a victim who sounds, against how loud she is at the array: over train-split runs.

Each train scenario runs as the benchmark runs it (``ssl_sim.runner.RescueRun``, the robot as it is) with
``record_snr``: every listen's truth then holds each source's band SNR at the array in that window (its own
sound in 300-6000 Hz against every other source's and the ambient field, from the simulator rendering each source
alone). For every listen and every victim sounding in it (``ssl_sim.runner.SOUNDING_FRACTION`` of its 10 ms
frames) the listen *detected* her when a detection lies within ``NEAR_DEG`` of her true direction (array frame,
the runner's matching). Printed: the detection rate per band-SNR bin and per distance; and, for the listens that
miss a victim who dominates the band (SNR above ``DOMINANT_DB``), what their detections point at: another sounding
source, a silent one, her azimuth only, or no source at all (a reflection or a lobe); split by whether her
straight path to the array is clear of obstacles (else her sound arrives diffracted or reflected).

``--driving``: the runs also hear while driving (``RescueConfig.listen_while_driving``); everything is then printed
for the listens heard standing and those heard while driving apart, with the signed azimuth and elevation errors of
the detections that found a victim, by her distance (a bias shows there, which the rates hide).

Run (train split; choose on train):

    nice -n 10 python tools/hearing_misses.py --start 200 --count 32 --workers 2 --json /tmp/misses.json
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import math
import multiprocessing as mp
import os
from collections import Counter

import numpy as np

from ssl_core.grid import direction_from_angles

NEAR_DEG = 10.0        # a detection this close (3-D angle) to her direction detected her
DOMINANT_DB = 5.0      # band SNR above which a victim dominates what the array hears
SNR_BINS_DB = (-math.inf, -20.0, -10.0, -5.0, 0.0, 5.0, 10.0, math.inf)
DIST_BINS_M = (0.0, 1.0, 2.0, 3.0, 4.0, 5.0, math.inf)


def run_one(index: int, driving: bool = False) -> list[dict]:
    """Train scenario ``index``: its listens (``RescueRun.listens`` with ``snr_db``); ``driving``: hearing while
    driving too."""
    os.nice(10)
    from dataclasses import replace

    from ssl_sim import suite
    from ssl_sim.runner import RescueRun
    sc = suite.generate("train", index)
    sc = replace(sc, behaviour=replace(sc.behaviour, listen_while_driving=driving))
    run = RescueRun(sc, record_snr=True)
    try:
        run.run()
    except Exception as exc:   # a simulator refusal ends the run; its listens so far still count
        print(f"train {index}: stopped early ({type(exc).__name__}: {exc})", flush=True)
    return run.listens


def _unit(az_deg: float, el_deg: float) -> np.ndarray:
    return direction_from_angles(math.radians(az_deg), math.radians(el_deg))


def classify(listens: list[dict]) -> list[dict]:
    """One row per (listen, sounding victim): band SNR (dB, None when silent), distance (m), detected, and for a
    miss what the listen's detections pointed at (``miss``)."""
    cos_near = math.cos(math.radians(NEAR_DEG))
    rows = []
    for rec in listens:
        srcs = rec["sources"]
        dirs = [_unit(s["azimuth_deg"], s["elevation_deg"]) for s in srcs]
        dets = [_unit(d["azimuth_deg"], d["elevation_deg"]) for d in rec["detections"]]
        for s, u in zip(srcs, dirs):
            if s["kind"] != "victim" or not s["active"]:
                continue
            near = [k for k, d in enumerate(dets) if float(d @ u) >= cos_near]
            hit = bool(near)
            miss, az_err, el_err = None, None, None
            if hit:   # the detection closest to her: its signed errors (deg, detection - truth)
                det = rec["detections"][max(near, key=lambda k: float(dets[k] @ u))]
                az_err = (det["azimuth_deg"] - s["azimuth_deg"] + 180.0) % 360.0 - 180.0
                el_err = det["elevation_deg"] - s["elevation_deg"]
            else:
                miss = "nothing detected" if not dets else _pointed_at(dets[0], s, srcs, dirs, cos_near)
            rows.append({"snr_db": s.get("snr_db"), "distance_m": s["distance_m"],
                         "line_of_sight": s.get("line_of_sight"), "detected": hit, "miss": miss,
                         "moving": bool(rec.get("moving", False)), "az_err_deg": az_err, "el_err_deg": el_err})
    return rows


def _pointed_at(d: np.ndarray, her: dict, srcs: list[dict], dirs: list[np.ndarray], cos_near: float) -> str:
    """What the strongest detection ``d`` of a listen that missed ``her`` points at."""
    near = [s for s, u in zip(srcs, dirs) if float(d @ u) >= cos_near]
    if any(s["active"] for s in near):
        return "another sounding " + ("victim" if any(s["kind"] == "victim" for s in near if s["active"])
                                      else "interferer")
    if near:
        return "a silent source"
    daz = math.degrees(math.atan2(d[1], d[0])) - her["azimuth_deg"]
    return "her azimuth, not her elevation" if abs((daz + 180.0) % 360.0 - 180.0) < NEAR_DEG else "no source"


def _binned(rows: list[dict], key: str, edges: tuple[float, ...], unit: str) -> list[dict]:
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = [r["detected"] for r in rows if r[key] is not None and lo <= r[key] < hi]
        if sel:
            out.append({"bin": f"{lo:g} .. {hi:g} {unit}", "n": len(sel), "detected": round(float(np.mean(sel)), 3)})
    return out


def errors(rows: list[dict]) -> list[dict]:
    """Signed azimuth and elevation errors (deg, detection - truth) of the detections that found her, by her
    distance: mean and median of each, and the median absolute azimuth error."""
    out = []
    for lo, hi in zip(DIST_BINS_M[:-1], DIST_BINS_M[1:]):
        sel = [r for r in rows if r["detected"] and lo <= r["distance_m"] < hi]
        if sel:
            az = np.array([r["az_err_deg"] for r in sel])
            el = np.array([r["el_err_deg"] for r in sel])
            out.append({"bin": f"{lo:g} .. {hi:g} m", "n": len(sel), "el_mean": round(float(el.mean()), 2),
                        "el_median": round(float(np.median(el)), 2), "az_mean": round(float(az.mean()), 2),
                        "abs_az_median": round(float(np.median(np.abs(az))), 2)})
    return out


def summary(rows: list[dict]) -> dict:
    dominant = [r for r in rows if r["snr_db"] is not None and r["snr_db"] > DOMINANT_DB]
    misses = Counter(r["miss"] for r in dominant if not r["detected"])
    by_path = {}
    for clear, name in ((True, "line of sight"), (False, "path blocked")):
        sel = [r for r in dominant if r.get("line_of_sight") is clear]
        by_path[name] = {"n": len(sel), "detected": sum(r["detected"] for r in sel),
                         "misses": dict(Counter(r["miss"] for r in sel if not r["detected"]).most_common())}
    return {"n": len(rows), "detected": round(float(np.mean([r["detected"] for r in rows])), 3) if rows else None,
            "by_snr": _binned(rows, "snr_db", SNR_BINS_DB, "dB"),
            "by_distance": _binned(rows, "distance_m", DIST_BINS_M, "m"),
            "dominant": {"n": len(dominant), "detected": sum(r["detected"] for r in dominant),
                         "misses": dict(misses.most_common()), "by_path": by_path},
            "errors_by_distance": errors(rows)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--start", type=int, default=200, help="first train scenario index")
    ap.add_argument("--count", type=int, default=32)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", help="write the rows and the summary here")
    ap.add_argument("--driving", action="store_true",
                    help="the runs hear while driving too; standing and driving listens are reported apart")
    args = ap.parse_args(argv)
    idx = list(range(args.start, args.start + args.count))
    with cf.ProcessPoolExecutor(args.workers, mp_context=mp.get_context("spawn")) as ex:
        rows = [r for listens in ex.map(run_one, idx, [args.driving] * len(idx)) for r in classify(listens)]
    parts = {"standing": [r for r in rows if not r["moving"]], "driving": [r for r in rows if r["moving"]]} \
        if args.driving else {"": rows}
    out = {}
    for name, part in parts.items():
        out[name or "all"] = s = summary(part)
        if s["n"]:
            _report(s, f"train {idx[0]}-{idx[-1]}" + (f", listens heard {name}" if name else ""))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"summary": out if args.driving else out["all"], "rows": rows}, f)
    return 0


def _report(s: dict, title: str) -> None:
    print(f"{title}: {s['n']} (listen, sounding victim) pairs, detected within {NEAR_DEG:g} deg "
          f"in {s['detected']:.2f}")
    for name in ("by_snr", "by_distance"):
        print(f"{name.replace('_', ' ')}: " + "; ".join(f"{b['bin']}: {b['detected']:.2f} of {b['n']}" for b in s[name]))
    d = s["dominant"]
    print(f"victims dominating the band (SNR > {DOMINANT_DB:g} dB): detected {d['detected']} of {d['n']}; the misses' "
          f"strongest detection: " + ", ".join(f"{k} {v}" for k, v in d["misses"].items()))
    for name, p in d["by_path"].items():
        print(f"  {name}: detected {p['detected']} of {p['n']}; misses: "
              + ", ".join(f"{k} {v}" for k, v in p["misses"].items()))
    print("errors of the detections that found her (deg, detection - truth): " + "; ".join(
        f"{b['bin']} ({b['n']}): elevation mean {b['el_mean']:+.1f} median {b['el_median']:+.1f}, azimuth mean "
        f"{b['az_mean']:+.1f} |median| {b['abs_az_median']:.1f}" for b in s["errors_by_distance"]))


if __name__ == "__main__":
    raise SystemExit(main())
