"""Rescue scenarios: a TOML file -> validated dataclasses -> World, sound sources and configs.

A scenario says where (scene), who calls for help (victims), what else is heard (interferers,
ambient noise), how the robot behaves (``RescueConfig`` fields), how it localizes
(``LocalizerConfig`` fields), and for how long. Units SI, world frame (``ssl_sim.world``), angles
of the robot start in radians. Example (``ssl_sim/scenarios/paper_lab.toml``)::

    name = "paper_lab"
    description = "The paper's empty lab, one caller 1.5 m ahead"
    seed = 0                 # default run seed (voices, noise, sensor; generated scenes)
    time_limit_s = 60.0      # simulated time
    # finds are scored by ssl_sim.scoring, the same for every scenario (docs/design/scoring.md)

    [scene]
    name = "empty_lab"       # a shipped scene; or file = "my_scene.toml" (World TOML, relative to
                             # this file); or generate = "light_rubble" (scene_gen preset) + seed
    # use_scene_victims = true   # add the scene's own victim sites (default: only if no [[victims]])

    [robot]
    start = [3.0, 3.0, 0.0]  # x, y (m), yaw (rad); default: the scene's robot_start

    [[victims]]
    position = [4.496, 2.895, 0.1]   # mouth, world m
    sound = "calls"          # calls | moans | shouts | knocks | mixed | continuous | file
    speaker = "male"         # ssl_sim.acoustics.SPEAKERS key (voices)
    level_db_spl = 62.5      # at 1 m while calling
    buried = 0.0             # 0 free .. 1 fully covered
    # file = "voices/help.wav"   # with sound = "file": a mono WAV, looped (relative to this file)

    [[interferers]]
    kind = "pump"            # pump | generator | talker | file
    position = [6.0, 3.0, 0.3]
    level_db_spl = 72.0

    [noise]                  # diffuse ambient noise (ssl_sim.acoustics.AmbientNoise fields)
    level_db_spl = 30.0
    spectrum = "hvac"

    [ego_noise]              # the drive's own motors while the wheels turn (ssl_sim.acoustics.ego_noise
    level_db_spl_1m = 40.0   # EgoNoiseConfig fields; on by default, enabled = false for a silent drive)

    [acoustics]              # AcousticConfig fields: rt60_s, ism_order, max_rir_s, late_reverb, ...
    [localizer]              # ssl_core LocalizerConfig fields
    [behaviour]              # robot.rescue RescueConfig fields (decisions)
    [motion]                 # robot.motion MotionConfig fields
    [sound_map]              # robot.sound_map SoundMapConfig fields
    [planner]                # robot.planner PlannerConfig fields
    [occupancy]              # robot.occupancy OccupancyConfig fields
    [coverage]               # robot.coverage CoverageConfig fields (area: the room's floor unless given)
    [pursuit]                # robot.pursuit PursuitConfig fields (per-source pursuit limits)
    [options]                # robot.options OptionsConfig fields (valuing approach / explore)
    [recovery]               # robot.recovery RecoveryConfig fields (escape)

Every error names the file and the field (``paper_lab.toml: victims[0].position: ...``).
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from robot.config_values import check_scalar, field_values, in_section
from robot.motion import MotionConfig
from robot.coverage import CoverageConfig
from robot.options import OptionsConfig
from robot.pursuit import PursuitConfig
from robot.recovery import RecoveryConfig
from robot.occupancy import OccupancyConfig
from robot.planner import PlannerConfig
from robot.rescue import RescueConfig
from robot.sound_map import SoundMapConfig
from ssl_core.gcc_phat import band_bins
from ssl_core.geometry import cube8
from ssl_core.localizer import LocalizerConfig, check_table_memory
from ssl_sim.acoustics import AcousticConfig, AmbientNoise, SoundSource, noise_source
from ssl_sim.acoustics.ego_noise import EgoNoiseConfig
from ssl_sim.acoustics.signals import LoopedSignal
from ssl_sim.acoustics.sources import PAPER_LEVEL_DB_SPL
from ssl_sim.acoustics.voices import SPEAKERS, VICTIM_SOUNDS, continuous_voice, victim_voice
from ssl_sim.physics.robot_model import RobotModelConfig
from ssl_sim.physics.scene_gen import PRESETS, generate_world, reachable_victims
from ssl_sim.physics.scenes import load_scene, scene_names
from ssl_sim.resources import SCENARIOS_DIR
from ssl_sim.scoring import FIND_BASE_RADIUS_M, FIND_REPORT_RADIUS_M, REACHED_RADIUS_M
from ssl_sim.world import VictimSite, World

DEFAULT_SCENARIO = "paper_lab"

VICTIM_SOUND_KINDS = (*VICTIM_SOUNDS, "continuous", "file")
INTERFERER_KINDS = ("pump", "generator", "talker", "file")
#: AcousticConfig fields a scenario may set (seed and ambient come from the scenario itself).
ACOUSTIC_FIELDS = ("ism_order", "obstacle_order", "ism_budget", "late_reverb", "rt60_s", "max_rir_s",
                   "visibility_grid_m", "min_obstacle_extent_m", "rir_cache_size", "diffraction")


class ScenarioError(ValueError):
    """A scenario file is invalid; the message names the file and the field."""


# ----------------------------------------------------------------------------- specs
@dataclass(frozen=True)
class SceneSpec:
    """Which World: exactly one of ``name`` (shipped scene), ``file`` (World TOML, absolute path),
    ``generate`` (``scene_gen.PRESETS`` key, with ``seed``; None = the run seed) or ``world`` (a World
    object held in memory, as ``ssl_sim.suite`` makes them; in a file it is ``file``)."""

    name: str | None = None
    file: str | None = None
    generate: str | None = None
    seed: int | None = None
    use_scene_victims: bool | None = None  # None: only when the scenario lists no victims
    world: World | None = None


@dataclass(frozen=True)
class VictimSpec:
    """A victim calling for help. ``position`` (world m, mouth) or ``scene_victim`` (index into the
    scene's victim sites); ``buried`` None = the scene site's value (0 for explicit positions)."""

    position: tuple[float, float, float] | None = None
    scene_victim: int | None = None
    sound: str = "calls"
    speaker: str | None = None          # None: cycles through SPEAKERS by victim index
    level_db_spl: float = PAPER_LEVEL_DB_SPL
    buried: float | None = None
    period_s: float = 2.5               # one call per period ...
    p_event: float = 0.9                # ... with this probability
    file: str | None = None             # sound = "file": absolute path of a mono WAV
    name: str = ""
    samples: np.ndarray | None = field(default=None, repr=False, compare=False)  # loaded WAV
    file_fs: int | None = None


@dataclass(frozen=True)
class InterfererSpec:
    """A non-victim sound: machine noise (``pump``, ``generator``), a ``talker`` (rescuer, radio)
    or a looped WAV ``file``; ``position`` world m; level dB SPL at 1 m."""

    kind: str
    position: tuple[float, float, float]
    level_db_spl: float = 72.0
    speaker: str = "male"
    file: str | None = None
    name: str = ""
    samples: np.ndarray | None = field(default=None, repr=False, compare=False)
    file_fs: int | None = None


@dataclass(frozen=True)
class Scenario:
    """A validated scenario (see the module docstring). ``path``: the file it came from."""

    name: str
    scene: SceneSpec
    victims: tuple[VictimSpec, ...] = ()
    interferers: tuple[InterfererSpec, ...] = ()
    description: str = ""
    seed: int = 0
    time_limit_s: float = 120.0
    robot_start: tuple[float, float, float] | None = None
    noise: AmbientNoise | None = field(default_factory=AmbientNoise)
    # The drive's own motor noise while the wheels turn (part of the world: on unless the scenario says
    # ``[ego_noise] enabled = false``); its level ``level_db_spl_1m`` and spectrum are EgoNoiseConfig fields.
    ego_noise: EgoNoiseConfig | None = field(default_factory=EgoNoiseConfig)
    acoustics: dict[str, Any] = field(default_factory=dict)
    localizer: LocalizerConfig = field(default_factory=LocalizerConfig)
    behaviour: RescueConfig = field(default_factory=RescueConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    sound_map: SoundMapConfig = field(default_factory=SoundMapConfig)
    planner: PlannerConfig = field(default_factory=PlannerConfig)
    occupancy: OccupancyConfig = field(default_factory=OccupancyConfig)
    coverage: CoverageConfig = field(default_factory=CoverageConfig)
    pursuit: PursuitConfig = field(default_factory=PursuitConfig)
    options: OptionsConfig = field(default_factory=OptionsConfig)
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)
    path: str = ""

    def stage_configs(self) -> dict[str, Any]:
        """The behaviour's per-stage configs as ``RescueBehaviour`` keyword arguments."""
        return {"motion": self.motion, "sound_map": self.sound_map, "planner": self.planner,
                "occupancy": self.occupancy, "coverage": self.coverage, "pursuit": self.pursuit,
                "options": self.options, "recovery": self.recovery}

    # -- building the run's objects ---------------------------------------------------------
    def with_overrides(self, seed: int | None = None, time_limit_s: float | None = None) -> "Scenario":
        """A copy with another run seed and/or time limit (s)."""
        s = self
        if seed is not None:
            if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
                raise ScenarioError(f"seed: expected an integer >= 0, got {seed!r}")
            s = replace(s, seed=int(seed))
        if time_limit_s is not None:
            if not (isinstance(time_limit_s, (int, float)) and math.isfinite(time_limit_s) and time_limit_s > 0):
                raise ScenarioError(f"time_limit_s: expected a duration > 0 s, got {time_limit_s!r}")
            s = replace(s, time_limit_s=float(time_limit_s))
        return s

    def world(self, seed: int | None = None) -> World:
        """The World of a run with ``seed`` (default ``self.seed``): scene + victim sites + start pose.

        Raises ScenarioError naming the field when a victim or the start is inside an obstacle,
        outside the room or unreachable."""
        seed = self.seed if seed is None else seed
        where = _where(self.path)
        sc = self.scene
        try:
            if sc.name is not None:
                base = load_scene(sc.name)
            elif sc.file is not None:
                base = load_scene(sc.file)
            elif sc.world is not None:
                base = sc.world
            else:
                base = generate_world(PRESETS[sc.generate], seed=sc.seed if sc.seed is not None else seed,
                                      name=f"{sc.generate}_{sc.seed if sc.seed is not None else seed}")
        except (ValueError, FileNotFoundError, RuntimeError) as exc:
            raise ScenarioError(f"{where}scene: {exc}") from None
        sites = []
        for i, v in enumerate(self.victims):
            if v.scene_victim is not None:
                if not 0 <= v.scene_victim < len(base.victims):
                    raise ScenarioError(f"{where}victims[{i}].scene_victim: scene '{base.name}' has "
                                        f"{len(base.victims)} victim site(s), got index {v.scene_victim}")
                s = base.victims[v.scene_victim]
                sites.append(VictimSite(s.position, s.buried if v.buried is None else v.buried))
            else:
                sites.append(VictimSite(v.position, 0.0 if v.buried is None else v.buried))
        use_scene = sc.use_scene_victims if sc.use_scene_victims is not None else not self.victims
        if use_scene:
            taken = {v.scene_victim for v in self.victims if v.scene_victim is not None}
            sites += [s for k, s in enumerate(base.victims) if k not in taken]
        start = self.robot_start if self.robot_start is not None else base.robot_start
        world = replace(base, victims=tuple(sites), robot_start=start)
        _check_world(world, self, where)
        return world

    def victim_specs(self, world: World) -> list[VictimSpec]:
        """One spec per victim of ``world`` (explicit ones first, then defaults for scene sites)."""
        specs = list(self.victims)
        specs += [VictimSpec(position=s.position, buried=s.buried) for s in world.victims[len(specs):]]
        return specs

    def sources(self, world: World, seed: int | None = None, fs: int = 16000) -> list[SoundSource]:
        """Sound sources of a run: the victims (in ``world.victims`` order), then the interferers."""
        seed = self.seed if seed is None else seed
        out = []
        for i, (v, site) in enumerate(zip(self.victim_specs(world), world.victims)):
            speaker = v.speaker or _SPEAKER_CYCLE[i % len(_SPEAKER_CYCLE)]
            if v.sound == "file":
                sig = LoopedSignal(_resample(v.samples, v.file_fs, fs), fs)
            elif v.sound == "continuous":
                sig = continuous_voice(speaker, seed=seed, fs=fs, stream=1000 + i)
            else:
                sig = victim_voice(v.sound, speaker, seed=seed, fs=fs, period_s=v.period_s, p_event=v.p_event,
                                   stream=1000 + i)
            name = v.name or f"victim{i}"
            out.append(SoundSource(site.position, sig, v.level_db_spl, site.buried, "victim", name))
        for j, s in enumerate(self.interferers):
            name = s.name or f"{s.kind}{j}"
            if s.kind in ("pump", "generator"):
                src = noise_source(s.position, s.kind, s.level_db_spl, seed=seed + 7919 * (j + 1), fs=fs)
                out.append(replace(src, name=name))
            elif s.kind == "talker":
                sig = continuous_voice(s.speaker, seed=seed, fs=fs, stream=2000 + j)
                out.append(SoundSource(s.position, sig, s.level_db_spl, 0.0, "talker", name))
            else:
                sig = LoopedSignal(_resample(s.samples, s.file_fs, fs), fs)
                out.append(SoundSource(s.position, sig, s.level_db_spl, 0.0, "interferer", name))
        return out

    def acoustic_config(self, seed: int | None = None) -> AcousticConfig:
        seed = self.seed if seed is None else seed
        return AcousticConfig(seed=seed, ambient=self.noise, **self.acoustics)

    def hal(self, seed: int | None = None, world: World | None = None):
        """The simulated robot's HAL for a run with ``seed``: ``ssl_sim.backends.SimHal`` (robot,
        acoustics, audio, drive, clock) in ``world`` (default ``self.world(seed)``), robot at the start."""
        from ssl_sim.backends import make_sim_hal

        seed = self.seed if seed is None else seed
        world = world if world is not None else self.world(seed)
        return make_sim_hal(world, sources=self.sources(world, seed, fs=self.localizer.fs),
                            acoustic_config=self.acoustic_config(seed), ego_noise=self.ego_noise)


_SPEAKER_CYCLE = ("male", "female", "male_low", "female_high", "child", "elderly_male", "male_high", "female_low")


def _where(path: str) -> str:
    return f"{Path(path).name}: " if path else ""


#: The run's truth grid (``ssl_sim.runner.FreeSpacePaths``: 5 cm cells of the free floor, 16-connected, for the
#: shortest paths of the score): tracemalloc peak 265-531 bytes per cell on the shipped scenes (more free floor,
#: more edges); 600 taken. Rooms needing more than ``MAX_TRUTH_GRID_MB`` are refused when the world is built.
TRUTH_GRID_BYTES_PER_CELL = 600
MAX_TRUTH_GRID_MB = 2048.0


def _check_world(world: World, sc: Scenario, where: str) -> None:
    """The room's truth grid within memory; victims in air, in the room, apart from the start; the start on free
    floor; all reachable."""
    room = world.room
    cells = math.ceil(room.size[0] / 0.05) * math.ceil(room.size[1] / 0.05)
    need_mb = cells * TRUTH_GRID_BYTES_PER_CELL / 1e6
    if need_mb > MAX_TRUTH_GRID_MB:
        raise ScenarioError(f"{where}scene room.size: {room.size[0]:g} x {room.size[1]:g} m: the run's free-space "
                            f"grid (5 cm cells, for the score's shortest paths) has {cells} cells and needs about "
                            f"{need_mb:.0f} MB, more than {MAX_TRUTH_GRID_MB:g} MB")
    x, y, yaw = world.robot_start
    if not room.contains([x, y, 1.0], margin=0.2):
        raise ScenarioError(f"{where}robot.start: ({x}, {y}) is outside the room {list(room.size)} "
                            "(needs 0.2 m clearance from the walls)")
    hit = world.inside_obstacle([x, y, 0.05], margin=RobotModelConfig().bumper_radius)
    if hit is not None:
        b = world.obstacles[hit]
        raise ScenarioError(f"{where}robot.start: ({x}, {y}) overlaps obstacle {hit} ({b.kind} at "
                            f"{list(b.center)}); the robot needs {RobotModelConfig().bumper_radius} m of free floor")
    # Refused rather than settled: on debris the physics shoves the robot before its first command (measured in
    # light_rubble: up to 11 cm and 11 deg within 1 s; up to 0.19 m and -96 deg measured elsewhere), and its odometry would
    # start from a pose it is not at.
    r = RobotModelConfig().bumper_radius
    for k, b in enumerate(world.obstacles):
        if b.climbable and _footprint_distance(b, x, y) < r:
            raise ScenarioError(f"{where}robot.start: ({x}, {y}) puts the robot on climbable debris (obstacle {k}, "
                                f"{b.kind} at {list(b.center)}, size {list(b.size)}); start it on flat floor, "
                                f"{r} m (its radius) from any debris")
    n_explicit = len(sc.victims)
    for i, v in enumerate(world.victims):
        field_name = f"victims[{i}].position" if i < n_explicit else f"scene victim site {i - n_explicit}"
        p = np.asarray(v.position)
        if not room.contains(p, margin=0.05):
            raise ScenarioError(f"{where}{field_name}: {list(v.position)} is outside the room "
                                f"{list(room.size)} m (needs 5 cm clearance)")
        hit = world.inside_obstacle(p, margin=0.02, include_climbable=True)
        if hit is not None:
            b = world.obstacles[hit]
            raise ScenarioError(f"{where}{field_name}: {list(v.position)} is inside obstacle {hit} ({b.kind}, "
                                f"centre {list(b.center)}, size {list(b.size)}); a victim's mouth must be in air")
        if math.hypot(p[0] - x, p[1] - y) < REACHED_RADIUS_M:
            raise ScenarioError(f"{where}{field_name}: {list(v.position)} is within {REACHED_RADIUS_M} m of the "
                                "robot start: reached before starting")
    for j, s in enumerate(sc.interferers):
        if not room.contains(s.position, margin=0.05):
            raise ScenarioError(f"{where}interferers[{j}].position: {list(s.position)} is outside the room "
                                f"{list(room.size)} m (needs 5 cm clearance)")
        hit = world.inside_obstacle(s.position, margin=0.02, include_climbable=True)
        if hit is not None:
            raise ScenarioError(f"{where}interferers[{j}].position: {list(s.position)} is inside obstacle {hit} "
                                f"({world.obstacles[hit].kind} at {list(world.obstacles[hit].center)})")
    ok = reachable_victims(world, reach=FIND_BASE_RADIUS_M)
    for i in np.flatnonzero(~ok):
        field_name = f"victims[{i}].position" if i < n_explicit else f"scene victim site {i - n_explicit}"
        raise ScenarioError(f"{where}{field_name}: {list(world.victims[i].position)} cannot be reached: no free "
                            f"path from the robot start to within {FIND_BASE_RADIUS_M} m (where a find is confirmed)")


def _footprint_distance(box, x: float, y: float) -> float:
    """Horizontal distance (m) from (x, y) to ``box``'s footprint (0 inside)."""
    c, s = math.cos(box.yaw), math.sin(box.yaw)
    dx, dy = x - box.center[0], y - box.center[1]
    local = np.abs([c * dx + s * dy, -s * dx + c * dy]) - np.asarray(box.size[:2]) / 2
    return float(np.hypot(*np.maximum(local, 0.0)))


def _resample(x: np.ndarray, fs_in: int, fs_out: int) -> np.ndarray:
    if fs_in == fs_out:
        return x
    from math import gcd

    from scipy.signal import resample_poly
    g = gcd(int(fs_in), int(fs_out))
    return resample_poly(x, fs_out // g, fs_in // g)


# ----------------------------------------------------------------------------- parsing
_TOP_KEYS = {"name", "description", "seed", "time_limit_s", "success_radius_m", "scene", "robot", "victims",
             "interferers", "noise", "acoustics", "localizer", "behaviour", "motion", "sound_map", "planner",
             "occupancy", "coverage", "pursuit", "options", "recovery", "ego_noise"}


def scenario_names() -> list[str]:
    return sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))


