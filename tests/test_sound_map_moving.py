"""Sound map from bearings heard while driving: each window's ray from the pose at the window's middle."""
from dataclasses import dataclass

import numpy as np
import pytest

from robot.mount import ArrayMount
from robot.sound_map import SoundMap, SoundMapConfig, pose_at

H = ArrayMount().height_m
SOURCE = np.array([2.0, 1.5, 0.1])


@dataclass(frozen=True)
class Ev:
    track_id: int | None
    direction: np.ndarray
    time: float
    voice_probability: float = 0.9
    level_db: float = -30.0
    activity: float = 1.0


def _drive(window_s=1.0, speed=0.3, n=12):
    """Robot drives along +x at ``speed`` from (0, 0), yaw turning 0.05 rad/s; one bearing per window to
    SOURCE seen from the pose at the window's middle (exact). Returns evidence and the trajectory."""
    traj = np.array([[t, speed * t, 0.0, 0.05 * t] for t in np.arange(0.0, n * window_s + 1e-9, 0.05)])
    evs = []
    for k in range(1, n + 1):
        t_mid = (k - 0.5) * window_s
        x, y, yaw = speed * t_mid, 0.0, 0.05 * t_mid
        v = SOURCE - [x, y, H]
        c, s = np.cos(yaw), np.sin(yaw)
        v = np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])
        evs.append(Ev(1, v / np.linalg.norm(v), k * window_s))
    return evs, traj


def test_pose_at_interpolates_and_unwraps_yaw():
    traj = np.array([[0.0, 0.0, 0.0, 3.1], [1.0, 1.0, 2.0, -3.1]])
    p = pose_at(traj, 0.5)
    assert p.x == pytest.approx(0.5) and p.y == pytest.approx(1.0)
    assert abs(np.angle(np.exp(1j * p.yaw)) - np.pi) < 1e-9   # through +-pi, not through 0


def test_bearings_from_a_moving_robot_place_the_source():
    evs, traj = _drive()
    m = SoundMap()
    m.update_moving(evs, traj, window_s=1.0)
    assert len(m.sources) == 1
    assert np.linalg.norm(m.sources[0].position[:2] - SOURCE[:2]) < 0.05
    # the same rays put at the window's end pose are 0.15 m off along the drive
    end = SoundMap()
    for ev in evs:
        end.update([ev], pose_at(traj, ev.time), ev.time)
    assert np.linalg.norm(end.sources[0].position[:2] - SOURCE[:2]) > 0.08


def test_bad_trajectory_is_named():
    with pytest.raises(ValueError, match="trajectory"):
        SoundMap().update_moving([Ev(1, np.array([1.0, 0, 0]), 1.0)], np.zeros((3, 3)), 1.0)
    with pytest.raises(ValueError, match="window_s"):
        SoundMap().update_moving([], np.zeros((1, 4)), -1.0)
