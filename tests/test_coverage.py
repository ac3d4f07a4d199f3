"""Listening coverage (search theory): what a listen covers, against the detection model put in."""
import math

import numpy as np
import pytest

from robot.coverage import CoverageConfig, ListeningCoverage
from robot.occupancy import OccupancyConfig, OccupancyGrid


def _coverage(cfg=CoverageConfig()):
    g = OccupancyGrid(OccupancyConfig(size_m=12.0))
    return g, ListeningCoverage(g.origin, g.n, g.resolution, cfg)


def test_a_listen_covers_the_hearing_disc_with_its_detection_probability():
    g, cov = _coverage()
    cov.listened((1.0, 0.0))
    assert cov.unheard[g.cell((1.0, 1.4))] == pytest.approx(0.5)        # 1.4 m away: inside 1.5 m
    assert cov.unheard[g.cell((1.0, 1.6))] == 1.0                        # 1.6 m away: not covered
    cov.listened((1.0, 0.0))
    assert cov.unheard[g.cell((1.0, 0.0))] == pytest.approx(0.25)        # two independent looks
    cov.listened((-3.0, 0.0), machines=[np.array([-3.0, 2.4])])         # a machine 2.4 m away masks
    assert cov.unheard[g.cell((-3.0, 0.0))] == pytest.approx(1 - 0.12)


def test_gain_is_the_unheard_share_of_the_disc_and_falls_near_a_machine():
    g, cov = _coverage()
    assert cov.gain()[g.cell((0.0, 0.0))] == pytest.approx(1.0)
    cov.listened((0.0, 0.0))
    gain = cov.gain()
    assert gain[g.cell((0.0, 0.0))] == pytest.approx(0.5, abs=0.02)     # the whole disc heard once (cells: 0.1 m)
    # 1.5 m east, the discs overlap by the lens area 2 r^2 acos(d / 2r) - d/2 sqrt(4 r^2 - d^2) (r = d = 1.5)
    r = d = 1.5
    lens = (2 * r * r * math.acos(d / (2 * r)) - d / 2 * math.sqrt(4 * r * r - d * d)) / (math.pi * r * r)
    assert gain[g.cell((1.5, 0.0))] == pytest.approx(1 - 0.5 * lens, abs=0.03)
    machine = np.array([4.0, 0.0])
    near = cov.gain([machine])
    assert near[g.cell((3.0, 0.0))] == pytest.approx(0.12 / 0.5, abs=0.01)   # masked: 0.12 instead of 0.5
    assert near[g.cell((0.0, 3.0))] == pytest.approx(gain[g.cell((0.0, 3.0))])  # 5 m from it: not masked


def test_floor_behind_a_bumper_contact_counts_as_searched():
    g, cov = _coverage()
    cov.shadow((0.0, 0.0), math.pi / 2, 0.3)                                 # a wall met driving north
    assert cov.unheard[g.cell((0.0, 0.5))] == 0.0 and cov.unheard[g.cell((0.0, 0.95))] == 0.0
    assert cov.unheard[g.cell((0.0, -0.2))] == 1.0                           # the robot's side
    assert cov.unheard[g.cell((0.5, 0.5))] == 1.0                            # beside the contact


def test_config_errors_name_the_field():
    with pytest.raises(ValueError, match="detect_probability"):
        CoverageConfig(detect_probability=1.0)
    with pytest.raises(ValueError, match="masked_probability"):
        CoverageConfig(masked_probability=0.6)
    with pytest.raises(ValueError, match="hearing_radius_m"):
        CoverageConfig(hearing_radius_m=0.0)


def test_the_search_area_bounds_the_unheard_floor_and_exploration():
    """A corridor 2 m wide from x = -6 to x = 1 given as the search area, the robot listened at the origin:
    nothing is unheard outside it, and the exploration goal leads along the corridor (west), although the
    floor in every other direction is as unvisited (without the area, east, the first heading, would do)."""
    from robot.planner import Planner
    g, cov = _coverage(CoverageConfig(area=(-6.0, -1.0, 1.0, 1.0)))
    assert cov.unheard[g.cell((0.0, 1.5))] == 0.0 and cov.unheard[g.cell((-3.0, 0.0))] == 1.0
    cov.listened((0.0, 0.0))
    plan, why = Planner().explore_goal(g, (0.0, 0.0, 0.0), cov)
    assert plan is not None, why
    goal = plan.waypoints[-1]
    assert goal[0] < -0.9 and abs(goal[1]) < 1.0, why


def test_no_exploration_goal_when_all_reachable_floor_is_heard():
    """A 3.4 m square room walled in by bumper contacts, listened to from its centre until nothing within the
    hearing radius is unheard: no goal is worth driving to (the behaviour then forgets single contacts and
    looks again), instead of stepping to and fro between goals worth nothing."""
    from robot.planner import Planner
    g, cov = _coverage(CoverageConfig(area=(-1.7, -1.7, 1.7, 1.7)))
    for t in np.arange(-1.7, 1.71, 0.1):
        for p, h in (((t, 1.7 - 0.17), math.pi / 2), ((t, -1.7 + 0.17), -math.pi / 2),
                     ((1.7 - 0.17, t), 0.0), ((-1.7 + 0.17, t), math.pi)):
            g.mark_contact(p, h, "bumper")
    for _ in range(12):
        for p in ((0.0, 0.0), (0.8, 0.8), (-0.8, 0.8), (0.8, -0.8), (-0.8, -0.8)):
            cov.listened(p)
    assert cov.unheard[cov.in_area].max() < 1e-3
    plan, why = Planner().explore_goal(g, (0.0, 0.0, 0.0), cov)
    assert plan is None, why