def resolve_scenario_path(name_or_path: str | Path) -> Path:
    """A shipped scenario by name (``paper_lab``) or a path to a ``.toml`` file."""
    p = Path(name_or_path)
    if p.suffix.lower() == ".toml" or p.exists():
        if not p.exists():
            raise ScenarioError(f"scenario file not found: {p}")
        if not p.is_file():
            raise ScenarioError(f"scenario {p}: is a directory, expected a .toml file or one of {scenario_names()}")
        return p
    q = SCENARIOS_DIR / f"{name_or_path}.toml"
    if not q.exists():
        raise ScenarioError(f"unknown scenario '{name_or_path}': expected one of {scenario_names()} or a .toml file")
    return q


#: The tables whose fields a setting (``load_scenario(settings=...)``) may replace: the robot's and the simulation's
#: configs, not the scene, victims or interferers (a different world, not a different setting of it).
SETTABLE_SECTIONS = ("localizer", "behaviour", "motion", "sound_map", "planner", "occupancy", "coverage", "pursuit",
                     "options", "recovery", "acoustics", "noise", "ego_noise")


def parse_setting(text: str) -> tuple[str, Any]:
    """``"SECTION.FIELD=VALUE"`` (VALUE a TOML value: ``15``, ``0.5``, ``true``, ``"text"``, ``[300, 4000]``) ->
    (``"SECTION.FIELD"``, value). ValueError naming what was expected otherwise."""
    key, sep, raw = str(text).partition("=")
    key = key.strip()
    section, dot, name = key.partition(".")
    if not sep or not dot or not name or "." in name:
        raise ValueError(f"setting {text!r}: expected SECTION.FIELD=VALUE, e.g. behaviour.voice_scan_deg=15")
    if section not in SETTABLE_SECTIONS:
        raise ValueError(f"setting {text!r}: section {section!r} cannot be set; expected one of {list(SETTABLE_SECTIONS)}")
    try:
        value = tomllib.loads(f"v = {raw.strip()}")["v"]
    except tomllib.TOMLDecodeError:
        raise ValueError(f"setting {text!r}: expected a TOML value after '=' (a number, true or false, a quoted "
                         "string or an array)") from None
    return key, value


