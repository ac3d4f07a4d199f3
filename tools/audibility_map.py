"""Where can the robot hear each caller? Standing 1 s listens on a grid of the reachable floor of a scenario.

The robot is placed (kinematically, at rest) at every ``--step`` m grid point of the floor reachable from its
start, and listens ``--listens`` times with the scenario's localizer (``Localizer.locate`` on the simulated
array, as ``robot.listening`` does). A source counts as detected in a listen when a detection lies within
``--tolerance`` deg of its true direction (array frame); only listens in which a caller sounds (>= 10 % of the
block) count for her. Prints, per caller, the detection rate by her distance and by the distance of the
loudest interferer; then one JSON line. This separates the limits of hearing (no listen position hears her)
from those of the behaviour (it never went where she is heard).

Measured (dense_pump, step 0.5 m, 6 listens, 75 points, 15 deg): the mid-room caller within 1.5 m was detected in
27/54 of her sounding listens with the pump over 2.5 m away, 2/16 with it closer, 12/210 from farther than 1.5 m;
the caller in the void under the slab in 7/35 within 1.5 m and 9/234 beyond.

With ``--scan-s 3`` every listen lasts 3 s: the 1 s figures are its first second, beside SRP-PHAT on each of its
three seconds (today's 1 s listens over the same time) and the voice scan (``robot.hearing``, beams every 15 deg,
a fresh chain per listen, listening all the time) scored after each ``--settle``. Measured (dense_pump, step
0.5 m, 3 listens of 3 s, 225 listens, 254 s CPU), detected / sounding listens, SRP-PHAT 1 s x 3 -> scan settled
after 1 s: the mid-room caller within 1.5 m, pump over 2.5 m away, 21/42 -> 27/42 (settled after 1.5 / 2 s:
20 / 15); pump closer 3/11 -> 4/11; 1.5-2.5 m from her 5/34 -> 6/34; beyond 2.5 m 14/121 -> 12/121; the caller
under the slab within 1.5 m 13/27 -> 11/27, 1.5-2.5 m 5/42 -> 7/42, beyond 8/141 -> 9/141; 98 of the scan's
435 detections near no caller. The scan does not hear either caller from farther away.

Per point (``--per-point``; measured on dense_pump the same way, 6 listens per point on the 0.3 m
grid's points within 2.6 m of the caller in the void): she is detected only from north of her slab, in 1-3 of 4-6 sounding listens per point at
y = 4.05-4.65 m, x = 0.45-2.25 m, and 4 of 4 at (2.25, 3.75); from her east and south in none.

Run: ``.venv/bin/python tools/audibility_map.py dense_pump [--step 0.5] [--listens 6] [--scan-s 3]
[--points X,Y;X,Y] [--per-point]``
"""
from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
from scipy import ndimage

from ssl_sim.backends import array_frame_directions
from ssl_sim.physics.scene_gen import free_space_grid
from ssl_sim.runner import RescueRun
from ssl_sim.scenario import load_scenario

BANDS = ((0.0, 1.5), (1.5, 2.5), (2.5, 99.0))   # m


