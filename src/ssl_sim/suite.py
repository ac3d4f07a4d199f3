"""Generated scenario suites: complete rescue scenarios drawn from a seed, in a ``train`` and a held-out ``test`` split.

    sc = generate("test", 17)                     # a validated ssl_sim.scenario.Scenario
    write_scenario("test", 17, "out/suite")       # out/suite/test_017_dense_collapsed.toml (+ scenes/): run PATH
    write_scenarios("train", "out/train", count=32)

A scenario is drawn whole from its seed: a scene family (``FAMILIES``: light rubble, a dense collapsed room,
partitions with doorways, voids under slabs) in a room of 4 x 4 to 10 x 8 m; 1-3 victims (procedural calls, shouts,
moans or mixed calling from ``ssl_sim.acoustics.voices``, or real recorded speech and shouts), some buried or behind
rubble, all intermittent; 0-2 interferers (real machinery, engines, alarms, music, or a procedural pump or
generator); diffuse noise of 30-50 dB SPL; an RT60 of 0.3-1.2 s; the robot's start on free floor.

**Splits.** ``train`` scenario ``i`` has the suite seed ``i`` (any ``0 <= i < TEST_SEED_BASE``); ``test`` is the
fixed list ``test_indices()`` (``TEST_SIZE`` scenarios) with suite seeds ``TEST_SEED_BASE + i``: the two seed
ranges are disjoint, so no train index can draw a test scenario. The generator's random stream is
``SeedSequence([SUITE_VERSION, suite seed, attempt])`` (the numbers of victims and interferers come from
``SeedSequence([SUITE_VERSION, suite seed])`` and stay across attempts), and the suite seed is also the scenario's
run seed (voices, noise, sensor). Real recordings come from the sound set's ``dev`` part for ``train`` and from its
``test`` part for ``test`` (``ssl_sim.acoustics.sound_set``: no speaker or machine is in both). Behaviour
parameters are chosen on ``train``; ``test`` is reported, never tuned on (docs/design/benchmark.md).

**Solvable by construction.** A draw is kept only if the scenario loader accepts it exactly as it accepts a
shipped file (a written copy is read back by ``load_scenario``: victims in air and in the room, start on free
floor, every victim with floor reachable from the start within 1.5 m on the free-space grid with obstacles grown
by the robot radius; the suite checks that again on its own, ``FIND_BASE_RADIUS_M``), and if every victim lies at least ``MIN_START_DISTANCE_M`` from the start, ``MIN_VICTIM_SPACING_M``
from the others and ``MIN_INTERFERER_DISTANCE_M`` from every interferer (a report at a machine is never a find).
Otherwise the next attempt of the same seed is drawn.

**Time limit** grows with the floor to search and the number of victims: 180 s for a 4 x 4 m room with one
victim, +1.5 s per m^2 above 16 m^2, +20 s per further victim, at most 300 s.

The files written use only fields the scenario loader has long understood ([scene] file, explicit victim
positions, ``sound = "file"`` with absolute paths into the sound set), so older code reruns them as a baseline.
"""
from __future__ import annotations

import math
import tempfile
from dataclasses import fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from robot.coverage import CoverageConfig
from robot.motion import MotionConfig
from robot.occupancy import OccupancyConfig
from robot.planner import PlannerConfig
from robot.rescue import RescueConfig
from robot.sound_map import SoundMapConfig
from ssl_core.localizer import LocalizerConfig
from ssl_sim.acoustics.sound_set import SoundFile, sound_files
from ssl_sim.acoustics.voices import SPEAKERS
from ssl_sim.physics.scene_gen import RubbleConfig, generate_world, reachable_victims
from ssl_sim.physics.scenes import _toml_value, save_scene
from ssl_sim.scenario import Scenario, ScenarioError, SceneSpec, load_scenario
from ssl_sim.world import World

__all__ = ["SPLITS", "FAMILIES", "TEST_SIZE", "TEST_SEED_BASE", "SUITE_VERSION", "suite_seed", "test_indices",
           "family_of", "generate", "indices", "scenarios", "summary_row", "to_toml", "write_scenario",
           "write_scenarios"]