def load_scenario(name_or_path: str | Path = DEFAULT_SCENARIO, settings: dict[str, Any] | None = None) -> Scenario:
    """Read, validate and return a scenario (its World is built once to check the victims).

    ``settings``: ``{"SECTION.FIELD": value}`` (see :func:`parse_setting`) replacing fields of the file's config
    tables before it is validated, as if the file said so: an unknown field or a bad value is refused by name."""
    p = resolve_scenario_path(name_or_path)
    try:
        data = tomllib.loads(p.read_text())
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{p.name}: invalid TOML ({exc})") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"scenario {p}: cannot read it as TOML text ({getattr(exc, 'strerror', None) or exc})") \
            from None
    for key, value in (settings or {}).items():
        section, _, name = key.partition(".")
        if section not in SETTABLE_SECTIONS or not name:
            raise ScenarioError(f"settings: {key!r} is no SECTION.FIELD of {list(SETTABLE_SECTIONS)}")
        table = data.setdefault(section, {})
        if not isinstance(table, dict):
            raise ScenarioError(f"{p.name}: {section}: expected a table, got {type(table).__name__}")
        table[name] = value
    sc = parse_scenario(data, base_dir=p.parent, path=str(p))
    sc.world()  # validates victims/start against the scene
    return sc


def parse_scenario(data: dict, base_dir: str | Path = ".", path: str = "") -> Scenario:
    """Scenario from a parsed TOML mapping; relative file names resolve against ``base_dir``."""
    where = _where(path)
    base_dir = Path(base_dir)

    def err(msg: str) -> ScenarioError:
        return ScenarioError(where + msg)

    if not isinstance(data, dict):
        raise err(f"expected a TOML table at the top level, got {type(data).__name__}")
    unknown = sorted(set(data) - _TOP_KEYS)
    if unknown:
        raise err(f"unknown key(s) {unknown} at the top level; expected some of {sorted(_TOP_KEYS)}")
    name = _get(data, "name", str, where, default=Path(path).stem or "scenario")
    seed = _get(data, "seed", int, where, default=0)
    if seed < 0:
        raise err(f"seed: expected an integer >= 0, got {seed}")
    time_limit = _get(data, "time_limit_s", float, where, default=120.0)
    if not time_limit > 0:
        raise err(f"time_limit_s: expected a duration > 0 s, got {time_limit}")
    # Older files name the former success criterion; it is now the fixed "reached" radius of ssl_sim.scoring.
    radius = _get(data, "success_radius_m", float, where, default=REACHED_RADIUS_M)
    if radius != REACHED_RADIUS_M:
        raise err(f"success_radius_m: no longer a scenario setting (finds are scored by ssl_sim.scoring: a report "
                  f"within {FIND_REPORT_RADIUS_M} m of a victim with the robot within {FIND_BASE_RADIUS_M} m; "
                  f"'reached' is {REACHED_RADIUS_M} m); expected {REACHED_RADIUS_M} or no key, got {radius}")

    scene = _scene(_table(data, "scene", where, required=True), base_dir, where)
    robot = _table(data, "robot", where)
    _no_unknown(robot, {"start"}, "robot", where)
    start = _vec(robot["start"], 3, "robot.start", where) if "start" in robot else None

    victims = tuple(_victim(v, i, base_dir, where) for i, v in enumerate(_array(data, "victims", where)))
    interferers = tuple(_interferer(v, i, base_dir, where) for i, v in enumerate(_array(data, "interferers", where)))
    if not victims and scene.use_scene_victims is False:
        raise err("victims: no victims (none listed and scene.use_scene_victims = false)")

    noise_t = _table(data, "noise", where)
    if noise_t.get("enabled", True) is False:
        _no_unknown(noise_t, {"enabled"}, "noise", where)
        noise = None
    else:
        noise = _dataclass(AmbientNoise, {k: v for k, v in noise_t.items() if k != "enabled"}, "noise", where)
    ego_t = _table(data, "ego_noise", where)
    if ego_t.get("enabled", True) is False:
        _no_unknown(ego_t, {"enabled"}, "ego_noise", where)
        ego_noise = None
    else:
        if "enabled" in ego_t and ego_t["enabled"] is not True:
            raise err(f"ego_noise.enabled: expected true or false, got {ego_t['enabled']!r}")
        ego_noise = _dataclass(EgoNoiseConfig, {k: v for k, v in ego_t.items() if k != "enabled"}, "ego_noise", where)
    acoustics_t = _table(data, "acoustics", where)
    _no_unknown(acoustics_t, set(ACOUSTIC_FIELDS), "acoustics", where)
    acoustics = _typed_kwargs(AcousticConfig, acoustics_t, "acoustics", where)
    try:
        AcousticConfig(**acoustics)
    except ValueError as exc:
        raise err(in_section(str(exc), AcousticConfig, "acoustics")) from None
    localizer = _dataclass(LocalizerConfig, _table(data, "localizer", where), "localizer", where)
    _check_localizer(localizer, AcousticConfig(**acoustics).fs, where)
    behaviour = _dataclass(RescueConfig, _table(data, "behaviour", where), "behaviour", where)
    if behaviour.listen_s * localizer.fs < localizer.frame_size:
        raise err(f"behaviour.listen_s: {behaviour.listen_s} s is shorter than one localizer frame")
    stages = {key: _dataclass(cls, _table(data, key, where), key, where)
              for key, cls in (("motion", MotionConfig), ("sound_map", SoundMapConfig), ("planner", PlannerConfig),
                               ("occupancy", OccupancyConfig), ("coverage", CoverageConfig),
                               ("pursuit", PursuitConfig), ("options", OptionsConfig), ("recovery", RecoveryConfig))}
    return Scenario(name=name, scene=scene, victims=victims, interferers=interferers,
                    description=_get(data, "description", str, where, default=""), seed=seed,
                    time_limit_s=time_limit, robot_start=start, noise=noise, ego_noise=ego_noise,
                    acoustics=acoustics, localizer=localizer, behaviour=behaviour, path=str(path), **stages)


