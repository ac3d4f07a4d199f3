"""World-frame sound map: bearings from a drive past static sources, checked against the geometry put in."""
from dataclasses import dataclass

import math

import numpy as np
import pytest

from robot.config_values import field_values
from robot.listening import NON_VOICE_P, VOICE_P
from robot.mount import ArrayMount
from robot.sound_map import SoundMap, SoundMapConfig, SourceClass, SourceState, triangulate

H = ArrayMount().height_m
SOURCES = np.array([[1.5, 2.0, 0.10], [3.2, -1.6, 0.15], [4.6, 1.1, 0.60]])  # world frame (m)
VOICE = [0.9, 0.1, 0.8]   # victim, machine, victim


@dataclass(frozen=True)
class Ev:
    track_id: int | None
    direction: np.ndarray
    time: float
    voice_probability: float
    level_db: float = -30.0
    activity: float = 1.0


def _drive_past(rng, outlier_fraction=0.1, noise_deg=3.0, track_ids=True):
    """Listens every 0.25 m along a drive from (0, 0) to (5.5, 0.5), yaw wobbling: bearings (array frame)
    to every source with Gaussian noise, ``outlier_fraction`` of them replaced by random directions."""
    out = []
    n = 24
    for k in range(n):
        x, y = 5.5 * k / (n - 1), 0.5 * k / (n - 1)
        yaw = 0.3 * np.sin(k)
        c, s = np.cos(yaw), np.sin(yaw)
        evs = []
        for i, p in enumerate(SOURCES):
            v = p - [x, y, H]
            v = np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])  # world -> array frame
            v /= np.linalg.norm(v)
            if rng.random() < outlier_fraction:   # a reflection: anywhere on the sphere
                v = rng.normal(size=3)
            else:
                v = v + rng.normal(scale=np.radians(noise_deg), size=3)
            evs.append(Ev(i if track_ids else None, v / np.linalg.norm(v), float(k), VOICE[i]))
        out.append(((x, y, yaw), float(k), evs))
    return out


def _closest(m, p):
    return min(m.sources, key=lambda s: np.linalg.norm(s.position - p))


@pytest.mark.parametrize("track_ids", [True, False])
def test_three_sources_within_0p3_m_despite_10pct_outliers(track_ids):
    rng = np.random.default_rng(4)
    m = SoundMap()
    for pose, t, evs in _drive_past(rng, track_ids=track_ids):
        m.update(evs, pose, t)
    for p, v in zip(SOURCES, VOICE):
        s = _closest(m, p)
        assert np.linalg.norm(s.position - p) <= 0.3, (p, s.position)
        assert s.n_inliers >= 18
        assert s.cls is (SourceClass.VICTIM if v > 0.5 else SourceClass.INTERFERER)
    # the estimate's own uncertainty covers its error (3 sigma)
    for p in SOURCES:
        s = _closest(m, p)
        assert np.linalg.norm(s.position[:2] - p[:2]) <= 3 * s.horizontal_sigma_m + 0.05
    # outliers do not become confirmed sources
    assert sum(s.n_listens >= 3 for s in m.sources) == 3
    # the machine (no voice) is an interferer of the map, at its place; the callers are not
    near = [[np.linalg.norm(xy - p[:2]) <= 0.3 for xy in m.interferers()] for p in SOURCES]
    assert sum(near[1]) == 1 and not any(near[0]) and not any(near[2])


def test_single_pose_gives_range_from_elevation_only():
    """From one spot the range comes from the elevation and the height prior: right within the prior's spread,
    and the covariance says so (long along the ray)."""
    m = SoundMap()
    p = np.array([2.0, 0.0, 0.2])
    d = p - [0, 0, H]
    m.update([Ev(0, d / np.linalg.norm(d), 0.0, 0.9)], (0.0, 0.0, 0.0), 0.0)
    s = m.sources[0]
    assert abs(np.arctan2(s.position[1], s.position[0])) < 1e-6
    assert np.linalg.norm(s.position - p) < 0.05
    w, v = np.linalg.eigh(s.covariance[:2, :2])
    assert abs(v[0, np.argmax(w)]) > 0.99           # the long axis is along x (the ray)
    assert np.sqrt(w.max()) > 3 * np.sqrt(w.min())


