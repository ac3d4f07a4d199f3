"""Cost of the acoustic simulation: image-source search per order and one listen step.

Listen step = 3 victims, 8 microphones (cube8 on the robot), 1 s of audio, int16 out,
in rubble rooms from the physics scene generator (named scenes) and a 3-victim copy of
the empty lab. Three cases: first call (builds diffuse tails), same pose again (RIRs
cached: convolution + noise + ADC only), and a new pose (image sources and RIRs redone).

Listen steps are timed with edge diffraction on and off (``AcousticConfig.diffraction``): its cost is
the difference at a new pose (the only case that recomputes paths). Times are CPU seconds of this
process (``time.process_time``; the machine may be shared).

Prints a table and one JSON line. Run: ``.venv/bin/python benchmarks/bench_acoustics.py [--quick]``
(``--quick``: the light-rubble scene only, image-source orders 1-2).
"""
from __future__ import annotations

import argparse
import json
import platform
import time
import warnings
from dataclasses import replace

import numpy as np
from tqdm import tqdm

from _results import add_check_option, finish, require_stored
from ssl_sim.acoustics import AcousticConfig, AcousticSimulator, RobotPose
from ssl_sim.acoustics.scene import AcousticScene
from ssl_sim.world import VictimSite


def _timed(fn, repeat: int = 1) -> float:
    """Best CPU time (s) of ``repeat`` calls."""
    best = np.inf
    for _ in range(repeat):
        t = time.process_time()
        fn()
        best = min(best, time.process_time() - t)
    return best


def worlds():
    from ssl_sim.physics.scene_gen import named_scene

    def three_victims(w):
        """Top up to 3 victims at free points of the room (the listen-step case of the task)."""
        extra = [VictimSite(p) for p in ((5.5, 4.5, 0.3), (1.0, 1.2, 0.5), (0.6, 4.4, 0.4), (5.4, 0.6, 0.4))
                 if w.inside_obstacle(p, margin=0.05, include_climbable=True) is None]
        return replace(w, victims=(w.victims + tuple(extra))[:3])

    return {"empty_lab": three_victims(named_scene("empty_lab")),
            "light_rubble": three_victims(named_scene("light_rubble")),
            "dense_collapsed_room": three_victims(named_scene("dense_collapsed_room"))}


def ism_costs(world, orders=(1, 2, 3), max_seconds: float = 20.0) -> dict:
    """CPU cost of the image-source search per source and order (stops after an order slower than max_seconds / 4)."""
    scene = AcousticScene(world)
    rx = np.array([world.robot_start[0], world.robot_start[1], 0.30])
    out = {}
    for order in orders:
        src = world.victims[0].position
        dt = _timed(lambda: scene.image_sources(src, rx, order))
        n = scene.image_sources(src, rx, order).order.size
        out[order] = {"ms_per_source": dt * 1e3, "visible_images": int(n)}
        if dt > max_seconds / 4:
            break
    return {"surfaces": len(scene.surfaces), "obstacle_faces": len(scene.obstacle_surfaces),
            "rt60_1k_s": float(scene.rt60()[3]), "orders": out}


def listen_costs(world, diffraction: bool = True) -> dict:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sim = AcousticSimulator(world, AcousticConfig(seed=1, diffraction=diffraction))
    spent = {"s": 0.0, "calls": 0, "arrivals": 0}
    inner = sim._diffracted

    def timed_diffracted(*a):  # the edge-path search alone
        t = time.process_time()
        pos, fac = inner(*a)
        spent["s"] += time.process_time() - t
        spent["calls"] += 1
        spent["arrivals"] += len(pos)
        return pos, fac

    sim._diffracted = timed_diffracted
    x0, y0, yaw0 = world.robot_start
    pose = RobotPose(x0, y0, yaw=yaw0)
    first = _timed(lambda: sim.listen_pose(pose, 1.0, t0=0.0))
    same = _timed(lambda: sim.listen_pose(pose, 1.0, t0=1.0), repeat=3)
    new = []
    for k in range(1, 4):  # moves of 6 cm and 0.1 rad: new visibility cell, new RIRs
        p = RobotPose(x0 + 0.06 * k * np.cos(yaw0), y0 + 0.06 * k * np.sin(yaw0), yaw=yaw0 + 0.1 * k)
        new.append(_timed(lambda p=p: sim.listen_pose(p, 1.0, t0=1.0 + k)))
    return {"diffraction": diffraction, "ism_order_used": sim.ism_order, "rir_length_s": sim.rir_length / sim.config.fs,
            "n_sources": len(sim.sources), "first_s": first, "same_pose_s": same, "new_pose_s": float(np.median(new)),
            "edge_search_ms_per_source_pose": 1e3 * spent["s"] / max(1, spent["calls"]),
            "diffracted_arrivals_per_source_pose": spent["arrivals"] / max(1, spent["calls"])}