def _check_localizer(cfg: LocalizerConfig, audio_fs: int, where: str) -> None:
    """What would otherwise fail only when the run builds its Localizer, named now."""
    if cfg.fs != audio_fs:
        raise ScenarioError(f"{where}localizer.fs: {cfg.fs} Hz, but the simulated audio is {audio_fs} Hz; "
                            "leave it out or set it to that")
    try:
        band_bins(cfg.fs, cfg.frame_size, cfg.band_hz)
    except ValueError as exc:
        raise ScenarioError(f"{where}localizer.band_hz: {exc}") from None
    try:   # the simulated robot's cube: its steering tables' memory, estimated before anything is built
        check_table_memory(cfg, len(cube8().pairs))
    except ValueError as exc:
        raise ScenarioError(f"{where}{in_section(str(exc), LocalizerConfig, 'localizer')}") from None


def _scene(t: dict, base_dir: Path, where: str) -> SceneSpec:
    _no_unknown(t, {"name", "file", "generate", "seed", "use_scene_victims"}, "scene", where)
    given = [k for k in ("name", "file", "generate") if k in t]
    if len(given) != 1:
        raise ScenarioError(f"{where}scene: expected exactly one of 'name' (one of {scene_names()}), 'file' "
                            f"(a World TOML) or 'generate' (one of {sorted(PRESETS)}), got {given or 'none'}")
    name = _get(t, "name", str, where, "scene.name")
    file = _get(t, "file", str, where, "scene.file")
    gen = _get(t, "generate", str, where, "scene.generate")
    seed = _get(t, "seed", int, where, "scene.seed")
    use = _get(t, "use_scene_victims", bool, where, "scene.use_scene_victims")
    if name is not None and name not in scene_names():
        raise ScenarioError(f"{where}scene.name: unknown scene {name!r}; expected one of {scene_names()}")
    if file is not None:
        fp = (base_dir / file).resolve()
        if not fp.exists():
            raise ScenarioError(f"{where}scene.file: scene file not found: {fp}")
        file = str(fp)
    if gen is not None and gen not in PRESETS:
        raise ScenarioError(f"{where}scene.generate: unknown preset {gen!r}; expected one of {sorted(PRESETS)}")
    if seed is not None and gen is None:
        raise ScenarioError(f"{where}scene.seed: only meaningful with scene.generate")
    if seed is not None and seed < 0:
        raise ScenarioError(f"{where}scene.seed: expected an integer >= 0, got {seed}")
    return SceneSpec(name, file, gen, seed, use)