def test_triangulate_two_perpendicular_rays_exact():
    o = np.array([[0.0, 0.0, H], [2.0, -2.0, H]])
    p = np.array([2.0, 0.0, H])
    pos, cov, inl = triangulate(o, (p - o) / np.linalg.norm(p - o, axis=1, keepdims=True))
    assert np.linalg.norm(pos - p) < 0.05 and inl.all()


@pytest.mark.parametrize("steep", [0, 1])
def test_triangulate_breaks_a_rounding_tie_for_the_earliest_ray(steep):
    """Two rays from places 1 m apart that never meet: each ray's own point at the height prior is a hypothesis
    with one inlier at angle 0 up to float rounding. Which one wins must not hang on the last bits of the
    arithmetic (another BLAS kernel rounds them differently): the earliest ray's, the steeper or not, whatever
    1e-12 the directions carry."""
    o = np.array([[0.0, 0.0, H], [0.0, 1.0, H]])
    d = np.array([[1.0, -1.0, -0.2], [1.0, 1.0, -0.2]])
    d[steep, 2] = -0.3
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    floor = o[0] + d[0] * (SoundMapConfig().source_height_m - H) / d[0, 2]
    rng = np.random.default_rng(7)
    for _ in range(40):
        pos, _, inl = triangulate(o, d + rng.normal(scale=1e-12, size=d.shape))
        assert inl.tolist() == [True, False]
        assert np.linalg.norm(pos - floor) < 1e-6, pos


def test_found_source_is_never_a_new_source():
    rng = np.random.default_rng(1)
    m = SoundMap()
    drive = _drive_past(rng, outlier_fraction=0.0)
    for pose, t, evs in drive[:12]:
        m.update(evs, pose, t)
    first = _closest(m, SOURCES[0])
    m.set_state(first.id, SourceState.FOUND, 12.0)
    for pose, t, evs in drive[12:]:
        m.update(evs, pose, t)
    near = [s for s in m.sources if np.linalg.norm(s.position[:2] - SOURCES[0, :2]) < 0.8]
    assert len(near) == 1 and near[0].state is SourceState.FOUND and near[0].id == first.id
    m.set_state(first.id, SourceState.APPROACHING)          # a found source stays found
    assert m.source(first.id).state is SourceState.FOUND
    assert all(s.id != first.id for s in m.unfound_victims())


def test_bad_input_names_the_field():
    with pytest.raises(ValueError, match="bearing_sigma_deg"):
        SoundMapConfig(bearing_sigma_deg=0)
    with pytest.raises(ValueError, match="direction"):
        SoundMap().update([Ev(0, np.zeros(3), 0.0, 0.5)], (0, 0, 0), 0.0)


def test_a_caller_heard_at_the_measured_speech_rate_is_a_victim_and_a_machine_an_interferer():
    """Per-listen voice evidence is the likelihood ratio measured on the train split (``robot.listening``): a caller
    whose beam has speech in 7 of 16 listens (the measured 44 %) ends a victim, never an interferer on the way; a
    machine (no speech) is an interferer within four listens; and a listen without speech weighs the same whether
    its beam is faint or loud."""
    m = SoundMap()
    caller, machine = np.array([3.5, 1.5, 0.1]), np.array([-1.0, -1.2, 0.3])
    rng = np.random.default_rng(7)
    speech_at = {1, 3, 5, 8, 10, 12, 14}
    for k in range(16):
        pose = (0.1 * k, 0.05 * k, 0.0)
        evs = []
        for i, (p, level, voiced) in enumerate([(caller, -58.0, k in speech_at), (machine, -40.0, False)]):
            v = p - [pose[0], pose[1], H]
            v = v / np.linalg.norm(v) + rng.normal(scale=np.radians(2.0), size=3)
            evs.append(Ev(i, v / np.linalg.norm(v), float(k), VOICE_P if voiced else NON_VOICE_P, level))
        m.update(evs, pose, float(k))
        c = _closest(m, caller)
        mach = max(m.sources, key=lambda s: sum(r.level_db == -40.0 for r in s.history))   # the machine's rays
        assert c.cls is not SourceClass.INTERFERER, (k, c.victim_probability)
        if k >= 3:
            assert mach.cls is SourceClass.INTERFERER, (k, mach.victim_probability)
    assert _closest(m, caller).cls is SourceClass.VICTIM
    probabilities = []
    for level in (-62.0, -40.0):
        m2 = SoundMap()
        for k in range(3):
            v = caller - [0.1 * k, 0.05 * k, H]
            m2.update([Ev(0, v / np.linalg.norm(v), float(k), NON_VOICE_P, level)], (0.1 * k, 0.05 * k, 0.0), float(k))
        probabilities.append(m2.sources[0].victim_probability)
    logit = math.log(NON_VOICE_P / (1 - NON_VOICE_P))
    assert probabilities == pytest.approx([1 / (1 + math.exp(-3 * logit))] * 2)


