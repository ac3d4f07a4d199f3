"""Baseline navigation policies on SSLRescue-v0: random vs the rescue behaviour's map-planning policy.

Each policy runs the same N seeded episodes (``env.reset(seed=s)`` for s = seed_start ..
seed_start + N - 1: the same generated scene, voices and noise for both policies); reported per
policy: success rate (every victim found before the time limit), SPL (success weighted by
shortest path / path taken, Anderson et al. 2018), fraction of victims found, mean episode
length (steps and simulated seconds), mean number of steps with the bumper pressed, mean return.

Writes ``policy_baselines.md`` (set-up + table), ``policy_baselines.csv`` (summary) and
``policy_baselines_episodes.csv`` (per episode) to ``--out`` (default experiments/results/),
prints the table and one JSON line. Run::

    .venv/bin/python experiments/policy_baselines.py --episodes 20
    .venv/bin/python experiments/policy_baselines.py --episodes 10 --n-victims 2 --max-steps 300
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

import gymnasium as gym

from ssl_sim.envs import EnvConfig
from ssl_sim.envs.evaluation import evaluate, markdown_table, summarize, write_csv
from ssl_sim.envs.policies import MapPlanningPolicy, RandomPolicy

OUT = Path(__file__).resolve().parent / "results"


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--episodes", type=int, default=20, help="seeded episodes per policy")
    ap.add_argument("--seed-start", type=int, default=0)
    ap.add_argument("--max-steps", type=int, default=150, help="time limit in steps (0.85 s each)")
    ap.add_argument("--fidelity", choices=("fast", "full"), default="fast")
    ap.add_argument("--n-victims", type=int, default=1)
    ap.add_argument("--scenario", default=None, help="a ssl_sim/scenarios/*.toml name or path instead of generated scenes")
    ap.add_argument("--out", type=Path, default=OUT)
    args = ap.parse_args(argv)
    if args.episodes < 1 or args.max_steps < 1:
        ap.error("--episodes and --max-steps: expected >= 1")

    cfg = EnvConfig(fidelity=args.fidelity, n_victims=args.n_victims, scenario=args.scenario)
    seeds = range(args.seed_start, args.seed_start + args.episodes)
    t0 = time.perf_counter()
    results = evaluate(lambda: gym.make("ssl_sim.envs:SSLRescue-v0", config=cfg, max_episode_steps=args.max_steps),
                       {"random": lambda env: RandomPolicy(env.action_space),
                        "map_planning_policy": lambda env: MapPlanningPolicy(cfg)}, seeds)
    wall = time.perf_counter() - t0
    summaries = summarize(results)
    table = markdown_table(summaries)

    world = (f"scenario `{args.scenario}`" if args.scenario else
             f"generated rubble rooms {cfg.rubble.room_size[0]:g} x {cfg.rubble.room_size[1]:g} m "
             f"(block coverage {cfg.rubble.block_coverage:g}, debris {cfg.rubble.debris_coverage:g}, "
             f"{cfg.rubble.n_pillars} pillar), {args.n_victims} victim(s) >= {cfg.min_start_distance_m:g} m of "
             f"path from the start, RT60 {cfg.rt60_s} s, {cfg.noise_db_spl:g} dB SPL diffuse noise, voices "
             f"{cfg.victim_level_db_spl:g} dB SPL at 1 m ({cfg.victim_sound})")
    setup = (f"SSLRescue-v0, {args.fidelity} fidelity; {world}; step = {cfg.control_s:g} s drive + "
             f"{cfg.settle_s:g} s settle + {cfg.listen_s:g} s listen; found within {cfg.found_radius_m:g} m; "
             f"time limit {args.max_steps} steps ({args.max_steps * cfg.step_s:g} s); seeds "
             f"{seeds.start}..{seeds.stop - 1}; wall time {wall:.0f} s")
    per_seed = "\n".join(f"| {r.policy} | {r.seed} | {r.scene} | {int(r.success)} | {r.steps} | "
                         f"{r.path_length_m:.2f} | {r.shortest_path_m:.2f} | {r.spl:.3f} | {r.collisions} |"
                         for r in results)
    md = (f"# Baseline policies on SSLRescue-v0\n\n{setup}\n\n{table}\n\n"
          "SPL = success x shortest path / max(path taken, shortest path); shortest path on the free-space "
          "grid (16-connected, obstacles grown by the bumper radius) to within the found radius of each victim.\n\n"
          "## Episodes\n\n| policy | seed | scene | success | steps | path (m) | shortest (m) | SPL | collisions |\n"
          "|---|---|---|---|---|---|---|---|---|\n" + per_seed + "\n")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "policy_baselines.md").write_text(md)
    write_csv(args.out / "policy_baselines.csv", summaries)
    write_csv(args.out / "policy_baselines_episodes.csv", results)
    print(setup)
    print(table)
    line = {"benchmark": "policy_baselines", "fidelity": args.fidelity, "episodes": args.episodes,
            "max_steps": args.max_steps, "n_victims": args.n_victims, "scenario": args.scenario,
            "seeds": [seeds.start, seeds.stop - 1], "wall_s": round(wall, 1),
            "summary": [{k: (round(v, 4) if isinstance(v, float) else v) for k, v in asdict(s).items()}
                        for s in summaries]}
    print(json.dumps(line))
    return line


if __name__ == "__main__":
    main(sys.argv[1:])