def _load_wav(file: str, base_dir: Path, what: str, where: str) -> tuple[str, np.ndarray, int]:
    from scipy.io import wavfile

    fp = (base_dir / file).resolve()
    if not fp.exists():
        raise ScenarioError(f"{where}{what}: voice file not found: {fp}")
    try:
        fs, x = wavfile.read(fp)
    except (ValueError, OSError) as exc:
        raise ScenarioError(f"{where}{what}: cannot read {fp} as WAV ({exc})") from None
    x = np.asarray(x)
    if x.dtype.kind in "iu":
        x = x.astype(float) / float(np.iinfo(x.dtype).max)
    x = x.astype(float)
    if not np.all(np.isfinite(x)):
        raise ScenarioError(f"{where}{what}: {fp} holds {np.count_nonzero(~np.isfinite(x))} NaN/infinite samples")
    if x.ndim == 2:
        x = x.mean(axis=1)  # mono: mix the channels
    if x.size < fs // 10 or not np.any(x):
        raise ScenarioError(f"{where}{what}: {fp} is silent or shorter than 0.1 s")
    return str(fp), x, int(fs)


_VICTIM_KEYS = {"position", "scene_victim", "sound", "speaker", "level_db_spl", "buried", "period_s", "p_event",
                "file", "name"}


