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

Run: ``.venv/bin/python benchmarks/bench_audibility.py dense_pump [--step 0.5] [--listens 6]``
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scenario")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--step", type=float, default=0.5, help="grid spacing (m)")
    ap.add_argument("--listens", type=int, default=6, help="listens per grid point")
    ap.add_argument("--tolerance", type=float, default=15.0, help="detection within this angle (deg)")
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
    names = [s.name for s in run.sources]
    kinds = [s.kind for s in run.sources]
    pos = np.array([s.position for s in run.sources])
    loud = [k for k in range(len(names)) if k >= run.n_victims]
    machine = max(loud, key=lambda k: run.sources[k].level_db_spl) if loud else None
    cos_tol = math.cos(math.radians(a.tolerance))
    rows = []   # (caller distances (n,), machine distance, sounding (n,), detected (n,))
    t0 = time.process_time()
    for x, y in points:
        for _ in range(a.listens):
            run.robot.place(x, y, 0.0)
            n0 = int(round(run.robot.time * fs))
            block = run.audio.read(fs)
            origin, rot = run.robot.array_pose()
            az, el, dist = array_frame_directions(origin, rot, pos)
            truth = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
            dets = run.localizer.locate(block.samples).detections
            u = np.array([d.direction for d in dets]).reshape(-1, 3)
            hit = (u @ truth.T >= cos_tol).any(axis=0) if len(u) else np.zeros(len(names), bool)
            sounding = []
            for s in run.sources:
                fr = s.signal.render(n0, fs)[: fs // 160 * 160].reshape(-1, 160)
                sounding.append(float(np.mean(np.sqrt(np.mean(fr**2, axis=1)) > 0.05)) >= 0.1)
            rows.append((dist, dist[machine] if machine is not None else math.inf, np.array(sounding), hit))
    cpu = time.process_time() - t0
    out = {"scenario": a.scenario, "points": len(points), "listens": len(rows), "cpu_s": round(cpu, 1), "callers": {}}
    print(f"{a.scenario}: {len(points)} points x {a.listens} listens, {cpu:.0f} s CPU; detected within "
          f"{a.tolerance:g} deg / sounding listens"
          + (f"; machine = {names[machine]}" if machine is not None else ""))
    for k in range(run.n_victims):
        res = {}
        for lo, hi in BANDS:
            for mlo, mhi in ((0.0, 2.5), (2.5, 99.0)):
                sel = [r for r in rows if r[2][k] and lo < r[0][k] <= hi and mlo < r[1] <= mhi]
                res[f"{lo}-{hi} m, machine {mlo}-{mhi} m"] = [int(sum(r[3][k] for r in sel)), len(sel)]
        out["callers"][names[k]] = res
        print(f"  {names[k]} ({kinds[k]}): " + "; ".join(f"{key}: {h}/{n}" for key, (h, n) in res.items()))
    print(json.dumps(out))


if __name__ == "__main__":
    main()
