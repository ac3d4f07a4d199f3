"""CPU cost of whole rescue runs per simulated second, split into physics, acoustics, localization, the
runner's truth bookkeeping and the behaviour, with the behaviour's largest items on their own.

Runs ``ssl_sim/scenarios/light_rubble_three.toml`` (three callers in light rubble), seeds 0-3 by default,
headless, without rerun logging, on one core (the run is single-threaded; BLAS threads are capped at 1 before
numpy loads). The split is the runner's (``ssl_sim.runner``, ``time.process_time`` around each part): physics =
MuJoCo stepping and the simulated drive's sensors (ranges, bumper, gyro: hardware on the robot), acoustics =
rendering the microphone signals, localization = ``Localizer.locate``, truth = the runner's bookkeeping of the
true poses, detections and finds; the behaviour is the rest: voice evidence, the microphone health monitor, the
choice of option (paths, exploration, coverage), sound map, occupancy, motion loop and odometry.

Prints a table, each run's fingerprint (``RescueRun.fingerprint``: two versions whose runs print the same
fingerprints ran them the same to the bit, which is how a pure speed-up is checked) and one JSON line. Run:
``.venv/bin/python benchmarks/bench_scenario.py [--seeds 0,1,2,3]``.
Targets: the loop >= 30x faster than real time on one core, the behaviour <= 20 % of it.

``--fidelity``: what the scenario's acoustic shortcuts cost (``acoustics.obstacle_order``): each caller alone,
calling continuously, heard from 16 fixed poses 0.6-4 m away (seeded), localized with the scenario's
localizer; the strongest detection's azimuth error with the scenario's settings against the exact order-3
image-source model, pose by pose, and the rendering CPU time of both.
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
from contextlib import contextmanager  # noqa: E402

from _timing import time_calls  # noqa: E402
from _results import add_check_option, finish, load_avg, require_stored  # noqa: E402
import robot.rescue as rescue_module  # noqa: E402
from ssl_sim.runner import RescueRun  # noqa: E402
from ssl_sim.scenario import load_scenario  # noqa: E402

PARTS = ("physics", "acoustics", "localization", "truth", "other")
#: The runner's "other" is the behaviour (its voice evidence included); "truth" the runner's own bookkeeping;
#: physics includes the simulated drive's sensors (ranges, bumper, gyro), which are hardware on the robot.
LABELS = {"physics": "physics", "acoustics": "acoustics", "localization": "localization", "truth": "truth",
          "other": "behaviour"}
#: Inside the behaviour, timed on their own (CPU s): the hearing stage's voice evidence (MPDR beams, VAD, the
#: voice scan), the microphone health monitor, and the choice of option (paths, exploration, coverage).
ITEMS = ("voice evidence", "mic health", "options")



@contextmanager
def _instrument(run: RescueRun):
    """Time the behaviour's items (``ITEMS``) in ``run`` while inside; yields the accumulator it fills."""
    acc = dict.fromkeys(ITEMS, 0.0)
    listener = run.behaviour.listener
    time_calls(listener, "_evidence", acc, "voice evidence")
    time_calls(listener, "_scanned", acc, "voice evidence")
    time_calls(run.mic_health.monitor, "update", acc, "mic health")
    choose = rescue_module.choose
    time_calls(rescue_module, "choose", acc, "options")
    try:
        yield acc
    finally:
        rescue_module.choose = choose