SPLITS = ("train", "test")
FAMILIES = ("light_rubble", "dense_collapsed", "partitions", "voids")
#: Scenarios in the test split (16 per family: scenario i is of family FAMILIES[i % 4]).
TEST_SIZE = 64
#: Test suite seeds are TEST_SEED_BASE + index; train suite seeds are the index itself, below it.
TEST_SEED_BASE = 1_000_000_000
#: Part of every generator seed: a changed generator is a new version, never silently the same names.
SUITE_VERSION = 1
#: Which part of the real sound set each split draws from.
SOUND_PART = {"train": "dev", "test": "test"}

FIND_BASE_RADIUS_M = 1.5        # a find needs the robot's base this close to her: floor this close must be reachable
MIN_START_DISTANCE_M = 2.0      # no victim found from the start without moving
MIN_VICTIM_SPACING_M = 1.2      # two victims never within one 0.5 m report radius of each other
MIN_INTERFERER_DISTANCE_M = 1.5
MAX_ATTEMPTS = 40

#: The robot's configuration in every suite scenario (one for all: the robot does not know the scene): several
#: sources per window, as in the shipped multi-victim scenarios; a second source must carry at least half the
#: strongest one's SRP power (chosen on the train split: a third fewer false finds than 0.3, docs/design/behaviour.md).
#: Everything else is the code's defaults.
ROBOT_PROFILE: dict[str, dict[str, Any]] = {"localizer": {"n_sources": 3, "rel_threshold": 0.5}}

_VOICE_KINDS = ("calls", "mixed", "shouts", "moans")
_VOICE_P = (0.5, 0.2, 0.2, 0.1)
_REAL_VICTIM_P = 0.4             # share of victims that are real recordings (speech or shouts)
_INTERFERER_CATEGORIES = ("machinery", "engine", "alarm", "music")
_INTERFERER_CAT_P = (0.4, 0.25, 0.2, 0.15)
_REAL_INTERFERER_P = 0.7
# levels at 1 m while sounding (dB SPL): a calling voice 60-70, a shout 66-76; machines up to 78 (up to ~15 dB
# above the quietest caller, as a generator beside a rescue site)
_LEVELS = {"calls": (60.0, 70.0), "mixed": (60.0, 70.0), "moans": (60.0, 68.0), "shouts": (66.0, 76.0),
           "speech": (60.0, 68.0), "machinery": (64.0, 78.0), "engine": (64.0, 78.0), "alarm": (60.0, 72.0),
           "music": (58.0, 70.0), "pump": (64.0, 78.0), "generator": (64.0, 78.0)}
_NOISE_SPECTRA = ("hvac", "pink", "brown")


class _Reject(Exception):
    """A draw that breaks a suite rule: the next attempt is drawn."""


# ----------------------------------------------------------------------------- naming
def _check_split(split: str) -> None:
    if split not in SPLITS:
        raise ValueError(f"split: expected one of {SPLITS}, got {split!r}")


def suite_seed(split: str, index: int) -> int:
    """The suite seed of scenario ``index`` of ``split`` (train: ``index``; test: ``TEST_SEED_BASE + index``)."""
    _check_split(split)
    if not isinstance(index, (int, np.integer)) or isinstance(index, bool) or index < 0:
        raise ValueError(f"index: expected an integer >= 0, got {index!r}")
    if split == "test":
        if index >= TEST_SIZE:
            raise ValueError(f"index: the test split has scenarios 0..{TEST_SIZE - 1}, got {index}")
        return TEST_SEED_BASE + int(index)
    if index >= TEST_SEED_BASE:
        raise ValueError(f"index: train scenarios are 0..{TEST_SEED_BASE - 1}, got {index}")
    return int(index)


def test_indices() -> list[int]:
    """The fixed test split: scenario indices 0..TEST_SIZE-1."""
    return list(range(TEST_SIZE))


def _name(split: str, index: int) -> str:
    return f"{split}_{index:03d}_{FAMILIES[index % len(FAMILIES)]}"


def family_of(name: str) -> str:
    """The scene family of a suite scenario from its name (``test_017_dense_collapsed`` -> ``dense_collapsed``)."""
    parts = name.split("_", 2)
    if len(parts) != 3 or parts[0] not in SPLITS or parts[2] not in FAMILIES:
        raise ValueError(f"scenario name: expected SPLIT_INDEX_FAMILY with a family of {FAMILIES}, got {name!r}")
    return parts[2]


