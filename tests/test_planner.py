"""Occupancy grid learned by touch and the planner on it, checked against the geometry put in."""
import dataclasses
import math

import numpy as np
import pytest

from robot.coverage import ListeningCoverage
from robot.occupancy import OccupancyConfig, OccupancyGrid
from robot.planner import Planner, PlannerConfig
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


def test_target_prefers_victims_interferers_last_never_found_or_rejected():
    g = OccupancyGrid()
    pump = _src(0, (0.8, 0.0), 0.05, SourceClass.INTERFERER)
    far_victim = _src(1, (3.0, 0.0), 0.9, SourceClass.VICTIM)
    found = _src(2, (1.0, 1.0), 0.95, SourceClass.VICTIM, SourceState.FOUND)
    unknown = _src(3, (-0.5, -1.0), 0.5, SourceClass.UNKNOWN)   # 1.6 m from the pump: not its image
    pl = Planner()
    s, plan, why = pl.choose_target([pump, far_victim, found, unknown], g, (0.0, 0.0, 0.0), 12.0)
    assert s.id == 1 and plan is not None          # the far victim, not the near pump or unknown source
    s, _, _ = pl.choose_target([pump, found, unknown], g, (0.0, 0.0, 0.0), 12.0)
    assert s.id == 3                                # no victim: the unclassified one, not the pump
    s, _, why = pl.choose_target([pump, found], g, (0.0, 0.0, 0.0), 12.0)
    assert s.id == 0 and "check" in why             # only a machine mapped: go and check it
    rejected = _src(0, (0.8, 0.0), 0.05, SourceClass.INTERFERER, SourceState.REJECTED)
    s, plan, _ = pl.choose_target([rejected, found], g, (0.0, 0.0, 0.0), 12.0)
    assert s is None and plan is None


def test_a_voiceless_source_mapped_outside_the_search_area_is_no_target():
    """A room from (-1, -1) to (4, 3): an unclassified source estimated 1 m beyond its east wall (a mirror image
    in it) is not approached; inside the room it is, and so is one classified victim beyond the wall."""
    g = OccupancyGrid()
    room = (-1.0, -1.0, 4.0, 3.0)
    image = _src(0, (5.0, 0.0), 0.42, SourceClass.UNKNOWN)
    assert Planner().choose_target([image], g, (0.0, 0.0, 0.0), 12.0, area=room)[0] is None
    assert Planner().choose_target([image], g, (0.0, 0.0, 0.0), 12.0)[0].id == 0              # no area known
    inside = _src(1, (3.8, 0.0), 0.42, SourceClass.UNKNOWN)
    assert Planner().choose_target([image, inside], g, (0.0, 0.0, 0.0), 12.0, area=room)[0].id == 1
    voiced = _src(2, (5.0, 1.0), 0.9, SourceClass.VICTIM)
    assert Planner().choose_target([image, voiced], g, (0.0, 0.0, 0.0), 12.0, area=room)[0].id == 2


def test_current_target_kept_unless_clearly_better():
    g = OccupancyGrid()
    a = _src(0, (2.0, 0.0), 0.8, SourceClass.VICTIM)
    b = _src(1, (0.0, 1.8), 0.8, SourceClass.VICTIM)
    pl = Planner(PlannerConfig(keep_factor=1.5))
    assert pl.choose_target([a, b], g, (0, 0, 0), 10.0, current=0)[0].id == 0
    assert pl.choose_target([a, b], g, (0, 0, 0), 10.0, current=1)[0].id == 1


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


def test_machine_image_needs_no_voice_and_the_machine_near_or_on_its_bearings():
    from robot.sound_map import Listen
    pump = _src(0, (3.0, 0.0), 0.05, SourceClass.INTERFERER)
    ray = Listen(1.0, (0.0, 0.0, 0.3), (1.0, 0.0, 0.0), None, 0.42, -40.0, 1.0)   # heard toward the pump
    voiced = Listen(2.0, (0.0, 0.0, 0.3), (1.0, 0.0, 0.0), None, 0.9, -40.0, 1.0)
    off = Listen(1.0, (0.0, 0.0, 0.3), (0.0, 1.0, 0.0), None, 0.42, -40.0, 1.0)    # 90 deg off the pump
    beyond = MapSource(1, np.array([6.0, 0.0, 0.1]), np.eye(3), 0.4, SourceClass.UNKNOWN, SourceState.UNVISITED,
                       1, 1, 0.0, 1.0, -40.0, -40.0, (ray,))
    pl = Planner()
    assert pl.machine_image(beyond, [pump])                       # 3 m beyond the pump, on its bearing
    assert not pl.machine_image(dataclasses.replace(beyond, history=(ray, voiced)), [pump])   # a voice was heard
    aside = dataclasses.replace(beyond, position=np.array([0.0, 2.0, 0.1]), history=(off,))
    assert not pl.machine_image(aside, [pump])                    # 3.6 m from it, heard 90 deg off its bearing
    near = dataclasses.replace(aside, position=np.array([3.0, 1.2, 0.1]))
    assert pl.machine_image(near, [pump])                         # 1.2 m from it


def test_an_unclassified_source_heard_once_is_no_target_a_victim_heard_once_is():
    """One voiceless peak (beside a machine mostly its reflection) is not worth a trip until heard again; one
    listen with speech is."""
    g = OccupancyGrid()
    once = dataclasses.replace(_src(0, (1.5, 0.0), 0.42, SourceClass.UNKNOWN), n_listens=1, n_inliers=1)
    s, plan, why = Planner().choose_target([once], g, (0.0, 0.0, 0.0), 12.0)
    assert s is None and plan is None and "no unfound source" in why
    twice = dataclasses.replace(once, n_listens=2, n_inliers=2)
    assert Planner().choose_target([twice], g, (0.0, 0.0, 0.0), 12.0)[0].id == 0
    voiced = dataclasses.replace(once, id=1, victim_probability=0.9, cls=SourceClass.VICTIM)
    assert Planner().choose_target([once, voiced], g, (0.0, 0.0, 0.0), 12.0)[0].id == 1
    assert Planner(PlannerConfig(min_unknown_listens=1)).choose_target([once], g, (0.0, 0.0, 0.0), 12.0)[0].id == 0
    with pytest.raises(ValueError, match="min_unknown_listens"):
        PlannerConfig(min_unknown_listens=0)
