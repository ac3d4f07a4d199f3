"""Configuration of the ``SSLRescue-v0`` environment: world source, acoustics fidelity, step
timing, action scaling, observation layout and reward terms (SI units, degrees where named)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields, replace
from typing import Any

from ssl_sim.physics.scene_gen import RubbleConfig
from ssl_sim.scoring import FIND_BASE_RADIUS_M

FIDELITIES = ("fast", "full")

#: AcousticConfig fields per fidelity. Both keep the same room model, diffuse late tail (same
#: random realisation: its length depends on the RT60, not on the order), ambient noise and
#: sensor; the fast mode stops the exact image-source model at order 2 instead of 3 (the tail
#: fills the rest with the same expected energy) and loops a 10.24 s realisation of the ambient
#: noise and sensor self-noise (computed once per episode, then cached; same statistics). The
#: fast mode also moves the robot kinematically (``SSLRescueEnv._drive_kinematic``). Measured:
#: ``benchmarks/bench_env.py``.
FIDELITY_ACOUSTICS: dict[str, dict[str, Any]] = {
    "full": {"ism_order": 3},
    "fast": {"ism_order": 2, "noise_loop_s": 10.24},
}

VICTIM_SOUNDS = ("continuous", "calls", "moans", "shouts", "knocks", "mixed")

#: Default generator: a small damaged room, one victim, some rubble. ``victim_reach`` is below
#: the found radius, so every victim's goal region can be reached from the start.
DEFAULT_RUBBLE = RubbleConfig(room_size=(6.0, 5.0, 2.8), block_coverage=0.08, debris_coverage=0.02, n_pillars=1,
                              n_victims=1, victim_modes=("beside", "on"), victim_reach=0.7)


@dataclass(frozen=True)
class RewardConfig:
    """Reward per step = ``progress`` x (shortest-path distance to the nearest not-yet-found victim
    before the step - after it, m) + ``found`` per victim found - ``collision`` if the bumper
    was pressed during the step - ``time`` - ``tip_over`` if the robot tipped over."""

    progress: float = 1.0       # per metre of shortest-path progress
    found: float = 10.0         # per victim found
    collision: float = 0.2      # per step with the bumper pressed
    time: float = 0.01          # per step
    tip_over: float = 10.0      # once, when the robot tips over (episode ends)

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"RewardConfig.{f.name}: expected a finite number >= 0, got {v!r}")


@dataclass(frozen=True)
class EnvConfig:
    """Everything that defines an ``SSLRescue-v0`` task.

    World, in order of precedence: ``scenario`` (a ``ssl_sim/scenarios/*.toml`` name or path, via
    ``ssl_sim.scenario``: its scene, victims, voices, noise, acoustics and success radius), else
    ``scene`` (a named scene or World TOML; its victim sites call with ``victim_sound``), else
    the rubble generator ``rubble`` with ``n_victims`` (if set) and ``scene_seed`` (None: a new
    scene every episode, drawn from the environment's seeded RNG).

    One step = drive ``control_s`` with the commanded twist, stop, wait ``settle_s`` (the robot
    comes to rest), listen ``listen_s`` standing still, localize.
    """

    # -- world ---------------------------------------------------------------------------------
    scenario: str | None = None
    scene: str | None = None
    rubble: RubbleConfig = field(default_factory=lambda: DEFAULT_RUBBLE)
    n_victims: int | None = None
    scene_seed: int | None = None
    min_start_distance_m: float = 1.5   # generated scenes: shortest path start -> every goal region
    # -- acoustics (generator / scene modes; a scenario brings its own) ---------------------------
    fidelity: str = "fast"
    rt60_s: float | None = 0.6          # None: from the surface materials (bare concrete: 2-3 s)
    noise_db_spl: float = 35.0          # diffuse ambient noise at the array
    victim_level_db_spl: float = 65.0   # at 1 m while calling
    victim_sound: str = "continuous"
    # The drive's motor noise at 1 m of one motor at rated speed (ssl_sim.acoustics.ego_noise); None: a silent
    # drive. A scenario brings its own ([ego_noise]).
    ego_noise_db_spl: float | None = 40.0
    # -- timing (s) -------------------------------------------------------------------------------
    control_s: float = 0.5
    settle_s: float = 0.1
    listen_s: float = 0.25
    # -- action scaling ---------------------------------------------------------------------------
    max_speed: float = 0.3              # m/s for |action[0]| = 1 or |action[1]| = 1
    max_turn_rate: float = 1.2          # rad/s for |action[2]| = 1
    # -- observation ------------------------------------------------------------------------------
    coarse_resolution_deg: float = 10.0  # SRP map grid spacing
    resolution_deg: float = 2.0          # detection refinement grid spacing
    n_detections: int = 3                # K: top-K detections reported
    min_power: float = 0.05              # detection threshold (normalised SRP)
    rel_threshold: float = 0.3           # a 2nd..Kth detection's SRP power >= this x the strongest one's
    include_audio: bool = False          # add the raw multichannel audio of the listen window
    # -- task -------------------------------------------------------------------------------------
    found_radius_m: float = 0.75        # horizontal distance robot centre - mouth that finds a victim
    tip_limit_deg: float = 45.0
    reward: RewardConfig = field(default_factory=RewardConfig)
    # -- output -----------------------------------------------------------------------------------
    render_size: tuple[int, int] = (240, 320)  # rgb_array image (height, width)
    rerun: str | None = None            # log episodes with ssl_sim.viz: "save:PATH.rrd" | "spawn" | "connect[:ADDR]"

    def __post_init__(self) -> None:
        def need(ok: bool, name: str, expected: str) -> None:
            if not ok:
                raise ValueError(f"EnvConfig.{name}={getattr(self, name)!r}: expected {expected}")

        need(self.fidelity in FIDELITIES, "fidelity", f"one of {FIDELITIES}")
        need(self.victim_sound in VICTIM_SOUNDS, "victim_sound", f"one of {VICTIM_SOUNDS}")
        need(isinstance(self.rubble, RubbleConfig), "rubble", "a ssl_sim.physics.RubbleConfig")
        need(isinstance(self.reward, RewardConfig), "reward", "a RewardConfig")
        need(self.n_victims is None or (isinstance(self.n_victims, int) and 1 <= self.n_victims <= 6),
             "n_victims", "None or an integer 1..6")
        need(self.scene_seed is None or (isinstance(self.scene_seed, int) and self.scene_seed >= 0),
             "scene_seed", "None or an integer >= 0")
        need(self.rt60_s is None or (math.isfinite(self.rt60_s) and 0 <= self.rt60_s <= 5), "rt60_s",
             "None or 0..5 s")
        need(0 <= self.min_start_distance_m <= 20, "min_start_distance_m", "0..20 m")
        need(-40 <= self.noise_db_spl <= 120, "noise_db_spl", "-40..120 dB SPL")
        need(self.ego_noise_db_spl is None or (math.isfinite(self.ego_noise_db_spl)
                                               and -20 <= self.ego_noise_db_spl <= 100),
             "ego_noise_db_spl", "None or -20..100 dB SPL at 1 m")
        need(0 <= self.victim_level_db_spl <= 130, "victim_level_db_spl", "0..130 dB SPL at 1 m")
        need(0 < self.control_s <= 5, "control_s", "0 < s <= 5")
        need(0 <= self.settle_s <= 2, "settle_s", "0..2 s")
        need(0.064 <= self.listen_s <= 5, "listen_s", "0.064..5 s (at least two 32 ms frames)")
        need(0 < self.max_speed <= 1.0, "max_speed", "0 < m/s <= 1")
        need(0 < self.max_turn_rate <= 6.0, "max_turn_rate", "0 < rad/s <= 6")
        need(2 <= self.coarse_resolution_deg < 45, "coarse_resolution_deg", "2 <= deg < 45")
        need(0 < self.resolution_deg <= self.coarse_resolution_deg, "resolution_deg",
             f"> 0 and <= coarse_resolution_deg ({self.coarse_resolution_deg})")
        need(isinstance(self.n_detections, int) and 1 <= self.n_detections <= 8, "n_detections", "an integer 1..8")
        need(0 <= self.min_power < 1, "min_power", "0 <= power < 1")
        need(0 <= self.rel_threshold <= 1, "rel_threshold", "a fraction of the strongest detection's power in [0, 1]")
        need(0 < self.found_radius_m <= FIND_BASE_RADIUS_M, "found_radius_m",
             f"0 < m <= {FIND_BASE_RADIUS_M} (a find needs the robot within that of her, ssl_sim.scoring)")
        need(0 < self.tip_limit_deg < 90, "tip_limit_deg", "0 < deg < 90")
        if self.rerun is not None:
            from ssl_sim.viz import parse_rerun_target

            parse_rerun_target(self.rerun)  # raises naming the expected forms
        h, w = self.render_size
        need(16 <= h <= 2048 and 16 <= w <= 2048, "render_size", "(height, width) in 16..2048 pixels")

    @property
    def step_s(self) -> float:
        """Simulated time of one step (s)."""
        return self.control_s + self.settle_s + self.listen_s

    def with_overrides(self, **overrides: Any) -> "EnvConfig":
        """A copy with some fields replaced; unknown names raise ValueError listing the valid ones."""
        known = {f.name for f in fields(self)}
        unknown = sorted(set(overrides) - known)
        if unknown:
            raise ValueError(f"EnvConfig: unknown field(s) {unknown}; expected some of {sorted(known)}")
        return replace(self, **overrides)