def _level(t: dict, w: str, where: str, default: float) -> float:
    level = _get(t, "level_db_spl", float, where, f"{w}.level_db_spl", default)
    if not 0 <= level <= 130:
        raise ScenarioError(f"{where}{w}.level_db_spl: expected 0..130 dB SPL at 1 m, got {level}")
    return level


def _sound_file(t: dict, w: str, where: str, base_dir: Path, wanted: bool, how: str):
    """``(file, samples, fs)`` of the WAV named by ``file`` when ``wanted`` (``how`` says which key asks)."""
    file = _get(t, "file", str, where, f"{w}.file")
    if not wanted:
        return file, None, None
    if file is None:
        raise ScenarioError(f"{where}{w}.file: {how} needs file = 'path/to/sound.wav'")
    return _load_wav(file, base_dir, f"{w}.file", where)


def _victim(t: Any, i: int, base_dir: Path, where: str) -> VictimSpec:
    w = f"victims[{i}]"
    if not isinstance(t, dict):
        raise ScenarioError(f"{where}{w}: expected a table ([[victims]]), got {type(t).__name__}")
    _no_unknown(t, _VICTIM_KEYS, w, where)
    has_pos, has_site = "position" in t, "scene_victim" in t
    if has_pos == has_site:
        raise ScenarioError(f"{where}{w}: expected exactly one of 'position' (world m) or 'scene_victim' "
                            "(index of a scene victim site)")
    pos = _vec(t["position"], 3, f"{w}.position", where) if has_pos else None
    site = _get(t, "scene_victim", int, where, f"{w}.scene_victim")
    sound = _get(t, "sound", str, where, f"{w}.sound", "calls")
    if sound not in VICTIM_SOUND_KINDS:
        raise ScenarioError(f"{where}{w}.sound: expected one of {VICTIM_SOUND_KINDS}, got {sound!r}")
    speaker = _get(t, "speaker", str, where, f"{w}.speaker")
    if speaker is not None and speaker not in SPEAKERS:
        raise ScenarioError(f"{where}{w}.speaker: expected one of {sorted(SPEAKERS)}, got {speaker!r}")
    level = _level(t, w, where, PAPER_LEVEL_DB_SPL)
    buried = _get(t, "buried", float, where, f"{w}.buried")
    if buried is not None and not 0 <= buried <= 1:
        raise ScenarioError(f"{where}{w}.buried: expected a fraction in [0, 1], got {buried}")
    period = _get(t, "period_s", float, where, f"{w}.period_s", 2.5)
    p_event = _get(t, "p_event", float, where, f"{w}.p_event", 0.9)
    if not period > 0.2:
        raise ScenarioError(f"{where}{w}.period_s: expected > 0.2 s, got {period}")
    if not 0 < p_event <= 1:
        raise ScenarioError(f"{where}{w}.p_event: expected a probability in (0, 1], got {p_event}")
    file, samples, ffs = _sound_file(t, w, where, base_dir, sound == "file", "sound = 'file'")
    if sound != "file" and file is not None:
        raise ScenarioError(f"{where}{w}.file: only used with sound = 'file' (sound is {sound!r})")
    return VictimSpec(pos, site, sound, speaker, level, buried, period, p_event, file,
                      _get(t, "name", str, where, f"{w}.name", ""), samples, ffs)