def _sounding(run: RescueRun, n0: int, n: int, min_share: float) -> np.ndarray:
    """Per source: active (10 ms frames with RMS > 0.05) in at least ``min_share`` of samples n0..n0+n."""
    out = []
    for s in run.sources:
        fr = s.signal.render(n0, n)[: n // 160 * 160].reshape(-1, 160)
        out.append(float(np.mean(np.sqrt(np.mean(fr**2, axis=1)) > 0.05)) >= min_share)
    return np.array(out)


def _by_band(rows: list, k: int, sounding, hit) -> dict[str, list[int]]:
    """[detected, sounding] listens of caller ``k`` per band of her distance and of the machine's."""
    res = {}
    for lo, hi in BANDS:
        for mlo, mhi in ((0.0, 2.5), (2.5, 99.0)):
            sel = [r for r in rows if sounding(r) and lo < r[0][k] <= hi and mlo < r[1] <= mhi]
            res[f"{lo}-{hi} m, machine {mlo}-{mhi} m"] = [int(sum(hit(r) for r in sel)), len(sel)]
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario", nargs="?", default="dense_pump", help="shipped name or .toml (default dense_pump)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--step", type=float, default=0.5, help="grid spacing (m)")
    ap.add_argument("--listens", type=int, default=6, help="listens per grid point")
    ap.add_argument("--tolerance", type=float, default=15.0, help="detection within this angle (deg)")
    ap.add_argument("--scan-s", type=float, default=0.0,
                    help="also listen this long (s) per listen with the voice scan (robot.hearing) and score its "
                         "detections after each of --settle (azimuth only: the scan is on the horizon)")
    ap.add_argument("--settle", default="1,1.5,2", help="scan settle times (s) scored, comma-separated")
    ap.add_argument("--points", default="", help="only grid points within 0.3 m of these x,y;x,y (m)")
    ap.add_argument("--per-point", action="store_true",
                    help="also print, per grid point, each caller's detected / sounding 1 s listens")
    a = ap.parse_args()
    run = RescueRun(load_scenario(a.scenario), seed=a.seed)
    w, fs = run.world, run.audio.sample_rate
    free, _ = free_space_grid(w, res=0.05)
    labels, _ = ndimage.label(free)
    x0, y0, _ = w.robot_start
    reach = labels == labels[int(x0 // 0.05), int(y0 // 0.05)]
    lx, ly, _ = w.room.size
    points = [(x, y) for x in np.arange(a.step / 2, lx, a.step) for y in np.arange(a.step / 2, ly, a.step)
              if reach[int(x // 0.05), int(y // 0.05)]]
    if a.points:
        only = np.array([[float(v) for v in p.split(",")] for p in a.points.split(";")])
        points = [p for p in points if np.min(np.hypot(*(only - p).T)) <= 0.3]
    names = [s.name for s in run.sources]
    kinds = [s.kind for s in run.sources]
    pos = np.array([s.position for s in run.sources])
    loud = [k for k in range(len(names)) if k >= run.n_victims]
    machine = max(loud, key=lambda k: run.sources[k].level_db_spl) if loud else None
    cos_tol = math.cos(math.radians(a.tolerance))
    rows = []   # (caller distances (n,), machine distance, sounding (n,), detected (n,), scan hits {settle: (n,)})
    settles = [float(v) for v in a.settle.split(",")] if a.scan_s > 0 else []
    scan_false = dict.fromkeys(settles, 0)   # scan detections after the settle near no caller
    scan_total = dict.fromkeys(settles, 0)
    if settles:
        from robot.hearing import Hearing, HearingConfig
        from robot.vad import SileroVad
        vad = SileroVad(sample_rate=8000)
        mics = np.asarray(run.localizer.geometry.positions, float)
        hcfg = HearingConfig(scan_step_deg=15.0, scan_settle_s=0.0, vad_on_s=1.0, vad_period_s=1.0)
    t0 = time.process_time()
    for x, y in points:
        for _ in range(a.listens):
            run.robot.place(x, y, 0.0)
            n0 = int(round(run.robot.time * fs))
            n = int(round(max(1.0, a.scan_s) * fs))
            block = run.audio.read(n)
            origin, rot = run.robot.array_pose()
            az, el, dist = array_frame_directions(origin, rot, pos)
            truth = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
            scan_hits = {}
            if settles:   # the scan of a fresh Hearing on the whole block, 0.1 s at a time, as a listen would feed it
                h = Hearing(mics, fs, hcfg, vad=vad)
                xs = block.samples
                found = []   # (time s, azimuth rad)
                for k0 in range(0, xs.shape[-1], fs // 10):
                    h.update(xs[:, k0:k0 + fs // 10], [], (k0 + fs // 10) / fs)
                    found += [((k0 + fs // 10) / fs, d.azimuth) for d in h.voice_detections()]
                near = np.array([[abs(math.remainder(f - t, 2 * math.pi)) <= math.radians(a.tolerance)
                                  for t in az[: run.n_victims]] for _, f in found]).reshape(-1, run.n_victims)
                # the same time spent in today's 1 s listens: SRP-PHAT on each whole second of the block
                hit_srp = np.zeros(run.n_victims, bool)
                for k0 in range(0, xs.shape[-1] - fs + 1, fs):
                    ud = np.array([d.direction for d in run.localizer.locate(xs[:, k0:k0 + fs]).detections]).reshape(-1, 3)
                    if len(ud):
                        hit_srp |= (ud @ truth[: run.n_victims].T >= cos_tol).any(axis=0)
                scan_hits["srp"] = hit_srp
                for st in settles:
                    after = np.array([t > st for t, _ in found], bool)
                    scan_hits[st] = near[after].any(axis=0)
                    scan_total[st] += int(after.sum())
                    scan_false[st] += int((~near[after].any(axis=1)).sum())
            dets = run.localizer.locate(block.samples[:, :fs]).detections
            u = np.array([d.direction for d in dets]).reshape(-1, 3)
            hit = (u @ truth.T >= cos_tol).any(axis=0) if len(u) else np.zeros(len(names), bool)
            # sounding in the first second (the 1 s listen's); for the scan, a second's worth anywhere in the block
            rows.append((dist, dist[machine] if machine is not None else 98.0,  # no machine: the farthest band
                         _sounding(run, n0, fs, 0.1), hit,
                         scan_hits, _sounding(run, n0, n, 0.1 * fs / n), (x, y)))
    cpu = time.process_time() - t0
    out = {"scenario": a.scenario, "points": len(points), "listens": len(rows), "cpu_s": round(cpu, 1), "callers": {}}
    print(f"{a.scenario}: {len(points)} points x {a.listens} listens, {cpu:.0f} s CPU; detected within "
          f"{a.tolerance:g} deg / sounding listens"
          + (f"; machine = {names[machine]}" if machine is not None else ""))
    for k in range(run.n_victims):
        res = _by_band(rows, k, lambda r: r[2][k], lambda r: r[3][k])
        out["callers"][names[k]] = res
        print(f"  {names[k]} ({kinds[k]}): " + "; ".join(f"{key}: {h}/{n}" for key, (h, n) in res.items()))
        for st in (["srp"] + settles) if settles else []:
            sres = _by_band(rows, k, lambda r: r[5][k], lambda r: r[4][st][k])
            label = (f"SRP-PHAT 1 s listens for {a.scan_s:g} s" if st == "srp"
                     else f"scan {a.scan_s:g} s, settle {st:g} s")
            out["callers"][f"{names[k]} {label}"] = sres
            print(f"    {label}: "
                  + "; ".join(f"{key}: {h}/{n}" for key, (h, n) in sres.items()))
    if a.per_point:
        for x, y in points:
            at = [r for r in rows if r[6] == (x, y)]
            print(f"  point ({x:.2f}, {y:.2f}): " + "; ".join(
                f"{names[k]} {sum(bool(r[3][k]) for r in at if r[2][k])}/{sum(bool(r[2][k]) for r in at)}"
                for k in range(run.n_victims)))
    for st in settles:
        out[f"scan settle {st:g} s detections, near no caller"] = [scan_total[st], scan_false[st]]
        print(f"  scan settle {st:g} s: {scan_total[st]} detections, {scan_false[st]} near no caller")
    print(json.dumps(out))


if __name__ == "__main__":
    main()
