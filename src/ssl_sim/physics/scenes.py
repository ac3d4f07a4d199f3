"""Named scenes (``ssl_sim/models/scenes/*.toml``, World data) and World <-> TOML.

A scene file is ``World.to_dict()`` in TOML: top-level ``name``, ``seed``,
``robot_start = [x, y, yaw]``, a ``[room]`` table and ``[[obstacles]]`` /
``[[victims]]`` arrays of tables (metres, radians, world frame).
"""
from __future__ import annotations

import math
import tomllib
from pathlib import Path

from ssl_sim.world import World
from ssl_sim.resources import MODELS_DIR

SCENES_DIR = MODELS_DIR / "scenes"


def scene_names() -> list[str]:
    """Names of the shipped scenes."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.toml"))


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"cannot write non-finite number {v} to TOML")
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {type(v).__name__} to TOML")


def world_to_toml(world: World, header: str = "") -> str:
    """TOML text of a World (exact round trip through ``load_scene``)."""
    d = world.to_dict()
    lines = [f"# {line}" for line in header.splitlines()]
    for key in ("name", "seed", "robot_start"):
        if d.get(key) is not None:
            lines.append(f"{key} = {_toml_value(d[key])}")
    lines += ["", "[room]"] + [f"{k} = {_toml_value(v)}" for k, v in d["room"].items()]
    for table in ("obstacles", "victims"):
        for item in d[table]:
            lines += ["", f"[[{table}]]"] + [f"{k} = {_toml_value(v)}" for k, v in item.items()]
    return "\n".join(lines) + "\n"


def save_scene(world: World, path: str | Path, header: str = "") -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(world_to_toml(world, header))
    return path


def load_scene(name_or_path: str | Path) -> World:
    """A shipped scene by name (``empty_lab``, ``light_rubble``, ...) or a World TOML file."""
    p = Path(name_or_path)
    if p.suffix.lower() != ".toml":
        p = SCENES_DIR / f"{name_or_path}.toml"
        if not p.exists():
            raise ValueError(f"unknown scene '{name_or_path}': expected one of {scene_names()} or a .toml file")
    elif not p.exists():
        raise FileNotFoundError(f"scene file not found: {p}")
    try:
        data = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ValueError(f"scene file {p}: invalid TOML ({exc})") from exc
    return World.from_dict(data)

