"""Running policies over seeded episodes and the navigation metrics of audio-goal navigation
(SoundSpaces, Chen et al. 2020; SPL from Anderson et al. 2018).

Per episode: ``success`` (every victim found before the time limit), ``spl`` by ``ssl_sim.scoring`` (the
metric of results.json and the sweep: per victim, found x l / max(p, l) for the leg that ended at her find,
``l`` the shortest path on the scoring graph from the leg's start to within 1.5 m of her, ``p`` the path the
robot centre took, ground truth sampled every 0.1 s; mean over victims), ``shortest_path_m`` the shortest tour
through every goal region from the start (``GeodesicMap.shortest_tour``, for reference), episode length in
steps and simulated seconds, steps with the bumper pressed (collisions), the fraction of victims found and
the return.
"""
from __future__ import annotations

import csv
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Iterable

import gymnasium as gym
import numpy as np

from ssl_sim.scoring import FreeSpaceGraph, leg_spls, run_spl


@dataclass(frozen=True)
class EpisodeResult:
    policy: str
    seed: int
    success: bool
    victims_found: int
    n_victims: int
    steps: int
    time_s: float
    path_length_m: float
    shortest_path_m: float
    spl: float
    collisions: int
    episode_return: float
    scene: str


def run_episode(env: gym.Env, policy, seed: int, name: str = "policy") -> EpisodeResult:
    """One episode of ``policy`` (``reset()``, ``policy(obs) -> action``) from ``env.reset(seed=seed)``."""
    obs, info = env.reset(seed=seed)
    shortest = float(info["shortest_path_m"])
    policy.reset(seed=seed)
    ret, steps = 0.0, 0
    while True:
        obs, reward, terminated, truncated, info = env.step(policy(obs))
        ret += float(reward)
        steps += 1
        if terminated or truncated:
            break
    success = info["victims_found"] == info["n_victims"] and not info.get("tipped_over", False)
    path = float(info["path_length_m"])
    u = env.unwrapped
    spl = episode_spl(u.scoring_graph, u.world, info["finds"]) if not info.get("tipped_over", False) else 0.0
    return EpisodeResult(name, int(seed), bool(success), int(info["victims_found"]), int(info["n_victims"]), steps,
                         float(info["time_s"]), path, shortest, spl, int(info["collisions"]), ret, str(info["scene"]))


def episode_spl(graph: FreeSpaceGraph, world, finds) -> float:
    """An episode's SPL by ``ssl_sim.scoring`` from ``info["finds"]`` (victim, base xy, path so far, time)."""
    legs = leg_spls(graph, [v.position[:2] for v in world.victims], world.robot_start[:2],
                    [(k, xy, path) for k, xy, path, _ in finds])
    return run_spl(len(world.victims), legs)


def evaluate(make_env: Callable[[], gym.Env], policies: dict[str, Callable[[gym.Env], object]],
             seeds: Iterable[int]) -> list[EpisodeResult]:
    """Every policy on every seed (same env instance per policy, so scene builds are reused).
    ``policies`` maps a name to a factory ``env -> policy``."""
    seeds = list(seeds)
    out = []
    env = make_env()
    try:
        for name, factory in policies.items():
            policy = factory(env)
            out += [run_episode(env, policy, s, name) for s in seeds]
    finally:
        env.close()
    return out


@dataclass(frozen=True)
class Summary:
    policy: str
    episodes: int
    success_rate: float
    spl: float
    victims_found_frac: float
    mean_steps: float
    mean_time_s: float
    mean_collisions: float
    mean_return: float


def summarize(results: list[EpisodeResult]) -> list[Summary]:
    """Per-policy means, in first-seen policy order."""
    names = list(dict.fromkeys(r.policy for r in results))
    out = []
    for n in names:
        rs = [r for r in results if r.policy == n]
        out.append(Summary(n, len(rs), float(np.mean([r.success for r in rs])), float(np.mean([r.spl for r in rs])),
                           float(np.mean([r.victims_found / r.n_victims for r in rs])),
                           float(np.mean([r.steps for r in rs])), float(np.mean([r.time_s for r in rs])),
                           float(np.mean([r.collisions for r in rs])), float(np.mean([r.episode_return for r in rs]))))
    return out


def markdown_table(summaries: list[Summary]) -> str:
    head = ("| policy | episodes | success rate | SPL | victims found | mean length (steps) | mean time (s) "
            "| mean collisions (steps) | mean return |")
    rows = [head, "|" + "---|" * 9]
    for s in summaries:
        rows.append(f"| {s.policy} | {s.episodes} | {s.success_rate:.2f} | {s.spl:.3f} | {s.victims_found_frac:.2f} | "
                    f"{s.mean_steps:.1f} | {s.mean_time_s:.1f} | {s.mean_collisions:.1f} | {s.mean_return:.2f} |")
    return "\n".join(rows)


def write_csv(path: str | Path, rows: list) -> Path:
    """Dataclass rows to CSV (header from the first row)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    dicts = [asdict(r) for r in rows]
    with path.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(dicts[0]) if dicts else [])
        w.writeheader()
        for d in dicts:
            w.writerow({k: (round(v, 4) if isinstance(v, float) and math.isfinite(v) else v) for k, v in d.items()})
    return path
