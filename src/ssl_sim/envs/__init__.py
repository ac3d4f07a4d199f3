"""Gymnasium environment for navigation-policy experiments: find victims by sound.

``import ssl_sim.envs`` registers ``SSLRescue-v0``. Gymnasium 1.x no longer loads entry-point
plugins by itself, so either import this package first or let ``make`` import it::

    import gymnasium as gym
    env = gym.make("ssl_sim.envs:SSLRescue-v0")                 # "module:EnvId" imports the module
    env = gym.make("ssl_sim.envs:SSLRescue-v0", fidelity="full", n_victims=2, render_mode="rgb_array")

Keyword arguments of ``make`` are :class:`EnvConfig` fields (or ``config=EnvConfig(...)``);
``max_episode_steps`` (default 200 steps = 170 s of simulated time) sets the TimeLimit.

Public API: :class:`SSLRescueEnv`, :class:`EnvConfig`, :class:`RewardConfig`,
:class:`~ssl_sim.envs.navigation.GeodesicMap`, the baseline policies (:mod:`.policies`) and the
evaluation helpers (:mod:`.evaluation`).

Rendering: ``render_mode="rgb_array"`` uses a MuJoCo offscreen context. Without a display
(no ``DISPLAY``/``WAYLAND_DISPLAY``) this package sets ``MUJOCO_GL=osmesa`` (CPU rendering,
Debian ``libosmesa6``) if nothing set it, mujoco is not imported yet and the OSMesa library is
installed (with ``MUJOCO_GL=osmesa`` and no OSMesa, ``import mujoco`` itself fails, so the
environment could not even run unrendered); otherwise set it yourself before anything imports mujoco.
"""
from __future__ import annotations

import ctypes.util
import os
import sys

if ("mujoco" not in sys.modules and "MUJOCO_GL" not in os.environ
        and not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY")
        and ctypes.util.find_library("OSMesa")):
    os.environ["MUJOCO_GL"] = "osmesa"

import gymnasium as gym  # noqa: E402

from ssl_sim.envs.config import FIDELITIES, EnvConfig, RewardConfig  # noqa: E402
from ssl_sim.envs.navigation import GeodesicMap  # noqa: E402
from ssl_sim.envs.rescue_env import SSLRescueEnv, localizer_config  # noqa: E402

ENV_ID = "SSLRescue-v0"
MAX_EPISODE_STEPS = 200

if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point="ssl_sim.envs.rescue_env:SSLRescueEnv",
                 max_episode_steps=MAX_EPISODE_STEPS, nondeterministic=False)

__all__ = ["ENV_ID", "FIDELITIES", "MAX_EPISODE_STEPS", "EnvConfig", "GeodesicMap", "RewardConfig", "SSLRescueEnv",
           "localizer_config"]
