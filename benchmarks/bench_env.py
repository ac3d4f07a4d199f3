"""Speed of SSLRescue-v0: environment steps per second, and fast-vs-full localization fidelity.

- one environment on one core (BLAS limited to one thread), fast and full fidelity: steps per CPU second over
  random actions in the default generated scene (after the episode's build), with the time per
  step split into physics (MuJoCo), acoustic rendering, SRP-PHAT localization and the rest;
  plus the cost of a reset that builds a new scene;
- a 2-process ``gymnasium.vector.AsyncVectorEnv`` (fast): environment steps per second summed
  over both workers (the machine's two cores; shared with whatever else runs);
- fidelity: localization errors of the observation's strongest detection, fast vs full, on the
  same poses (``ssl_sim.envs.fidelity``); and the kinematic (fast) against the dynamic (full) drive:
  pose after one step from rest with the same action.

Prints a table and one JSON line. Run: ``.venv/bin/python benchmarks/bench_env.py`` (``--quick``
for fewer steps and poses).
"""
from __future__ import annotations

import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")  # one core per environment

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
from collections import defaultdict  # noqa: E402

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402

from _timing import time_calls  # noqa: E402
from _results import add_check_option, finish, load_avg, require_stored  # noqa: E402
from ssl_sim.envs import EnvConfig, SSLRescueEnv  # noqa: E402
from ssl_sim.envs.fidelity import compare_fidelities, fidelity_summary  # noqa: E402



def single(fidelity: str, steps: int, seed: int = 0) -> dict:
    env = SSLRescueEnv(EnvConfig(fidelity=fidelity))
    t = time.perf_counter()
    env.reset(seed=seed)
    build = time.perf_counter() - t
    acc: dict = defaultdict(float)
    ep = env._ep
    time_calls(ep.robot, "step", acc, "physics")
    time_calls(env, "_drive_kinematic", acc, "physics")  # fast fidelity: kinematic moves + bumper checks
    time_calls(ep.acoustics, "listen", acc, "acoustics")
    time_calls(env.localizer, "locate", acc, "localization")
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(steps)]
    done = 0
    t, c = time.perf_counter(), time.process_time()
    for a in actions:
        _, _, term, _, _ = env.step(a)
        done += 1
        if term:
            env.reset()
    wall = time.perf_counter() - t
    cpu = time.process_time() - c
    # resets that build a new scene (new seeds) vs one that reuses the cached build
    t = time.perf_counter()
    for s in range(1000, 1003):
        env.reset(seed=s)
    new_scene = (time.perf_counter() - t) / 3
    env.close()
    ms = {k: 1e3 * v / done for k, v in acc.items()}
    ms["other"] = 1e3 * cpu / done - sum(ms.values())
    return {"fidelity": fidelity, "steps": done, "steps_per_s": done / cpu, "wall_steps_per_s": done / wall,
            "ms_per_step": 1e3 * cpu / done,
            "ms_breakdown": {k: round(v, 2) for k, v in ms.items()}, "first_reset_s": build,
            "reset_new_scene_s": new_scene}


def drive_fidelity(n: int = 12) -> dict:
    """Kinematic (fast) against dynamic (full) drive: the same random action from the same start pose,
    one step; pose difference after it (position m, yaw deg) against the distance driven."""
    envs = {f: SSLRescueEnv(EnvConfig(fidelity=f)) for f in ("fast", "full")}
    rng = np.random.default_rng(7)
    dpos, dyaw, moved = [], [], []
    try:
        for k in range(n):
            a = rng.uniform(-1, 1, 3).astype(np.float32)
            poses = {}
            for f, e in envs.items():
                e.reset(seed=200 + k)
                p0 = e._ep.robot.pose()
                e.step(a)
                p = e._ep.robot.pose()
                poses[f] = (p.x, p.y, p.yaw, p0.x, p0.y)
            (x1, y1, w1, x0, y0), (x2, y2, w2, _, _) = poses["fast"], poses["full"]
            dpos.append(float(np.hypot(x1 - x2, y1 - y2)))
            dyaw.append(abs(float(np.degrees((w1 - w2 + np.pi) % (2 * np.pi) - np.pi))))
            moved.append(float(np.hypot(x2 - x0, y2 - y0)))
    finally:
        for e in envs.values():
            e.close()
    return {"steps": n, "pos_diff_median_m": float(np.median(dpos)), "pos_diff_max_m": float(np.max(dpos)),
            "yaw_diff_median_deg": float(np.median(dyaw)), "yaw_diff_max_deg": float(np.max(dyaw)),
            "full_moved_median_m": float(np.median(moved))}


