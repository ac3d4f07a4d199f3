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


def _biased_ray(origin, bias_deg):
    """Unit vector from ``origin`` toward SOURCE with its elevation lowered by ``bias_deg``."""
    v = SOURCE - origin
    az, el = np.arctan2(v[1], v[0]), np.arctan2(v[2], np.hypot(v[0], v[1])) - np.radians(bias_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])



def _heard(moving: bool, bias_deg: float) -> float:
    """Horizontal error (m) of the source after three exact bearings heard standing from spread poses, then twelve
    heard on a drive toward it (2.1 m to 1.2 m) whose elevation reads ``bias_deg`` low, every ray alike."""
    m = SoundMap()
    for k, xy in enumerate([(0.0, 0.0), (0.6, -0.4), (0.0, 0.6)]):
        m.update([Ev(1, _biased_ray(np.array([*xy, H]), 0.0), float(k))], (xy[0], xy[1], 0.0), float(k))
    start, to = np.array([0.3, 0.2]), SOURCE[:2] - [0.3, 0.2]
    for k in range(12):
        xy = start + (0.08 * k) * to / np.linalg.norm(to)
        m.update([Ev(1, _biased_ray(np.array([*xy, H]), bias_deg), 10.0 + k)], (xy[0], xy[1], 0.0), 10.0 + k,
                 moving=moving)
    [s] = m.sources
    return float(np.linalg.norm(s.position[:2] - SOURCE[:2]))


def test_a_drive_heard_with_an_elevation_bias_pulls_the_range_less_when_flagged_moving():
    """The drive's windows read elevation a few degrees low, all alike (a shared bias, not independent noise):
    flagged as heard while driving, their elevation weighs less and the estimate stays nearer the source than when
    the same rays count as standing listens. Unbiased rays place it within 5 cm either way."""
    for bias in (3.0, 4.0):
        assert _heard(True, bias) < 0.7 * _heard(False, bias)
    assert max(_heard(True, 0.0), _heard(False, 0.0)) < 0.05
