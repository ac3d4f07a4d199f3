"""What to do next, in one currency: expected victims confirmed per second of robot time.

Options (``OptionKind``), each valued from the belief (world/odometry frame):

* **approach** a mapped source: ``P(victim there) / (t_drive(path + sigma) + t_confirm)``. P(victim there) is the
  map's voice evidence after the pursuit's misses (``robot.pursuit``) times the mass of the estimate's Gaussian
  inside the search area (a mirror image beyond a wall, a machine outside the area: little mass, little value).
  Bearings heard on the way narrow a loose estimate, and its 1-sigma is the path it may still move by: a loose
  estimate costs time, not probability. ``t_drive`` is the path at the drive speed plus a listen per step;
  ``t_confirm`` the cycle time over the per-listen confirm probability;
* **triangulate** (a step of ``baseline_step_m`` across the bearing): the same victim, after the step, with the
  1-sigma one more bearing from the new pose gives (range x bearing noise / sin(angle the step subtends)): worth
  more than approaching when the step costs less than the spread it removes (information gain in time);
* **explore** (drive to where a listen hears the most still-unheard floor, ``robot.coverage``) and **listen** again
  where the robot stands: the prior density of callers times the floor a listen there would newly hear times the
  detection probability, each caller heard costing ``follow_s`` more to confirm;
* **recover** when nothing else has a path (``robot.recovery``): worth nothing by itself, it frees the robot.

The best option wins; the one being carried out counts ``keep_factor`` times (hysteresis: a value that moves by
rounding must not flip the choice).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Sequence

import numpy as np
from scipy.special import ndtr

from robot.config_values import need
from robot.coverage import ListeningCoverage
from robot.found import FIND_RADIUS_M
from robot.occupancy import OccupancyGrid
from robot.planner import Plan, Planner
from robot.pursuit import Pursuits
from robot.sound_map import MapSource, SourceClass, SourceState

__all__ = ["OptionKind", "Option", "OptionsConfig", "Timing", "area_mass", "choose"]


class OptionKind(StrEnum):
    APPROACH = "approach"
    TRIANGULATE = "triangulate"
    EXPLORE = "explore"
    LISTEN = "listen"
    RECOVER = "recover"


@dataclass(frozen=True)
class Option:
    kind: OptionKind
    value: float                       # expected victims confirmed per second
    plan: Plan | None = None           # the path (world m); None: stand and listen (or recover)
    source: MapSource | None = None
    why: str = ""


@dataclass(frozen=True)
class OptionsConfig:
    """``victims_per_m2``: prior density of callers on the search floor (fitted: the train split's victims per
    m^2 of room floor). ``follow_s``: time from hearing a new caller to confirming her (a choice: the train
    split's mean time from first hearing to a find). ``baseline_step_m``: the step across a bearing (a choice:
    0.4 m subtends 11 deg at 2 m, two bearing sigmas)."""

    victims_per_m2: float | None = None   # None: the fitted value (robot/models/found_model.json)
    follow_s: float = 40.0
    baseline_step_m: float = 0.4

    def __post_init__(self) -> None:
        need(self, self.victims_per_m2 is None or self.victims_per_m2 > 0, "victims_per_m2",
             "> 0 per m^2, or None for the fitted value")
        need(self, self.follow_s > 0, "follow_s", "> 0 s")
        need(self, self.baseline_step_m > 0, "baseline_step_m", "> 0 m")


@dataclass(frozen=True)
class Timing:
    """The robot's time costs: drive speed (m/s), one listen cycle (settle + listen, s), the longest step between
    two listens (m), the per-listen confirm probability and one bearing's noise (rad)."""

    speed: float
    cycle_s: float
    step_m: float
    confirm_probability: float
    bearing_sigma: float

    def drive_s(self, length_m: float) -> float:
        return length_m / self.speed + math.ceil(max(length_m, 0.0) / self.step_m) * self.cycle_s

    @property
    def confirm_s(self) -> float:
        return self.cycle_s / self.confirm_probability