def _interferer(t: Any, i: int, base_dir: Path, where: str) -> InterfererSpec:
    w = f"interferers[{i}]"
    if not isinstance(t, dict):
        raise ScenarioError(f"{where}{w}: expected a table ([[interferers]]), got {type(t).__name__}")
    _no_unknown(t, {"kind", "position", "level_db_spl", "speaker", "file", "name"}, w, where)
    kind = _get(t, "kind", str, where, f"{w}.kind")
    if kind not in INTERFERER_KINDS:
        raise ScenarioError(f"{where}{w}.kind: expected one of {INTERFERER_KINDS}, got {kind!r}")
    if "position" not in t:
        raise ScenarioError(f"{where}{w}.position: missing (world m)")
    pos = _vec(t["position"], 3, f"{w}.position", where)
    level = _level(t, w, where, 72.0)
    speaker = _get(t, "speaker", str, where, f"{w}.speaker", "male")
    if speaker not in SPEAKERS:
        raise ScenarioError(f"{where}{w}.speaker: expected one of {sorted(SPEAKERS)}, got {speaker!r}")
    file, samples, ffs = _sound_file(t, w, where, base_dir, kind == "file", "kind = 'file'")
    return InterfererSpec(kind, pos, level, speaker, file, _get(t, "name", str, where, f"{w}.name", ""), samples, ffs)


