"""Run a seeded random policy in the SSLRescue-v0 gymnasium environment and print each episode's return.

Run: ``python examples/random_policy.py [--episodes 2] [--steps 50] [--fidelity fast]``.
"""
from __future__ import annotations

import argparse

import gymnasium as gym
import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=2)
    ap.add_argument("--steps", type=int, default=50, help="at most this many steps per episode")
    ap.add_argument("--fidelity", choices=("fast", "full"), default="fast")
    args = ap.parse_args(argv)
    env = gym.make("ssl_sim.envs:SSLRescue-v0", fidelity=args.fidelity)
    env.action_space.seed(0)
    try:
        for episode in range(args.episodes):
            obs, info = env.reset(seed=episode)
            total, steps = 0.0, 0
            for steps in range(1, args.steps + 1):
                action = env.action_space.sample()        # normalised body twist (vx, vy, omega) in [-1, 1]
                obs, reward, terminated, truncated, info = env.step(action)
                total += float(reward)
                if terminated or truncated:
                    break
            strongest = obs["detections"][0]
            print(f"episode {episode}: {steps} steps, return {total:.2f}, found flag {np.asarray(obs['found']).tolist()}, "
                  f"strongest detection row {np.round(strongest, 2).tolist()}")
    finally:
        env.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
