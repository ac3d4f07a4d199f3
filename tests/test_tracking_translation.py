"""Tracker translation compensation: a drive past a static source, its true directions from the geometry."""
import numpy as np
import pytest

from ssl_core.detection import Detection
from ssl_core.tracking import Tracker

WINDOW_S = 0.128
SOURCE = np.array([1.0, 0.0, -0.25])  # m, world frame; the array starts 0.5 m to its right


def _drive(speed=0.3, distance=1.0, gap=(1.3, 2.5), noise_deg=1.5, seed=3, yaw_rate=0.0,
           compensate=True, source_range=1.0):
    """Array moves along world +y from y = -0.5 (yaw turning at ``yaw_rate`` rad/s); the source is detected
    in every window except during ``gap`` (s, a pause in her calling) at its true direction (array frame)
    plus noise. Returns the ids of the confirmed tracks per window and the angle (deg) between the first
    track and the truth per window (nan: no track)."""
    rng = np.random.default_rng(seed)
    tr = Tracker()
    n = int(round(distance / speed / WINDOW_S))
    prev_pos, prev_yaw = None, None
    ids, errs = [], []
    for k in range(n + 1):
        t = k * WINDOW_S
        pos, yaw = np.array([0.0, -0.5 + speed * t, 0.0]), yaw_rate * t
        c, s = np.cos(yaw), np.sin(yaw)
        R_world = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])  # columns: array axes in the world
        u = R_world.T @ (SOURCE - pos)
        u /= np.linalg.norm(u)
        dets = []
        if not gap[0] <= t < gap[1]:
            z = u + rng.normal(scale=np.radians(noise_deg), size=3)
            z /= np.linalg.norm(z)
            dets = [Detection(float(np.arctan2(z[1], z[0])), float(np.arcsin(z[2])), z, 0.12, -30.0)]
        kw = {"source_range": source_range} if compensate else {}
        if prev_pos is not None:
            c0, s0 = np.cos(prev_yaw), np.sin(prev_yaw)
            R_prev = np.array([[c0, -s0, 0], [s0, c0, 0], [0, 0, 1.0]])
            kw["rotation"] = R_world.T @ R_prev                    # previous array frame -> current
            if compensate:
                kw["translation"] = R_world.T @ (pos - prev_pos)   # displacement in the current frame
        tracks = tr.update(dets, t, **kw)
        ids.append({x.id for x in tracks})
        errs.append(float(np.degrees(np.arccos(np.clip(tracks[0].direction @ u, -1, 1)))) if tracks else np.nan)
        prev_pos, prev_yaw = pos, yaw
    return ids, errs


@pytest.mark.parametrize("yaw_rate", [0.0, 0.4])
def test_track_id_survives_a_1_m_drive_past_a_static_source(yaw_rate):
    ids, errs = _drive(yaw_rate=yaw_rate)
    confirmed = [i for i in ids if i]
    assert confirmed and all(i == confirmed[0] for i in confirmed) and len(confirmed[0]) == 1, ids
    assert ids[-1] == confirmed[0]
    assert errs[-1] < 5.0
    # through the 1.2 s pause the coasting track follows her by the geometry alone
    gap = slice(int(1.3 / WINDOW_S) + 1, int(2.5 / WINDOW_S))
    assert np.nanmax(errs[gap]) < 3.0, errs


def test_an_assumed_range_off_by_half_still_keeps_the_id():
    ids, errs = _drive(source_range=2.0)  # the source is 1.0-1.1 m away
    confirmed = [i for i in ids if i]
    assert all(i == confirmed[0] for i in confirmed) and ids[-1] == confirmed[0]
    assert errs[-1] < 5.0


def test_without_translation_the_coasting_track_falls_behind():
    """The control: during the pause the source sweeps ~20 deg across the array's view; without the
    translation the coasting track only extrapolates its velocity."""
    _, errs = _drive(compensate=False)
    gap = slice(int(1.3 / WINDOW_S) + 1, int(2.5 / WINDOW_S))
    assert np.nanmax(errs[gap]) > 6.0, errs


def test_bad_translation_is_named():
    tr = Tracker()
    with pytest.raises(ValueError, match="translation"):
        tr.update([], 0.0, translation=[0.1, 0.0])
    with pytest.raises(ValueError, match="source_range"):
        tr.update([], 0.0, translation=[0.1, 0.0, 0.0], source_range=0.0)
