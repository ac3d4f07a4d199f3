"""The rescue behaviour's own parameters (``RescueConfig``) and what it reports per victim (``FoundVictim``)."""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import ClassVar

from robot.events import FindCriterion
from robot.protocol import FAULT_NAMES

__all__ = ["RescueConfig", "FoundVictim"]

_GONE = "no decision reads it: found is P(find) >= p_find (robot.found), the next move the option worth most " \
        "(robot.options)"


@dataclass(frozen=True)
class RescueConfig:
    """The behaviour's own parameters (SI units; ``*_deg`` in degrees). The stages have their own configs
    (``[motion]``, ``[sound_map]``, ``[planner]``, ``[occupancy]``, ``[coverage]``, ``[pursuit]``, ``[options]``,
    ``[recovery]`` in a scenario)."""

    listen_s: float = 1.0                  # audio per listen (s)
    settle_s: float = 0.3                  # standing after a move before listening (s): braking sway, motor decay
    min_power: float = 0.0                 # ignore detections with a lower normalised SRP-PHAT power
    voice_threshold: float = 0.1           # VAD speech-frame fraction of a beam counted as voice (robot.listening)
    voice_scan_deg: float = 0.0            # > 0: scan for a voice beside a louder non-voice source (robot.listening)
    p_find: float = 0.45                   # declare a find at P(victim within 0.5 m of the report) >= this (chosen
    #                                        on the train curve: experiments/found_model/p_find_curve.json)
    step_m: float = 0.6                    # longest move between two listens (m)
    listen_while_driving: bool = False     # hear listen_s windows while driving too, when the localizer suppresses
    #                                        the drive's noise (robot.drive_hearing)
    max_victims: int | None = None         # stop after finding this many (None: keep searching)
    fatal_faults: tuple[str, ...] = ("encoder_error",)  # drive faults that end the mission

    #: Fields that no longer exist (robot.config_values.field_values): ignored with a warning.
    RETIRED: ClassVar[dict[str, str]] = {
        **{name: _GONE for name in (
            "require_voice", "found_elevation_deg", "corroborated_elevation_deg", "level_rise_db",
            "found_distance_m", "found_sigma_m", "cue_distance_m", "cue_sigma_m", "reach_elevation_deg",
            "echo_azimuth_deg", "supporting_elevation_deg", "supporting_rise_db", "found_min_power",
            "bump_found_range_m", "bump_ahead_deg", "bump_heard_within_s", "found_exclusion_m",
            "max_contacts_per_target", "max_baseline_steps", "machine_radius_m", "reject_after_listens",
            "refute_after_listens", "mouth_height_m", "short_estimate_m", "explore_after_silent", "min_step_m")},
        "baseline_step_m": "MOVED: options.baseline_step_m",
        "wedged_turn_deg": "MOVED: recovery.wedged_turn_deg",
        "escape_rounds": "MOVED: recovery.escape_rounds",
        "array_height_m": "MOVED: the array's height is robot.mount.ArrayMount.height_m (ssl-robot: --set "
                          "mount.height_m=...; in simulation the robot model's cube height, set by the simulator)",
    }

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, float) and not (math.isfinite(v) and v >= 0):
                raise ValueError(f"RescueConfig.{f.name}: expected a finite number >= 0, got {v}")
        for name in ("listen_s", "step_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"RescueConfig.{name}: expected > 0, got {getattr(self, name)}")
        if not 0 < self.p_find < 1:
            raise ValueError(f"RescueConfig.p_find: expected a probability in (0, 1), got {self.p_find}")
        if not 0 <= self.voice_threshold <= 1:
            raise ValueError(f"RescueConfig.voice_threshold: expected 0..1, got {self.voice_threshold}")
        if not 0 <= self.voice_scan_deg <= 90:
            raise ValueError(f"RescueConfig.voice_scan_deg: expected 0 (off) .. 90 deg, got {self.voice_scan_deg}")
        if not (isinstance(self.fatal_faults, tuple) and set(self.fatal_faults) <= set(FAULT_NAMES.values())):
            raise ValueError(f"RescueConfig.fatal_faults: expected drive fault names out of "
                             f"{sorted(FAULT_NAMES.values())} (an empty list for none), got {self.fatal_faults!r}")
        if self.max_victims is not None and self.max_victims < 1:
            raise ValueError(f"RescueConfig.max_victims: expected None or >= 1, got {self.max_victims}")


@dataclass(frozen=True)
class FoundVictim:
    """A victim declared found: the reported ``position`` (x, y) and ``height`` (m), odometry frame."""

    position: tuple[float, float]
    time: float
    criterion: str            # the decision in words: P(find) and its largest log-odds terms
    height: float
    voice: float = 0.0        # P(victim) of the map source when declared
    source_id: int = -1
    cue: FindCriterion | None = None