# -- small typed accessors ------------------------------------------------------------------


def _check_type(value: Any, typ: type, what: str, where: str) -> Any:
    try:
        return check_scalar(value, typ, what)
    except ValueError as exc:
        raise ScenarioError(f"{where}{exc}") from None


def _get(t: dict, key: str, typ: type, where: str, what: str | None = None, default: Any = None) -> Any:
    if key not in t:
        return default
    return _check_type(t[key], typ, what or key, where)


def _vec(value: Any, n: int, what: str, where: str) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise ScenarioError(f"{where}{what}: expected a list of {n} numbers, got {value!r}")
    return tuple(_check_type(v, float, what, where) for v in value)


def _table(data: dict, key: str, where: str, required: bool = False) -> dict:
    if key not in data:
        if required:
            raise ScenarioError(f"{where}{key}: missing [{key}] table")
        return {}
    t = data[key]
    if not isinstance(t, dict):
        raise ScenarioError(f"{where}{key}: expected a table [{key}], got {type(t).__name__}")
    return t


def _array(data: dict, key: str, where: str) -> list:
    v = data.get(key, [])
    if not isinstance(v, list):
        raise ScenarioError(f"{where}{key}: expected an array of tables [[{key}]], got {type(v).__name__}")
    return v


def _no_unknown(t: dict, known: set[str], what: str, where: str) -> None:
    unknown = sorted(set(t) - known)
    if unknown:
        raise ScenarioError(f"{where}{what}: unknown key(s) {unknown}; expected some of {sorted(known)}")


def _typed_kwargs(cls, t: dict, what: str, where: str) -> dict[str, Any]:
    """Check ``t``'s values against the field annotations of dataclass ``cls`` (robot.config_values)."""
    try:
        return field_values(cls, t, what)
    except ValueError as exc:
        raise ScenarioError(f"{where}{exc}") from None


def _dataclass(cls, t: dict, what: str, where: str):
    kwargs = _typed_kwargs(cls, t, what, where)
    try:
        return cls(**kwargs)
    except (ValueError, TypeError) as exc:   # "Class.field=..." named as the file's "section.field=..."
        raise ScenarioError(f"{where}{in_section(str(exc), cls, what)}") from None
