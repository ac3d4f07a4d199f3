"""Occupancy grid learned by touch and the planner on it, checked against the geometry put in."""
import dataclasses
import math

import numpy as np
import pytest

from robot.coverage import ListeningCoverage
from robot.occupancy import OccupancyConfig, OccupancyGrid
from robot.planner import Planner, PlannerConfig, path_start
from robot.sound_map import MapSource, SourceClass, SourceState


def _wall_grid():
    """A wall along x = 2 from y = -1 to y = 1.5, learned from bumps driving +x along it."""
    g = OccupancyGrid(OccupancyConfig(size_m=8.0), origin=(1.0, 0.0))
    for y in np.arange(-1.0, 1.51, 0.25):
        g.mark_contact((2.0 - 0.17, y), 0.0)
    return g


def _listened(g, points, machines=()):
    """Listening coverage of grid ``g`` after a listen at each of ``points`` (world x, y)."""
    cov = ListeningCoverage(g.origin, g.n, g.resolution)
    for p in points:
        cov.listened(p, machines)
    return cov


def test_contact_marks_a_face_ahead_and_driving_clears():
    g = OccupancyGrid()
    c = g.mark_contact((1.0, 1.0, 0.0), math.pi / 2)
    assert abs(c[0] - 1.0) < 1e-9 and 1.16 < c[1] < 1.25
    assert g.occupied[g.cell(c)] and not g.occupied[g.cell((1.0, 1.0))]
    assert g.blocked[g.cell((1.0, 1.05))]            # the robot centre cannot be within its radius of it
    for _ in range(6):
        g.mark_path((1.0, 0.5), (1.0, 1.3))
    assert not g.occupied[g.cell(c)]                 # driven through it often: it was not an obstacle


def test_path_goes_around_a_learned_wall():
    g = _wall_grid()
    p = Planner().plan(g, (0.0, 0.0), (4.0, 0.0), stop_radius=0.2)
    assert p is not None
    pts = np.vstack([[0.0, 0.0], p.waypoints])
    # never crosses the wall's span: every segment crossing x = 2 does so at y > 1.5 + radius or y < -1 - radius
    for a, b in zip(pts[:-1], pts[1:]):
        if (a[0] - 2) * (b[0] - 2) < 0:
            y = a[1] + (2 - a[0]) * (b[1] - a[1]) / (b[0] - a[0])
            assert y > 1.5 + 0.16 or y < -1.0 - 0.16
    straight = 4.0 - 0.2
    assert straight < p.length < 2.2 * straight
    assert np.hypot(*(p.waypoints[-1] - [4.0, 0.0])) <= 0.2 + 0.1


def test_unreachable_goal_gives_none():
    g = OccupancyGrid(OccupancyConfig(size_m=6.0))
    for a in np.linspace(0, 2 * math.pi, 48, endpoint=False):   # a closed ring of contacts around (2, 0)
        g.mark_contact((2 + 0.5 * math.cos(a), 0.5 * math.sin(a)), a)
    assert Planner().plan(g, (0.0, 0.0), (2.0, 0.0), stop_radius=0.1) is None


def _src(i, xy, p, cls, state=SourceState.UNVISITED, last=10.0):
    return MapSource(i, np.array([*xy, 0.1]), np.eye(3) * 0.01, p, cls, state, 5, 5, 0.0, last, -30.0, -30.0, ())


def test_explore_goes_to_unheard_floor_away_from_found_victims():
    g = OccupancyGrid()
    g.mark_path((-3.0, 0.0), (0.0, 0.0))               # came from -x, listening every 0.6 m
    cov = _listened(g, [(x, 0.0) for x in np.arange(-3.0, 0.01, 0.6)])
    plan, why = Planner().explore_goal(g, (0.0, 0.0, 0.0), cov, avoid=[np.array([0.0, -1.0])])
    goal = plan.waypoints[-1]
    assert goal[0] > -0.3 and goal[1] > -0.3           # not back along the path, not toward the found victim


def test_a_stall_alone_is_no_obstacle_two_are_and_forget_drops_single_contacts():
    g = OccupancyGrid()
    c = g.mark_contact((1.0, 1.0, 0.0), 0.0, "stall")
    assert not g.occupied[g.cell(c)]                 # wheels stall on debris they could cross
    g.mark_contact((1.0, 1.0, 0.0), 0.0, "stall")
    assert g.occupied[g.cell(c)]                     # stalled twice at one place: an obstacle
    b = g.mark_contact((-1.0, -1.0, 0.0), math.pi, "bumper")
    assert g.occupied[g.cell(b)]                     # one bumper press is
    g.mark_contact((3.0, 0.0, 0.0), 0.0, "bumper")
    twice = g.mark_contact((3.0, 0.0, 0.0), 0.0, "bumper")
    assert g.forget() > 0
    assert not g.occupied[g.cell(b)] and not g.occupied[g.cell(c)]
    assert g.occupied[g.cell(twice)]                 # confirmed by two presses: kept