def main() -> int:
    ap = argparse.ArgumentParser(description="acoustic simulation cost")
    ap.add_argument("--quick", action="store_true", help="light rubble only, orders 1-2")
    add_check_option(ap)
    args = ap.parse_args()
    require_stored("acoustics", args.check)
    ws = worlds()
    if args.quick:
        ws = {"light_rubble": ws["light_rubble"]}
    orders = (1, 2) if args.quick else (1, 2, 3)
    results: dict = {}
    cases = [(n, d) for n in ws for d in (False, True)]
    with tqdm(total=len(ws) + len(cases), desc="bench_acoustics", unit="case") as bar:
        for name, w in ws.items():
            results[name] = {"ism": ism_costs(w, orders)}
            bar.update()
        for name, d in cases:
            results[name]["listen_diffraction" if d else "listen_no_diffraction"] = listen_costs(ws[name], d)
            bar.update()
    print(f"{'world':22s} {'surf':>5s} {'RT60@1k':>8s}  ISM ms/source (order: ms, images)")
    for name in ws:
        ism = results[name]["ism"]
        orders_txt = ", ".join(f"{o}: {v['ms_per_source']:.1f} ms/{v['visible_images']}" for o, v in ism["orders"].items())
        print(f"{name:22s} {ism['surfaces']:5d} {ism['rt60_1k_s']:7.2f}s  {orders_txt}")
    print()
    print(f"{'world':22s} {'diffr.':>6s} {'order':>5s} {'RIR s':>6s} {'first':>8s} {'same pose':>10s} {'new pose':>9s}"
          "   (3 victims, 8 mics, 1 s; CPU s)")
    for name, d in cases:
        lc = results[name]["listen_diffraction" if d else "listen_no_diffraction"]
        print(f"{name:22s} {'on' if d else 'off':>6s} {lc['ism_order_used']:5d} {lc['rir_length_s']:6.2f} "
              f"{lc['first_s']:7.3f}s {lc['same_pose_s']:9.3f}s {lc['new_pose_s']:8.3f}s"
              + (f"   edge search {lc['edge_search_ms_per_source_pose']:.2f} ms/source/pose, "
                 f"{lc['diffracted_arrivals_per_source_pose']:.1f} diffracted arrivals" if d else ""))
    results["machine"] = platform.processor() or platform.machine()
    results["quick"] = args.quick
    print(json.dumps({"bench": "acoustics", **results}))
    figures = {}
    for name in ws:
        for o, v in results[name]["ism"]["orders"].items():
            figures[f"ism_ms_per_source order {o} | {name}"] = v["ms_per_source"]
        for d in (False, True):
            lc = results[name]["listen_diffraction" if d else "listen_no_diffraction"]
            tag = f"{name}, diffraction {'on' if d else 'off'}"
            figures[f"listen_new_pose_cpu_s | {tag}"] = lc["new_pose_s"]
            figures[f"listen_same_pose_cpu_s | {tag}"] = lc["same_pose_s"]
            if d:
                figures[f"edge_search_ms_per_source_pose | {name}"] = lc["edge_search_ms_per_source_pose"]
    return finish("acoustics", figures, check=args.check,
                  better={k: "lower" for k in figures if k.startswith("listen_new_pose_cpu_s")})


if __name__ == "__main__":
    raise SystemExit(main())
