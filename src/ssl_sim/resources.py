"""Where the simulator's shipped data lives: scenarios, MuJoCo models and scenes, the real sound set.

All of it is package data under ``ssl_sim`` (``scenarios/``, ``models/``, ``sounds/``), reached through
``importlib.resources`` so that a clone, an editable install and a wheel find the same files.
"""
from __future__ import annotations

from importlib import resources
from pathlib import Path


def _package_dir(name: str) -> Path:
    # ssl_sim is a regular package on disk (never zipped), so its resources are real paths
    return Path(str(resources.files("ssl_sim") / name))


#: Shipped scenarios (``*.toml``) and the hand-written scenes they use (``scenes/``).
SCENARIOS_DIR = _package_dir("scenarios")
#: MuJoCo robot model (``omni_robot.xml``) and named scenes (``scenes/*.toml`` World data, ``*.xml``).
MODELS_DIR = _package_dir("models")
#: Real recordings (16 kHz mono WAV) in a ``dev`` and a ``test`` part, listed with licences in ``PROVENANCE``.
SOUNDS_DIR = _package_dir("sounds")