# ----------------------------------------------------------------------------- drawing
def _scene_config(family: str, rng: np.random.Generator, size: tuple[float, float, float],
                  n_victims: int) -> RubbleConfig:
    area = size[0] * size[1]
    u = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731
    common = dict(room_size=size, n_victims=n_victims)
    if family == "light_rubble":
        return RubbleConfig(**common, block_coverage=u(0.04, 0.08), debris_coverage=0.03,
                            n_pillars=int(rng.integers(0, 2 + int(area // 40))), victim_modes=("beside", "on"))
    if family == "dense_collapsed":
        return RubbleConfig(**common, block_coverage=u(0.14, 0.2), debris_coverage=0.05,
                            n_pillars=1 + int(area // 40), n_walls=int(rng.integers(1, 2 + int(area // 25))),
                            n_voids=int(rng.integers(1, 3)), stack_fraction=0.35,
                            victim_modes=("on", "beside", "under"))
    if family == "partitions":
        n_part = 1 if max(size[:2]) < 7.0 else int(rng.integers(1, 3))
        return RubbleConfig(**common, n_partitions=n_part, block_coverage=u(0.03, 0.06), debris_coverage=0.02,
                            n_pillars=int(rng.integers(0, 2)), victim_modes=("beside", "on"))
    if family == "voids":
        return RubbleConfig(**common, n_voids=2 + int(area // 30), block_coverage=u(0.05, 0.08),
                            debris_coverage=0.03, victim_modes=("under", "under", "beside"))
    raise ValueError(f"family: expected one of {FAMILIES}, got {family!r}")


def _pick(rng: np.random.Generator, files: list[SoundFile], used: set[Path]) -> SoundFile | None:
    free = [f for f in files if f.path not in used]
    if not free:
        return None
    f = free[int(rng.integers(len(free)))]
    used.add(f.path)
    return f


def _level(rng: np.random.Generator, what: str) -> float:
    return round(float(rng.uniform(*_LEVELS[what])), 1)


def _victims(rng: np.random.Generator, world: World, part: str) -> list[dict[str, Any]]:
    used: set[Path] = set()
    speakers = list(rng.permutation(sorted(SPEAKERS)))
    out = []
    for i, site in enumerate(world.victims):
        t: dict[str, Any] = {"position": [round(v, 3) for v in site.position]}
        buried = site.buried
        if buried < 0.3 and rng.random() < 0.3:
            buried = float(rng.uniform(0.3, 0.6))   # partly covered by debris where she lies
        real = None
        if rng.random() < _REAL_VICTIM_P:
            cat = "shouts" if rng.random() < 0.35 else "speech"
            real = _pick(rng, sound_files(part, cat), used)
        if real is not None:
            t.update(sound="file", file=str(real.path), level_db_spl=_level(rng, real.category))
            label = f"{real.category}_{real.name}"
        else:
            kind = str(rng.choice(_VOICE_KINDS, p=_VOICE_P))
            speaker = str(speakers[i % len(speakers)])
            t.update(sound=kind, speaker=speaker, level_db_spl=_level(rng, kind),
                     period_s=round(float(rng.uniform(2.0, 4.0)), 2), p_event=round(float(rng.uniform(0.5, 0.9)), 2))
            label = f"{kind}_{speaker}"
        t["buried"] = round(float(buried), 2)
        t["name"] = f"v{i}_{label}"
        out.append(t)
    return out


def _interferers(rng: np.random.Generator, world: World, part: str, n: int) -> list[dict[str, Any]]:
    used: set[Path] = set()
    L = np.asarray(world.room.size)
    start = np.asarray(world.robot_start[:2])
    out = []
    for j in range(n):
        real = None
        if rng.random() < _REAL_INTERFERER_P:
            cat = str(rng.choice(_INTERFERER_CATEGORIES, p=_INTERFERER_CAT_P))
            real = _pick(rng, sound_files(part, cat), used)
        for _ in range(60):
            xy = rng.uniform([0.3, 0.3], L[:2] - 0.3)
            p = np.array([xy[0], xy[1], rng.uniform(0.2, 1.0)]).round(3)
            if (world.inside_obstacle(p, margin=0.05, include_climbable=True) is None
                    and np.linalg.norm(p[:2] - start) >= 0.75
                    and all(math.dist(p[:2], v.position[:2]) >= MIN_INTERFERER_DISTANCE_M for v in world.victims)):
                break
        else:
            raise _Reject("no free spot for an interferer")
        pos = [float(v) for v in p]
        if real is not None:
            out.append({"kind": "file", "position": pos, "level_db_spl": _level(rng, real.category),
                        "file": str(real.path), "name": f"i{j}_{real.category}_{real.name}"})
        else:
            kind = str(rng.choice(["pump", "generator"]))
            out.append({"kind": kind, "position": pos, "level_db_spl": _level(rng, kind), "name": f"i{j}_{kind}"})
    return out


def _time_limit_s(size: tuple[float, float, float], n_victims: int) -> float:
    area = size[0] * size[1]
    return float(min(300.0, round(180.0 + 1.5 * max(0.0, area - 16.0) + 20.0 * (n_victims - 1))))


def _draw(split: str, index: int, rng: np.random.Generator, n_victims: int,
          n_interferers: int) -> tuple[dict[str, Any], World]:
    """One attempt: the scenario's TOML table (without [scene]) and its World (scene with victim sites)."""
    family = FAMILIES[index % len(FAMILIES)]
    lx = round(float(rng.uniform(4.0, 10.0)), 1)
    ly = round(float(rng.uniform(4.0, min(8.0, lx))), 1)
    size = (lx, ly, round(float(rng.uniform(2.6, 3.2)), 1))
    cfg = _scene_config(family, rng, size, n_victims)
    try:
        world = generate_world(cfg, seed=int(rng.integers(2**31)), name=_name(split, index))
    except RuntimeError as exc:
        raise _Reject(str(exc)) from None
    start = np.asarray(world.robot_start[:2])
    vs = [np.asarray(v.position[:2]) for v in world.victims]
    if any(np.linalg.norm(v - start) < MIN_START_DISTANCE_M for v in vs):
        raise _Reject("a victim near the start")
    if any(np.linalg.norm(a - b) < MIN_VICTIM_SPACING_M for k, a in enumerate(vs) for b in vs[k + 1:]):
        raise _Reject("two victims too close")
    part = SOUND_PART[split]
    victims = _victims(rng, world, part)
    interferers = _interferers(rng, world, part, n_interferers)
    rt60 = round(float(rng.uniform(0.3, 1.2)), 2)
    noise = {"level_db_spl": round(float(rng.uniform(30.0, 50.0)), 1), "spectrum": str(rng.choice(_NOISE_SPECTRA))}
    seed = suite_seed(split, index)
    data: dict[str, Any] = {
        "name": _name(split, index),
        "description": (f"{family.replace('_', ' ')} {lx:g} x {ly:g} m, {len(victims)} victim(s), "
                        f"{len(interferers)} interferer(s), RT60 {rt60:g} s, noise {noise['level_db_spl']:g} dB SPL "
                        f"({split} split, suite v{SUITE_VERSION})"),
        "seed": seed,
        "time_limit_s": _time_limit_s(size, len(victims)),
        "robot": {"start": list(world.robot_start)},
        "victims": victims,
        "interferers": interferers,
        "noise": noise,
        # The RIR is cut where the tail has decayed by 60-105 dB; reflections off rubble faces stop at order 2
        # (the diffuse tail carries their energy; light_rubble_three.toml measures what that costs in accuracy).
        "acoustics": {"rt60_s": rt60, "max_rir_s": round(min(1.2, 0.3 + 0.75 * rt60), 2), "obstacle_order": 2},
        **{k: dict(v) for k, v in ROBOT_PROFILE.items()},
    }
    return data, world


def generate(split: str, index: int) -> Scenario:
    """Scenario ``index`` of ``split``: the same arguments always give the same Scenario. Its scene is held in
    memory (``scene.world``); the loader's checks have passed (see the module docstring)."""
    seed = suite_seed(split, index)
    # How many victims and interferers is fixed by the seed (a redrawn attempt keeps them: the split's mix stays
    # as designed instead of drifting to the easier draws)
    design = np.random.default_rng(np.random.SeedSequence([SUITE_VERSION, seed]))
    n_victims = int(design.choice([1, 2, 3], p=[0.3, 0.4, 0.3]))
    n_interferers = int(design.choice([0, 1, 2], p=[0.3, 0.45, 0.25]))
    reasons = []
    for attempt in range(MAX_ATTEMPTS):
        rng = np.random.default_rng(np.random.SeedSequence([SUITE_VERSION, seed, attempt]))
        try:
            data, world = _draw(split, index, rng, n_victims, n_interferers)
            return _validated(data, world)
        except (_Reject, ScenarioError) as exc:
            reasons.append(str(exc))
    raise RuntimeError(f"suite {split} {index}: no valid scenario in {MAX_ATTEMPTS} attempts (last: {reasons[-1]})")


def _validated(data: dict[str, Any], world: World) -> Scenario:
    """Write the draw as files, read them back with the scenario loader (every check a shipped file gets),
    and check the suite's own rule: reachable floor within FIND_BASE_RADIUS_M of every victim."""
    scene = replace(world, victims=())
    with tempfile.TemporaryDirectory(prefix="ssl_suite_") as d:
        text = _table_toml(data, f"scenes/{data['name']}.toml")
        path = Path(d) / f"{data['name']}.toml"
        save_scene(scene, Path(d) / "scenes" / f"{data['name']}.toml")
        path.write_text(text)
        sc = load_scenario(path)
    sc = replace(sc, path="", scene=SceneSpec(world=scene))
    full = sc.world()
    ok = reachable_victims(full, reach=FIND_BASE_RADIUS_M)
    if not ok.all():
        raise _Reject(f"victim {int(np.flatnonzero(~ok)[0])} has no reachable floor within {FIND_BASE_RADIUS_M} m")
    return sc


def scenarios(split: str, count: int | None = None) -> list[Scenario]:
    """The first ``count`` scenarios of ``split`` (test: default and at most TEST_SIZE; train: default TEST_SIZE)."""
    return [generate(split, i) for i in indices(split, count)]


def indices(split: str, count: int | None = None, first: int = 0) -> list[int]:
    """The indices of :func:`scenarios` (test: ``test_indices()[first:first+count]``, a part of the fixed split, to
    run it in parts; train: ``first..first+count-1``, default count TEST_SIZE: a train range apart from the one a
    model was fitted on is a held-out check)."""
    _check_split(split)
    if count is not None and (not isinstance(count, int) or count < 1):
        raise ValueError(f"count: expected an integer >= 1, got {count!r}")
    if not isinstance(first, int) or first < 0:
        raise ValueError(f"first: expected an integer >= 0, got {first!r}")
    if split == "test":
        end = TEST_SIZE if count is None else first + count
        if end > TEST_SIZE or first >= TEST_SIZE:
            raise ValueError(f"first, count: the test split has {TEST_SIZE} scenarios, got first={first}, "
                             f"count={count}")
        return test_indices()[first:end]
    return list(range(first, first + (count or TEST_SIZE)))


def summary_row(sc: Scenario) -> dict[str, Any]:
    """What ``ssl-rescue suite list`` shows of a suite scenario."""
    world = sc.world()
    return {"name": sc.name, "family": family_of(sc.name), "room_m": f"{world.room.size[0]:g}x{world.room.size[1]:g}",
            "victims": len(sc.victims),
            "victim_sounds": ",".join(f"rec_{Path(v.file).parent.name}" if v.sound == "file" else v.sound
                                      for v in sc.victims),
            "buried_max": max((v.buried or 0.0) for v in sc.victims),
            "interferers": len(sc.interferers),
            "interferer_kinds": ",".join(Path(i.file).parent.name if i.kind == "file" else i.kind
                                         for i in sc.interferers) or "-",
            "rt60_s": sc.acoustics.get("rt60_s"), "noise_db_spl": sc.noise.level_db_spl if sc.noise else None,
            "time_limit_s": sc.time_limit_s, "seed": sc.seed}


# ----------------------------------------------------------------------------- TOML
def _config_table(obj: Any, default: Any, what: str) -> dict[str, Any]:
    out = {}
    for f in fields(obj):
        v = getattr(obj, f.name)
        if v != getattr(default, f.name):
            if v is None:
                raise ValueError(f"to_toml: {what}.{f.name} = None cannot be written to TOML")
            out[f.name] = list(v) if isinstance(v, tuple) else v
    return out


def _scenario_table(sc: Scenario) -> dict[str, Any]:
    """The TOML table of ``sc`` (config tables hold the fields that differ from the loader's defaults)."""
    data: dict[str, Any] = {"name": sc.name, "description": sc.description, "seed": sc.seed,
                            "time_limit_s": sc.time_limit_s}
    if sc.robot_start is not None:
        data["robot"] = {"start": list(sc.robot_start)}
    vs = []
    for v in sc.victims:
        t: dict[str, Any] = ({"position": list(v.position)} if v.position is not None
                             else {"scene_victim": v.scene_victim})
        t.update(sound=v.sound)
        if v.speaker is not None:
            t["speaker"] = v.speaker
        t["level_db_spl"] = v.level_db_spl
        if v.buried is not None:
            t["buried"] = v.buried
        t.update(period_s=v.period_s, p_event=v.p_event)
        if v.file is not None:
            t["file"] = v.file
        t["name"] = v.name
        vs.append(t)
    data["victims"] = vs
    data["interferers"] = [{"kind": s.kind, "position": list(s.position), "level_db_spl": s.level_db_spl,
                            **({"speaker": s.speaker} if s.kind == "talker" or s.speaker != "male" else {}),
                            **({"file": s.file} if s.file is not None else {}), "name": s.name}
                           for s in sc.interferers]
    data["noise"] = ({"enabled": False} if sc.noise is None
                     else {"level_db_spl": sc.noise.level_db_spl, "spectrum": sc.noise.spectrum})
    data["acoustics"] = dict(sc.acoustics)
    defaults = {"localizer": LocalizerConfig(),
                "behaviour": RescueConfig(),
                "motion": MotionConfig(), "sound_map": SoundMapConfig(), "planner": PlannerConfig(),
                "occupancy": OccupancyConfig(), "coverage": CoverageConfig()}
    for key, default in defaults.items():
        t = _config_table(getattr(sc, key), default, key)
        if t:
            data[key] = t
    return data


def _table_toml(data: dict[str, Any], scene_file: str) -> str:
    lines = ["# A generated rescue scenario (ssl_sim.suite); run it with: ssl-rescue run THIS_FILE"]
    for k in ("name", "description", "seed", "time_limit_s"):
        lines.append(f"{k} = {_toml_value(data[k])}")
    lines += ["", "[scene]", f"file = {_toml_value(scene_file)}"]
    for key in ("robot", "noise", "acoustics", "localizer", "behaviour", "motion", "sound_map", "planner",
                "occupancy", "coverage"):
        if data.get(key):
            lines += ["", f"[{key}]"] + [f"{k} = {_toml_value(v)}" for k, v in data[key].items()]
    for key in ("victims", "interferers"):
        for t in data.get(key, []):
            lines += ["", f"[[{key}]]"] + [f"{k} = {_toml_value(v)}" for k, v in t.items()]
    return "\n".join(lines) + "\n"


def to_toml(sc: Scenario, scene_file: str | None = None) -> str:
    """The scenario file of ``sc``; its scene is referenced as ``scene_file`` (default ``scenes/NAME.toml``,
    which :func:`write_scenario` writes beside it)."""
    return _table_toml(_scenario_table(sc), scene_file or f"scenes/{sc.name}.toml")


def write_scenario(split: str, index: int, out_dir: str | Path) -> Path:
    """Write scenario ``index`` of ``split`` to ``out_dir/NAME.toml`` and its scene to ``out_dir/scenes/NAME.toml``;
    returns the scenario file (``ssl-rescue run PATH`` reruns it; ``load_scenario`` reads back the same Scenario)."""
    return _write(generate(split, index), Path(out_dir))


def _write(sc: Scenario, out: Path) -> Path:
    world = sc.scene.world
    if world is None:
        raise ValueError(f"write_scenario: scenario {sc.name!r} holds no in-memory scene (scene.world)")
    save_scene(world, out / "scenes" / f"{sc.name}.toml",
               header=f"Scene of the generated scenario {sc.name} (ssl_sim.suite, World data, SI units, world frame).")
    path = out / f"{sc.name}.toml"
    path.write_text(to_toml(sc))
    return path


def write_scenarios(split: str, out_dir: str | Path, count: int | None = None, first: int = 0) -> list[Path]:
    """Write ``count`` scenarios of ``split`` from index ``first`` (see :func:`indices`) to ``out_dir``; returns
    their files."""
    out = Path(out_dir)
    return [_write(generate(split, i), out) for i in indices(split, count, first)]