def fidelity(sc, n_poses: int = 16) -> dict:
    """Azimuth errors (deg) of the strongest detection per fixed pose: the scenario's acoustic settings and the
    exact model (``obstacle_order`` unset), and the CPU seconds each spent rendering."""
    from dataclasses import replace

    import numpy as np

    from ssl_core.geometry import cube8
    from ssl_core.localizer import Localizer
    from ssl_sim.acoustics import AcousticSimulator, ArrayMount, RobotPose, SoundSource
    from ssl_sim.acoustics.voices import continuous_voice
    from ssl_sim.physics.robot_model import RobotModelConfig
    from ssl_sim.scoring import FreeSpaceGraph

    world = sc.world()
    sources = sc.sources(world, fs=sc.localizer.fs)
    cells = FreeSpaceGraph(world).cells
    mount = ArrayMount(height_m=RobotModelConfig().array_height)
    loc = Localizer(cube8(), replace(sc.localizer, n_sources=1))
    configs = {"scenario": sc.acoustic_config(), "exact": replace(sc.acoustic_config(), obstacle_order=None)}
    err = {k: [] for k in configs}
    cpu = dict.fromkeys(configs, 0.0)
    for k, s in enumerate(sources):
        src = SoundSource(s.position, continuous_voice("male", seed=k, fs=sc.localizer.fs), s.level_db_spl,
                          s.buried, s.kind, s.name)
        d = np.hypot(*(cells - np.asarray(s.position)[:2]).T)
        rng = np.random.default_rng([k, 0xF1DE])
        picks = rng.choice(np.flatnonzero((d >= 0.6) & (d <= 4.0)), n_poses, replace=False)
        poses = [RobotPose(float(cells[i, 0]), float(cells[i, 1]), yaw=float(rng.uniform(-np.pi, np.pi))) for i in picks]
        for name, cfg in configs.items():
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                sim = AcousticSimulator(world, cfg, sources=[src])
            for j, pose in enumerate(poses):
                mics = mount.mic_positions_world(pose)
                truth = (np.asarray(s.position) - mics.mean(axis=0)) @ pose.rotation  # array frame
                az = np.degrees(np.arctan2(truth[1], truth[0]))
                c = time.process_time()
                x = sim.listen(mics, 1.0, 1.0 + 1.7 * j)
                cpu[name] += time.process_time() - c
                dets = loc.locate(x).detections
                err[name].append(abs((dets[0].azimuth_deg - az + 180) % 360 - 180) if dets else np.nan)
    a, b = np.array(err["scenario"]), np.array(err["exact"])
    diff = np.abs(a - b)
    return {"poses": int(a.size), "settings": {k: v for k, v in sc.acoustics.items()},
            "az_median": [round(float(np.nanmedian(a)), 2), round(float(np.nanmedian(b)), 2)],
            "az_mean": [round(float(np.nanmean(a)), 2), round(float(np.nanmean(b)), 2)],
            "per_pose_absdiff_median": round(float(np.nanmedian(diff)), 2),
            "per_pose_within_1deg": round(float(np.mean(diff <= 1.0)), 3),
            "render_cpu_s": [round(cpu["scenario"], 2), round(cpu["exact"], 2)]}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default="light_rubble_three")
    ap.add_argument("--seeds", default="0,1,2,3", help="comma list of run seeds")
    ap.add_argument("--time-limit", type=float, default=None, help="simulated seconds (default: the scenario's)")
    ap.add_argument("--fidelity", action="store_true", help="only compare the scenario's acoustic shortcuts "
                    "with the exact model on fixed poses")
    add_check_option(ap)
    args = ap.parse_args(argv)
    if args.fidelity and args.check:
        ap.error("--check compares the loop's speed; --fidelity measures accuracy, which has no speed figure")
    require_stored("scenario", args.check)
    sc = load_scenario(args.scenario).with_overrides(time_limit_s=args.time_limit)
    if args.fidelity:
        f = fidelity(sc)
        print(f"bench_scenario --fidelity: {sc.name}, {f['poses']} fixed poses, acoustics {f['settings']}")
        print(f"azimuth error of the strongest detection, scenario settings / exact order 3: median "
              f"{f['az_median'][0]:.2f} / {f['az_median'][1]:.2f} deg, mean {f['az_mean'][0]:.2f} / "
              f"{f['az_mean'][1]:.2f} deg; per pose |difference| median {f['per_pose_absdiff_median']:.2f} deg, "
              f"{100 * f['per_pose_within_1deg']:.0f} % within 1 deg; rendering CPU {f['render_cpu_s'][0]:.2f} / "
              f"{f['render_cpu_s'][1]:.2f} s")
        print(json.dumps({"bench": "scenario_fidelity", "scenario": sc.name, **f}))
        return finish("scenario_fidelity", {k: v for k, v in f.items() if isinstance(v, (int, float))})
    rows = []
    for seed in [int(s) for s in args.seeds.split(",")]:
        t = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            run = RescueRun(sc, seed=seed)
        setup = time.perf_counter() - t
        with _instrument(run) as items:
            c = time.process_time()
            r = run.run()
            cpu = time.process_time() - c
        w = r["wall_clock_s"]
        rows.append({"seed": seed, "sim_s": r["sim_time_s"], "setup_s": round(setup, 3), "loop_s": w["loop"],
                     **{p: w[p] for p in PARTS}, "found": f"{r['n_found']}/{r['n_victims']}",
                     "listens": r["n_listens"], "cpu_s": cpu, "cpu_parts": w["cpu"], "items": items,
                     "fingerprint": r["fingerprint"]})
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
    cpu_per = {p: sum(r["cpu_parts"][p] for r in rows) / sim for p in PARTS}
    cpu_loop = sum(r["cpu_parts"]["loop"] for r in rows)
    print("CPU s per simulated s by part: " + ", ".join(f"{LABELS[p]} {cpu_per[p]:.4f} "
                                                        f"({100 * cpu_per[p] * sim / cpu_loop:.0f} %)" for p in PARTS)
          + f"; load average {load_avg()[0]:.2f}")
    cpu_items = {k: sum(r["items"][k] for r in rows) / sim for k in ITEMS}
    rest = cpu_per["other"] - sum(cpu_items.values())
    print("behaviour by item, CPU s per simulated s: " + ", ".join(f"{k} {v:.4f}" for k, v in cpu_items.items())
          + f", the rest (sound map, occupancy, motion loop, odometry, pursuits) {rest:.4f}")
    print("fingerprints (the same in two versions: the same runs to the bit): "
          + ", ".join(f"seed {r['seed']} {r['fingerprint']}" for r in rows))
    print(json.dumps({"bench": "scenario", "scenario": sc.name, "seeds": [r["seed"] for r in rows],
                      "sim_s": round(sim, 2), "wall_per_sim_s": round(loop / sim, 4),
                      "realtime_factor": round(sim / loop, 2), "cpu_per_sim_s": round(cpu / sim, 4),
                      "cpu_realtime_factor": round(sim / cpu, 2), "loadavg_1min": os.getloadavg()[0],
                      "per_sim_s": {p: round(per[p], 4) for p in PARTS},
                      "found": [r["found"] for r in rows], "setup_s": [r["setup_s"] for r in rows]}))
    figures = {"sim_s": round(sim, 2), "cpu_per_sim_s": round(cpu / sim, 4), "cpu_x_realtime": round(sim / cpu, 2),
               "wall_x_realtime": round(sim / loop, 2), **{f"{p}_wall_per_sim_s": round(per[p], 4) for p in PARTS},
               **{f"{LABELS[p]}_cpu_s_per_sim_s": round(cpu_per[p], 4) for p in PARTS},
               "behaviour_share_cpu": round(cpu_per["other"] * sim / cpu_loop, 3),
               **{f"behaviour_{k.replace(' ', '_')}_cpu_s_per_sim_s": round(v, 4) for k, v in cpu_items.items()},
               "victims_found": sum(int(r["found"].split("/")[0]) for r in rows),
               "victims": sum(int(r["found"].split("/")[1]) for r in rows)}
    runs = "| seed | simulated s | found | fingerprint |\n|---|---|---|---|\n" + "".join(
        f"| {r['seed']} | {r['sim_s']} | {r['found']} | {r['fingerprint']} |\n" for r in rows)
    return finish("scenario", figures, {"runs": runs}, check=args.check, better={"cpu_x_realtime": "higher"})


if __name__ == "__main__":
    raise SystemExit(main())