def _across(grid: OccupancyGrid, xy: np.ndarray, target_xy, step: float) -> np.ndarray | None:
    """A point ``step`` m from ``xy`` at right angles to the bearing to ``target_xy``: counter-clockwise round it
    (always the same way: each step widens the angle the bearings cross at), else clockwise if that cell is
    blocked; None if both are."""
    b = math.atan2(target_xy[1] - xy[1], target_xy[0] - xy[0])
    for side in (1.0, -1.0):
        goal = xy + step * np.array([math.cos(b + side * math.pi / 2), math.sin(b + side * math.pi / 2)])
        ij = grid.cell(goal)
        if grid.inside(ij) and not grid.blocked[ij]:
            return goal
    return None


def area_mass(s: MapSource, area: tuple[float, float, float, float] | None) -> float:
    """Mass of the source's horizontal Gaussian inside the search area (1 without one)."""
    if area is None:
        return 1.0
    sig = max(s.horizontal_sigma_m, 0.05)
    x, y = s.position[:2]
    return float((ndtr((area[2] - x) / sig) - ndtr((area[0] - x) / sig))
                 * (ndtr((area[3] - y) / sig) - ndtr((area[1] - y) / sig)))


def choose(sources: Sequence[MapSource], pursuits: Pursuits, planner: Planner, grid: OccupancyGrid,
           coverage: ListeningCoverage, pose, now: float, timing: Timing, config: OptionsConfig,
           current: int | None = None, listening_area: float | None = None) -> Option:
    """The most valuable option from ``pose`` (x, y, yaw: world m, rad) at time ``now`` (s)."""
    xy = np.asarray(pose[:2], float)
    keep = planner.config.keep_factor
    search = planner.distances(grid, xy, coverage.config.area)
    machines = [s.position[:2] for s in sources if s.cls is SourceClass.INTERFERER and s.state is not SourceState.FOUND]
    found = [s.position[:2] for s in sources if s.state is SourceState.FOUND]
    options: list[Option] = []
    for s in sources:
        if s.state is SourceState.FOUND or not pursuits.available(s.id, now):
            continue
        p = pursuits.posterior(s.id, s.victim_probability) * area_mass(s, coverage.config.area)
        if p <= 0:
            continue
        bonus = keep if s.id == current else 1.0
        sig = s.horizontal_sigma_m
        plan = planner.plan(grid, xy, planner.goal_of(s, pose), _search=search)
        if plan is not None:
            # Bearings taken on the way narrow the estimate; its spread costs the path it may move by.
            v = bonus * p / (timing.drive_s(plan.length + sig) + timing.confirm_s)
            options.append(Option(OptionKind.APPROACH, v, plan, s,
                                  f"P(victim there) {p:.2f}, +- {sig:.2f} m, path {plan.length:.2f} m"))
        d = s.distance_to(xy)
        if sig > FIND_RADIUS_M and d > 1e-6:
            step = config.baseline_step_m
            after = min(sig, max(0.05, d * timing.bearing_sigma / math.sin(math.atan2(step, d))))
            v = bonus * p / (timing.drive_s(step) + timing.drive_s(d + after) + timing.confirm_s)
            goal = _across(grid, xy, s.position[:2], step)
            if goal is not None:
                options.append(Option(OptionKind.TRIANGULATE, v, Plan(goal[None], step), s,
                                      f"P(victim there) {p:.2f}, +- {sig:.2f} m now, ~{after:.2f} m after a "
                                      f"{step:g} m step across its bearing"))
    gain = coverage.gain(machines)
    area = listening_area if listening_area is not None else math.pi * coverage.config.hearing_radius_m ** 2

    def heard_per_listen(at) -> float:
        ij = grid.cell(np.asarray(at, float))
        g = float(gain[ij]) if grid.inside(ij) else 0.0
        return config.victims_per_m2 * area * g * coverage.detect_probability(at, machines)

    here = heard_per_listen(xy)
    options.append(Option(OptionKind.LISTEN, here / (timing.cycle_s + config.follow_s), None, None,
                          f"{here:.3f} new victim(s) expected per listen here"))
    plan, how = planner.explore_goal(grid, pose, coverage, found, machines, gain)
    if plan is not None:
        there = heard_per_listen(plan.waypoints[-1])
        v = there / (timing.drive_s(plan.length) + config.follow_s)
        options.append(Option(OptionKind.EXPLORE, v, plan, None, f"{how}; {there:.3f} new victim(s) expected"))
    best = max(options, key=lambda o: o.value)
    if best.value <= 0 and plan is None:
        return Option(OptionKind.RECOVER, 0.0, None, None, f"nothing worth doing has a path ({how})")
    return best