def _pocket():
    """A room-like pocket around (0, 0) learned by bumper presses: walls 0.5 m away on three sides and a
    wall 0.5 m north with a gap; beyond the gap a 3 m corridor leads north. Truth: the only way out is the gap
    at x in [0.9, 1.5] on y = 0.5."""
    g = OccupancyGrid(OccupancyConfig(size_m=12.0))
    for t in np.arange(-0.6, 1.61, 0.1):
        for _ in range(3):
            g.mark_contact((t, -0.5 + 0.17), -math.pi / 2)        # south wall y = -0.5
            if not 0.8 <= t <= 1.6:
                g.mark_contact((t, 0.5 - 0.17), math.pi / 2)      # north wall, gap at x 0.8-1.6
    for t in np.arange(-0.5, 0.51, 0.1):
        for _ in range(3):
            g.mark_contact((-0.7 + 0.17, t), math.pi)             # west wall x = -0.7
            g.mark_contact((1.7 - 0.17, t), 0.0)                  # east wall x = 1.7
    for t in np.arange(0.5, 3.51, 0.1):
        for _ in range(3):
            g.mark_contact((0.7 + 0.17, t), math.pi)              # corridor walls x = 0.7 and 1.7
            g.mark_contact((1.7 - 0.17, t), 0.0)
    for x in np.arange(-0.5, 1.51, 0.1):                         # the pocket's floor has been covered
        g.mark_path((x, -0.2), (x, 0.2))
    return g