def vector(steps: int, workers: int = 2) -> dict:
    fns = [lambda: gym.make("ssl_sim.envs:SSLRescue-v0", fidelity="fast") for _ in range(workers)]
    venv = gym.vector.AsyncVectorEnv(fns)
    try:
        venv.reset(seed=list(range(workers)))
        venv.action_space.seed(0)
        for _ in range(3):  # warm up (voice loops, caches)
            venv.step(venv.action_space.sample())
        t = time.perf_counter()
        for _ in range(steps):
            venv.step(venv.action_space.sample())
        wall = time.perf_counter() - t
    finally:
        venv.close()
    return {"workers": workers, "vector_steps": steps, "env_steps_per_s": workers * steps / wall}


def main() -> int:
    ap = argparse.ArgumentParser(description="SSLRescue-v0 speed and fidelity")
    ap.add_argument("--quick", action="store_true", help="fewer steps and poses")
    add_check_option(ap)
    args = ap.parse_args()
    require_stored("env", args.check)
    n_fast, n_full, n_vec = (40, 15, 20) if args.quick else (200, 60, 100)
    seeds, poses = (range(100, 104), 6) if args.quick else (range(100, 116), 10)

    fast = single("fast", n_fast)
    full = single("full", n_full)
    vec = vector(n_vec)
    drive = drive_fidelity(6 if args.quick else 20)
    t = time.perf_counter()
    fid = fidelity_summary(compare_fidelities(EnvConfig(), seeds, poses))
    fid_wall = time.perf_counter() - t

    print(f"SSLRescue-v0, default generated scene, 1 victim; step = 0.5 s drive + 0.1 s settle + 0.25 s listen "
          f"(0.85 s simulated); {platform.processor() or platform.machine()}, load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print("CPU time of this process (the machine is shared: wall-clock steps/s in the JSON line)")
    print("| case | steps/s (CPU) | ms/step | physics | acoustics | localization | other | new-scene reset (s) |")
    print("|---|---|---|---|---|---|---|---|")
    for r in (fast, full):
        b = r["ms_breakdown"]
        print(f"| {r['fidelity']}, 1 env, 1 core | {r['steps_per_s']:.1f} | {r['ms_per_step']:.1f} | "
              f"{b.get('physics', 0):.1f} | {b.get('acoustics', 0):.1f} | {b.get('localization', 0):.1f} | "
              f"{b['other']:.1f} | {r['reset_new_scene_s']:.2f} |")
    print(f"| fast, AsyncVectorEnv x{vec['workers']} | {vec['env_steps_per_s']:.1f} (sum, wall) | | | | | | |")
    print(f"(load average {load_avg()[0]:.2f} after the speed runs)")
    print()
    print(f"Drive, kinematic (fast) vs dynamic (full), one step from rest with the same random action "
          f"({drive['steps']} steps; full drove {drive['full_moved_median_m']:.3f} m median): position differs "
          f"{drive['pos_diff_median_m']:.3f} m median ({drive['pos_diff_max_m']:.3f} max), yaw "
          f"{drive['yaw_diff_median_deg']:.1f} deg median ({drive['yaw_diff_max_deg']:.1f} max)")
    print(f"Fidelity on {fid['poses']} poses ({fid['both_detected']} detected by both; 0.5-3.5 m from the victim, "
          f"{fid_wall:.0f} s): azimuth error mean fast {fid['az_mean_fast']:.2f} / full {fid['az_mean_full']:.2f} deg "
          f"(diff {fid['az_mean_diff']:.2f}), median {fid['az_median_fast']:.2f} / {fid['az_median_full']:.2f} deg "
          f"(diff {fid['az_median_diff']:.2f}); per pose |fast - full| median {fid['az_per_pose_absdiff_median']:.2f}, "
          f"p90 {fid['az_per_pose_absdiff_p90']:.2f} deg, {100 * fid['az_per_pose_within_1deg']:.0f} % within 1 deg; "
          f"detection rate {fid['detection_rate_fast']:.2f} / {fid['detection_rate_full']:.2f}")
    line = {"benchmark": "bench_env", "fast": fast, "full": full, "vector": vec, "drive": drive,
            "fidelity": {k: (round(v, 3) if isinstance(v, float) else v) for k, v in fid.items()},
            "loadavg_1min": os.getloadavg()[0], "cpus": os.cpu_count(), "quick": args.quick}
    print(json.dumps(line))
    figures = {"fast_steps_per_cpu_s": fast["steps_per_s"], "fast_ms_per_step": fast["ms_per_step"],
               **{f"fast_{k}_ms_per_step": v for k, v in fast["ms_breakdown"].items()},
               "full_steps_per_cpu_s": full["steps_per_s"], "full_ms_per_step": full["ms_per_step"],
               "vector_env_steps_per_wall_s": vec["env_steps_per_s"], "vector_workers": vec["workers"],
               "drive_pos_diff_median_m": drive["pos_diff_median_m"],
               **{f"fidelity_{k}": v for k, v in fid.items() if isinstance(v, (int, float))}}
    return finish("env", figures, check=args.check,
                  better={"fast_steps_per_cpu_s": "higher", "full_steps_per_cpu_s": "higher"})


if __name__ == "__main__":
    raise SystemExit(main())