def test_the_retired_faint_beam_weighting_is_ignored_with_a_warning():
    """Old scenario files that set the faint-beam weighting still load, told that the value is ignored."""
    for name in ("silent_loud_db", "silent_faint_db", "silent_faint_weight"):
        with pytest.warns(FutureWarning, match=rf"sound_map.{name}: no longer a field .*fit_voice_evidence"):
            kept = field_values(SoundMapConfig, {name: 0.5, "merge_distance_m": 0.4}, "sound_map")
        assert kept == {"merge_distance_m": 0.4}


def test_sources_are_numbered_from_one_like_the_victims_found():
    """The behaviour prints "victim #1 (source #1)": map sources and victims found share one convention."""
    m = SoundMap()
    for k, p in enumerate(([2.0, 0.0, 0.2], [0.0, 2.5, 0.2])):
        d = np.array(p) - [0, 0, H]
        m.update([Ev(k, d / np.linalg.norm(d), 0.0, 0.9)], (0.0, 0.0, 0.0), 0.0)
    assert sorted(s.id for s in m.sources) == [1, 2]


def test_two_rays_crossing_beside_the_second_listen_stay_two_sources():
    """Two callers far apart, each heard along one ray from spots 0.36 m apart: the rays cross 0.36 m from the
    second spot, a point no bearing there could tell from any other (a mouth that close is heard steeply). The
    map keeps two sources along their rays, neither at the crossing, whether by association or by merging."""
    m = SoundMap()
    far_a = np.array([4.0, 0.0, 0.2])                 # along +x from the first spot, 4 m out
    d = far_a - [0.0, 0.0, H]
    m.update([Ev(None, d / np.linalg.norm(d), 0.0, 0.9)], (0.0, 0.0, 0.0), 0.0)
    spot = np.array([0.2, 0.35])
    crossing = np.array([0.3, 0.0])                   # on the first ray, 0.36 m from the second spot
    u = crossing - spot
    far_b = np.append(spot + 3.0 * u / np.linalg.norm(u), 0.2)   # the second caller, 3 m out along that line
    d = far_b - [spot[0], spot[1], H]
    m.update([Ev(None, d / np.linalg.norm(d), 1.0, 0.9)], (spot[0], spot[1], 0.0), 1.0)
    assert len(m.sources) == 2
    for s in m.sources:
        assert np.linalg.norm(s.position[:2] - crossing) > 0.3


def test_array_mount_bearing_to_a_world_point():
    from robot.mount import ArrayMount
    mount = ArrayMount(height_m=0.3)
    # robot at (1, 1) facing +y: a point 1 m to the world's +x is on the robot's right (azimuth -90 deg), and
    # 0.3 m below the array at 1 m range is 16.7 deg down
    az, el = mount.bearing_to((1.0, 1.0, math.pi / 2), (2.0, 1.0, 0.0))
    assert math.degrees(az) == pytest.approx(-90.0)
    assert math.degrees(el) == pytest.approx(-math.degrees(math.atan2(0.3, 1.0)))
    # straight behind: azimuth -180 deg (the wrap is [-pi, pi))
    az, _ = mount.bearing_to((0.0, 0.0, 0.0), (-1.0, 0.0, 0.3))
    assert az == pytest.approx(-math.pi)