def test_explore_leaves_a_covered_pocket_through_its_only_gap():
    g = _pocket()
    pl = Planner(PlannerConfig(explore_distance_m=1.2))
    plan, why = pl.explore_goal(g, (0.0, 0.0, 0.0), _listened(g, [(-0.3, 0.0), (0.6, 0.0), (1.3, 0.0)]))
    assert plan is not None, why
    pts = np.vstack([[0.0, 0.0], plan.waypoints])
    assert plan.waypoints[-1][1] > 0.5                                 # out of the pocket, north
    for a, b in zip(pts[:-1], pts[1:]):                                # through the gap, never a wall
        if (a[1] - 0.5) * (b[1] - 0.5) < 0:
            x = a[0] + (0.5 - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
            assert 0.8 + 0.16 <= x <= 1.6 - 0.16


def test_config_errors_name_the_field():
    with pytest.raises(ValueError, match="keep_factor"):
        PlannerConfig(keep_factor=0.5)
    with pytest.raises(ValueError, match="resolution_m"):
        OccupancyConfig(resolution_m=0)
    with pytest.raises(ValueError, match="stall_log_odds"):
        OccupancyConfig(stall_log_odds=3.0)


def test_explore_listens_out_of_a_machine_s_masking_and_frontier_goals_stay_near_covered_floor():
    """Covered floor along y = 0 from x = -2 to x = 2, listened to from the origin, a machine at (-2.5, 0): the
    goal lies where a listen is not masked by it (2.5 m or more from it), and a frontier goal is unvisited floor
    next to the covered strip."""
    g = OccupancyGrid(OccupancyConfig(size_m=12.0))
    g.mark_path((-2.0, 0.0), (2.0, 0.0))
    cfg = PlannerConfig()
    machine = [np.array([-2.5, 0.0])]
    cov = _listened(g, [(0.0, 0.0)], machine)
    plan, why = Planner(cfg).explore_goal(g, (0.0, 0.0, 0.0), cov, machines=machine)
    assert plan is not None, why
    assert np.hypot(*(plan.waypoints[-1] - machine[0])) >= cov.config.masked_within_m, why
    plan, why = Planner(cfg)._frontier_goal(g, (0.0, 0.0), cov.gain(machine), None, [],
                                            Planner(cfg).distances(g, (0.0, 0.0)))
    assert plan is not None, why
    visited = np.argwhere(g.visited > 0)
    gap = np.min(np.hypot(*(g.centre(visited) - plan[0].waypoints[-1]).T))
    assert gap <= cfg.frontier_reach_m + g.resolution, why         # not deep in the unknown (a wall may be there)
    assert np.hypot(*(plan[0].waypoints[-1] - machine[0])) >= cov.config.masked_within_m, why





def _half_cell_sight(grid, a, b) -> bool:
    """The planner's line of sight, one segment at a time: no blocked cell under samples every half cell."""
    n = max(2, int(math.ceil(np.linalg.norm(b - a) / (0.5 * grid.resolution))))
    ij = np.floor((a + np.linspace(0, 1, n)[:, None] * (b - a) - grid.origin) / grid.resolution).astype(int)
    ok = (ij >= 0).all(1) & (ij < grid.n).all(1)
    return not grid.blocked[ij[ok, 0], ij[ok, 1]].any()


def test_shortcut_is_the_greedy_farthest_point_in_sight():
    # The batched line-of-sight test against the plain greedy walk: from each waypoint, the farthest later point
    # of the path in sight, else the next point; the same waypoints, bit for bit, on random clutter and paths.
    rng = np.random.default_rng(7)
    g = OccupancyGrid(OccupancyConfig(size_m=6.0, resolution_m=0.1), origin=(0, 0))
    skips = 0
    for _ in range(100):
        g.log_odds[:] = 0
        g.log_odds[rng.random((g.n, g.n)) < rng.uniform(0.0, 0.06)] = 10.0
        g._blocked = None
        path = np.cumsum(rng.normal(0, 0.15, (int(rng.integers(2, 40)), 2)), axis=0)
        want, i = [], 0
        while i < len(path) - 1:
            j = len(path) - 1
            while j > i + 1 and not _half_cell_sight(g, path[i], path[j]):
                j -= 1
            skips += j > i + 1
            want.append(path[j])
            i = j
        assert np.array_equal(Planner._shortcut(g, path), np.array(want).reshape(-1, 2))
    assert skips > 50   # the clutter leaves lines of sight to shortcut along


def test_paths_stay_within_the_margin_of_the_search_area():
    # A 4 x 3 m search area (a floor plan's room) on an 8 m grid with nothing learned yet: a goal 2 m beyond its
    # east edge has no path once the area is given (1 m margin), one without it; a goal inside keeps its path,
    # which never leaves the margin.
    g = OccupancyGrid(OccupancyConfig(size_m=8.0), origin=(2.0, 1.5))
    area = (0.0, 0.0, 4.0, 3.0)
    pl = Planner()
    outside = (6.0, 1.5)
    assert pl.plan(g, (1.0, 1.5), outside, _search=pl.distances(g, (1.0, 1.5))) is not None
    assert pl.plan(g, (1.0, 1.5), outside, _search=pl.distances(g, (1.0, 1.5), area)) is None
    p = pl.plan(g, (1.0, 1.5), (4.8, 2.9), _search=pl.distances(g, (1.0, 1.5), area))
    assert p is not None and np.hypot(*(p.waypoints[-1] - [4.8, 2.9])) <= 0.35 + 0.1
    m = pl.config.search_margin_m + g.resolution
    assert np.all((p.waypoints >= [area[0] - m, area[1] - m]) & (p.waypoints <= [area[2] + m, area[3] + m]))
    # A robot outside the margin (e.g. driven there by hand) still plans: the bound is not applied to it.
    assert pl.plan(g, (5.6, 1.5), (2.0, 1.5), _search=pl.distances(g, (5.6, 1.5), area)) is not None


def test_path_start_cuts_the_polyline_at_the_step_length():
    # an L-shaped path: 0.4 m east, then 1 m north; the first 0.6 m end 0.2 m up the second leg
    legs, total = path_start((1.0, 1.0), [(1.0, 1.0), (1.4, 1.0), (1.4, 2.0)], 0.6)
    assert total == pytest.approx(0.6)
    assert len(legs) == 2
    assert np.allclose(legs[0], (1.4, 1.0)) and np.allclose(legs[1], (1.4, 1.2))
    # a path shorter than the step is driven whole; a repeated waypoint adds no leg
    legs, total = path_start((0.0, 0.0), [(0.3, 0.4), (0.3, 0.4)], 0.6)
    assert total == pytest.approx(0.5) and len(legs) == 1 and np.allclose(legs[0], (0.3, 0.4))
    # standing on the goal: nothing to drive
    legs, total = path_start((2.0, 2.0), [(2.0, 2.0)], 0.6)
    assert legs == [] and total == 0.0
