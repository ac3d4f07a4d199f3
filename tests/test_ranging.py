"""Range sensors: the simulated rays against box geometry, the occupancy they map, and moves that stop before
what they see (no touch needed)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from robot.hal import DriveStatus
from robot.motion import Blocked, Motion, MotionConfig
from robot.occupancy import OccupancyGrid
from robot.odometry import Odometry
from robot.ranging import RangeLayout, ray_ends
from ssl_sim.physics import SimClock, SimDriveBase, SimRobot
from ssl_sim.world import Box, Room, World

LAYOUT = RangeLayout()
# A 4 x 3 m room with a 0.2 m thick, 1 m wide block whose near face is at x = 1.9 m.
WORLD = World(room=Room(size=(4.0, 3.0, 2.5)), obstacles=(Box((2.0, 1.5, 0.3), (0.2, 1.0, 0.6)),),
              robot_start=(1.0, 1.5, 0.0))


def _expected(x: float, y: float, yaw: float, layout: RangeLayout) -> np.ndarray:
    """Distances from each sensor to the block's near face or the room's walls, by 2D geometry."""
    out = []
    for a in layout.azimuths_rad:
        c, s = math.cos(yaw + a), math.sin(yaw + a)
        sx, sy = x + layout.mount_radius_m * c, y + layout.mount_radius_m * s
        cands = []
        for wall, coord, d in ((0.0, sx, c), (4.0, sx, c)):
            if d * (wall - coord) > 0:
                cands.append((wall - coord) / d)
        for wall, coord, d in ((0.0, sy, s), (3.0, sy, s)):
            if d * (wall - coord) > 0:
                cands.append((wall - coord) / d)
        if c > 1e-9:                               # the block's face x = 1.9, 1.0 <= y <= 2.0
            t = (1.9 - sx) / c
            if t > 0 and 1.0 <= sy + t * s <= 2.0:
                cands.append(t)
        r = min(cands)
        out.append(r if r <= layout.max_range_m else np.inf)
    return np.array(out)


@pytest.mark.parametrize("yaw", [0.0, 0.3, -2.0])
def test_simulated_rays_meet_the_walls_and_the_block_where_geometry_says(yaw):
    robot = SimRobot(WORLD, start=(1.0, 1.5, yaw))
    robot.step(0.3)
    p = robot.pose()
    far = RangeLayout(max_range_m=3.0)
    np.testing.assert_allclose(robot.ray_distances(far), _expected(p.x, p.y, p.yaw, far), atol=2e-3)
    near = robot.ray_distances(LAYOUT)                      # beyond 0.8 m: no return
    np.testing.assert_allclose(near, _expected(p.x, p.y, p.yaw, LAYOUT), atol=2e-3)


def test_sim_drive_reports_ranges_in_whole_centimetres_with_noise_and_none_without_sensors():
    robot = SimRobot(WORLD, start=(1.2, 1.5, 0.0))
    robot.step(0.3)
    drive = SimDriveBase(robot, seed=4)
    truth = robot.ray_distances(LAYOUT)
    assert np.isfinite(truth[0]) and truth[0] == pytest.approx(0.64, abs=0.01)   # the block, 0.64 m ahead
    reads = []
    for _ in range(200):
        robot.step(0.01)
        st = drive.status()
        assert len(st.ranges) == LAYOUT.n
        reads.append(st.ranges)
    r = np.array(reads)
    assert np.all(np.isinf(r[:, np.isinf(truth)]))          # nothing within range stays nothing
    front = r[:, 0]
    np.testing.assert_allclose(front * 100, np.round(front * 100), atol=1e-9)     # whole cm, as the firmware
    assert abs(front.mean() - truth[0]) < 0.01 and 0.005 < front.std() < 0.03      # 2 % of 0.64 m = 1.3 cm
    assert SimDriveBase(robot, range_layout=None).status().ranges is None


def test_ray_ends_are_world_points_of_the_returns():
    layout = RangeLayout(azimuths_rad=(0.0, math.pi / 2))
    starts, ends, hit = ray_ends(layout, (1.0, 2.0, math.pi / 2), (0.5, math.inf))
    np.testing.assert_allclose(starts, [[1.0, 2.06], [0.94, 2.0]], atol=1e-12)
    np.testing.assert_allclose(ends, [[1.0, 2.56], [0.14, 2.0]], atol=1e-12)   # no return: free to 0.8 m
    assert hit.tolist() == [True, False]
    with pytest.raises(ValueError, match="ranges: expected 2 readings"):
        ray_ends(layout, (0, 0, 0), (0.5,))
    with pytest.raises(ValueError, match="ranges"):
        ray_ends(layout, (0, 0, 0), (0.5, np.nan))
    with pytest.raises(ValueError, match="min_range_m"):
        RangeLayout(min_range_m=0.9)


def test_rays_map_a_wall_they_pass_along_and_the_floor_before_it():
    grid = OccupancyGrid(origin=(0.0, 0.0))
    layout = RangeLayout(azimuths_rad=(0.0,))
    for y in np.arange(-0.5, 0.51, 0.05):                  # drive along y, the sensor looking at the wall x = 0.65
        grid.mark_rays(*ray_ends(layout, (0.0, y, 0.0), (0.65 - layout.mount_radius_m,)))
    occ = grid.occupied
    for y in np.arange(-0.4, 0.41, 0.1):
        assert occ[grid.cell((0.65, y))]                       # the wall
        assert not occ[grid.cell((0.3, y))] and grid.range_log_odds[grid.cell((0.3, y))] < 0   # floor before it
    assert not occ[grid.cell((0.65, 1.0))]                     # nothing beyond where the rays looked


def test_one_far_return_is_no_obstacle_yet_a_near_one_is():
    grid = OccupancyGrid(origin=(0.0, 0.0))
    layout = RangeLayout(azimuths_rad=(0.0,))
    grid.mark_rays(*ray_ends(layout, (0.0, 0.0, 0.0), (0.7,)))    # could be the floor seen by a tilted ray
    assert not grid.occupied[grid.cell((0.76, 0.0))]
    grid.mark_rays(*ray_ends(layout, (0.0, 0.0, 0.0), (0.7,)))    # seen again: an obstacle
    assert grid.occupied[grid.cell((0.76, 0.0))]
    grid.mark_rays(*ray_ends(layout, (0.0, 1.0, 0.0), (0.2,)))    # 0.2 m: no floor is seen that close
    assert grid.occupied[grid.cell((0.26, 1.0))]


def test_a_clear_ray_over_low_rubble_does_not_erase_what_the_bumper_found():
    grid = OccupancyGrid(origin=(0.0, 0.0))
    contact = grid.mark_contact((0.0, 0.0, 0.0), 0.0)          # bumper: rubble 0.2 m ahead, below the rays
    layout = RangeLayout(azimuths_rad=(0.0,))
    for _ in range(20):
        grid.mark_rays(*ray_ends(layout, (0.0, 0.0, 0.0), (math.inf,)))
    assert grid.occupied[grid.cell(contact)]


def _motion_toward_the_block(yaw_start: float):
    robot = SimRobot(WORLD, start=(1.0, 1.5, yaw_start))
    robot.step(0.2)
    drive, clock = SimDriveBase(robot, seed=1), SimClock(robot)
    p = robot.pose()
    motion = Motion(drive, clock, Odometry(start_pose=(p.x, p.y, p.yaw)), MotionConfig(), range_layout=LAYOUT)
    return robot, motion


def test_a_move_stops_before_an_obstacle_its_sensors_see_without_touching_it():
    robot, motion = _motion_toward_the_block(0.0)
    with pytest.raises(Blocked) as exc:
        motion.translate(0.0, 1.5, stop_for_ranges=True)       # straight at the block's face (x = 1.9)
    assert exc.value.kind == "range"
    gap = 1.9 - (robot.pose().x + MotionConfig().body_radius_m)
    assert not robot.bumper() and 0.0 < gap <= MotionConfig().range_stop_m + 0.02
    # Moving along the face, it is not in the way; the same move blind to ranges ends on the bumper.
    motion.translate(math.pi / 2, 0.3, stop_for_ranges=True)
    with pytest.raises(Blocked) as exc:
        motion.translate(0.0, 0.5)
    assert exc.value.kind == "bumper"


def test_a_move_past_an_obstacle_beside_the_path_does_not_stop():
    robot, motion = _motion_toward_the_block(math.pi / 2)       # facing +y; the block's face is to the right
    motion.translate(-math.pi / 2, 0.5, stop_for_ranges=True)   # right, toward it: the bumper stops 0.24 m short
    motion.translate(0.0, 0.4, stop_for_ranges=True)           # forward along the face, 0.24 m beside the path
    p = robot.pose()
    assert p.x == pytest.approx(1.5, abs=0.03) and p.y == pytest.approx(1.9, abs=0.03) and not robot.bumper()
