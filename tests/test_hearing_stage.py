"""The hearing stage as one chain: localizer -> tracker across listens (robot motion removed) -> voice evidence
per track -> sound map. The localizer is replaced by the analytic direction of each source from the array centre
at the robot's pose (plus seeded bearing noise); no audio is simulated."""
import math
from dataclasses import dataclass

import numpy as np
import pytest

from robot.hal import AudioBlock, ManualClock
from robot.listening import (LISTEN_TRACKER, MAX_TRACK_LOG_ODDS, NON_VOICE_P, VOICE_P, Listener, ListenEvidence,
                             TrackVoice)
from robot.mount import ArrayMount
from robot.sound_map import TRACK_GATE_FACTOR, SoundMap, SoundMapConfig
from ssl_core.tracking import Tracker, TrackerConfig

HEIGHT = ArrayMount().height_m
DRIVE_S = 4.0          # s of driving between two listens (the clock runs on while the robot moves)


@dataclass(frozen=True)
class _Det:
    azimuth: float
    elevation: float
    direction: np.ndarray
    power: float
    level_db: float
    talking: bool


@dataclass(frozen=True)
class _Result:
    detections: list


class _Audio:
    sample_rate = 16000

    def flush(self):
        pass

    def read(self, n):
        return AudioBlock(np.zeros((8, n), np.float32), self.sample_rate, 0.0)


class _World:
    """Sources at world positions (m); ``locate`` returns their directions in the array frame of ``pose``."""

    def __init__(self, sources, talking=(), noise_deg=1.5, seed=0):
        self.sources = [np.asarray(p, float) for p in sources]
        self.talking = set(talking)
        self.pose = (0.0, 0.0, 0.0)
        self.rng = np.random.default_rng(seed)
        self.noise = math.radians(noise_deg)

    def direction(self, k):
        """Unit vector toward source ``k`` in the array frame at ``pose`` (no noise)."""
        x, y, yaw = self.pose
        v = self.sources[k] - np.array([x, y, HEIGHT])
        c, s = math.cos(yaw), math.sin(yaw)
        u = np.array([c * v[0] + s * v[1], -s * v[0] + c * v[1], v[2]])   # Rz(-yaw) v
        return u / np.linalg.norm(u)

    def locate(self, samples):
        dets = []
        for k in range(len(self.sources)):
            u = self.direction(k)
            az = math.atan2(u[1], u[0]) + self.noise * self.rng.normal()
            el = math.asin(u[2]) + self.noise * self.rng.normal()
            d = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
            dets.append(_Det(az, el, d, 0.1, -40.0, k in self.talking))
        return _Result(dets)


def _listener(world, tracker=None):
    return Listener(_Audio(), ManualClock(), world, None, speech=lambda x, d, u: 1.0 if d.talking else 0.0,
                    tracker=tracker)


def _nearest(world, evidence, k):
    """The evidence whose direction is nearest source ``k``'s true direction (and that angle, rad)."""
    u = world.direction(k)
    angles = [math.acos(min(1.0, float(e.direction @ u))) for e in evidence]
    i = int(np.argmin(angles))
    return evidence[i], angles[i]


# A listen at pose A, a 90 deg turn in place, a 0.5 m step sideways (robot's -y after the turn: world +x).
POSES = [(0.0, 0.0, 0.0), (0.0, 0.0, math.pi / 2), (0.5, 0.0, math.pi / 2)]


def _run(world, listener, poses, reported=None):
    """Listen at each pose (driving ``DRIVE_S`` s between), telling the listener the ``reported`` poses (default:
    the true ones); returns per listen the evidence list."""
    out = []
    for i, pose in enumerate(poses):
        if i:
            listener.clock.sleep(DRIVE_S)
        world.pose = pose
        res = listener.listen(1.0, 0.0, 0.0, pose=pose if reported is None else reported[i])
        assert res.n_detections == len(world.sources)
        out.append(res.evidence)
    return out


def test_one_source_keeps_its_track_id_through_a_turn_and_a_step():
    world = _World([(1.5, 1.5, 0.2)])
    listens = _run(world, _listener(world), POSES)
    ids = []
    for k, ev in enumerate(listens):
        world.pose = POSES[k]
        e, angle = _nearest(world, ev, 0)
        assert angle < math.radians(6)          # the evidence is the source's bearing in this array frame
        ids.append(e.track_id)
    assert ids[0] is not None and ids == [ids[0]] * 3
    # the step moved the source's bearing by parallax (11 deg at 2.1 m): the id survived that too
    world.pose = POSES[1]
    before = world.direction(0)
    world.pose = POSES[2]
    assert math.degrees(math.acos(float(before @ world.direction(0)))) > 10


def test_two_sources_90_deg_apart_keep_distinct_ids_that_do_not_swap():
    # source 0 ahead, source 1 on the left: after the 90 deg turn source 0 lies where source 1 was
    world = _World([(2.0, 0.0, 0.2), (0.0, 2.0, 0.2)], seed=1)
    listens = _run(world, _listener(world), POSES)
    ids = []
    for k, ev in enumerate(listens):
        world.pose = POSES[k]
        ids.append((_nearest(world, ev, 0)[0].track_id, _nearest(world, ev, 1)[0].track_id))
    a, b = ids[0]
    assert a is not None and b is not None and a != b
    assert ids == [(a, b)] * 3
    # Told the robot did not turn, the tracker takes the turn for sources that jumped: the id that was ahead
    # follows what is ahead now, source 1 (the motion from the poses is what makes the ids hold).
    world2 = _World([(2.0, 0.0, 0.2), (0.0, 2.0, 0.2)], seed=1)
    blind = _run(world2, _listener(world2), POSES[:2], reported=[POSES[0]] * 2)
    world2.pose = POSES[1]
    assert _nearest(world2, blind[1], 1)[0].track_id == _nearest(world2, blind[0], 0)[0].track_id


def test_tracker_detection_ids_name_the_track_each_detection_updated():
    """``Tracker.detection_ids``: None for a tentative track under the default (3 of 8) birth rule, the id once
    confirmed; the same id for the detection that keeps updating it."""
    tr = Tracker(TrackerConfig())
    u = np.array([1.0, 0.0, 0.0])
    det = _Det(0.0, 0.0, u, 0.12, -30.0, False)
    seen = []
    for k in range(4):
        tr.update([det], 0.128 * k)
        seen.append(tr.detection_ids())
    assert seen[:2] == [[None], [None]] and seen[2] == seen[3] == [tr.tracks()[0].id]
    tr.update([], 0.128 * 4)
    assert tr.detection_ids() == []


def test_listen_without_pose_starts_the_tracker_over_and_bad_pose():
    world = _World([(2.0, 0.0, 0.2)])
    lis = _listener(world)
    first = lis.listen(1.0, 0.0, 0.0).evidence          # the call without a pose still works, ids given
    second = lis.listen(1.0, 0.0, 0.0).evidence         # motion unknown: a new track, not the old one's id
    assert None not in (first[0].track_id, second[0].track_id) and first[0].track_id != second[0].track_id
    assert second[0].track_voice_probability == pytest.approx(second[0].voice_probability)
    still = [lis.listen(1.0, 0.0, 0.0, pose=(1.0, 2.0, 0.3)).evidence[0].track_id for _ in range(2)]
    assert still[0] == still[1]                          # standing still with its pose: one track
    with pytest.raises(ValueError, match="pose"):
        lis.listen(1.0, 0.0, 0.0, pose=(0.0, float("nan"), 0.0))
    with pytest.raises(ValueError, match="pose"):
        lis.listen(1.0, 0.0, 0.0, pose=(0.0, 1.0))
    with pytest.raises(ValueError, match="tracker"):
        Listener(_Audio(), ManualClock(), world, None, tracker={"silence_s": 3})


def test_voice_accumulates_per_track_over_listens():
    world = _World([(2.0, 0.0, 0.2), (0.0, 2.0, 0.2)], talking={0}, seed=2)
    lis = _listener(world)
    listens = _run(world, lis, POSES)
    per = []
    for k, ev in enumerate(listens):
        world.pose = POSES[k]
        per.append((_nearest(world, ev, 0)[0], _nearest(world, ev, 1)[0]))
    logit = lambda p: math.log(p / (1 - p))   # noqa: E731
    sigmoid = lambda x: 1 / (1 + math.exp(-x))   # noqa: E731
    for n, (talker, silent) in enumerate(per, start=1):
        # the per-listen meaning is unchanged
        assert talker.voice_probability == VOICE_P and silent.voice_probability == NON_VOICE_P
        want_t = sigmoid(min(n * logit(VOICE_P), MAX_TRACK_LOG_ODDS))
        want_s = sigmoid(max(n * logit(NON_VOICE_P), -MAX_TRACK_LOG_ODDS))
        assert talker.track_voice_probability == pytest.approx(want_t)
        assert silent.track_voice_probability == pytest.approx(want_s)
    assert per[0][0].track_voice_probability == pytest.approx(VOICE_P)
    assert per[0][1].track_voice_probability == pytest.approx(NON_VOICE_P)
    assert per[2][0].track_voice_probability > per[0][0].track_voice_probability
    assert per[2][1].track_voice_probability < per[0][1].track_voice_probability
    assert per[2][1].track_voice_probability < 0.3
    assert lis.track_voice(per[2][0].track_id) == pytest.approx(per[2][0].track_voice_probability)
    with pytest.raises(KeyError, match="track_id"):
        lis.track_voice(999)


def test_evidence_without_a_track_keeps_its_listen_voice():
    e = ListenEvidence(None, np.array([1.0, 0.0, 0.0]), 0.0, VOICE_P, -40.0, 1.0, 0.1)
    assert e.track_voice_probability == VOICE_P
    tv = TrackVoice()
    assert tv.add(3, NON_VOICE_P) == pytest.approx(NON_VOICE_P)
    tv.keep([4])
    with pytest.raises(KeyError):
        tv.probability(3)


def test_tracker_defaults_coast_a_track_across_a_drive():
    """The listener's tracker keeps a track silent through a 6 s drive (it must not be deleted), but not forever."""
    assert LISTEN_TRACKER.silence_s > 6.0 + 1.0
    assert LISTEN_TRACKER.confirm_hits == 1 and LISTEN_TRACKER.theta_new == 0.0
    world = _World([(2.0, 0.0, 0.2)])
    lis = _listener(world)
    a = lis.listen(1.0, 0.0, 0.0, pose=(0.0, 0.0, 0.0)).evidence[0].track_id
    world.sources = []
    lis.clock.sleep(6.0)
    assert lis.listen(1.0, 0.0, 0.0, pose=(0.0, 0.0, 0.0)).evidence == []   # a listen without the source
    world.sources = [np.array([2.0, 0.0, 0.2])]
    lis.clock.sleep(6.0)
    assert lis.listen(1.0, 0.0, 0.0, pose=(0.0, 0.0, 0.0)).evidence[0].track_id == a


# ------------------------------------------------------------------------ the map uses the track id
def _ray(az_deg):
    a = math.radians(az_deg)
    return np.array([math.cos(a), math.sin(a), 0.0])


def _ev(track_id, direction, time):
    return ListenEvidence(track_id, direction, time, NON_VOICE_P, -40.0, 1.0, 0.1)


def _chi2_off_ray(az_deg):
    """Chi-square of a level ray from (0, -2) at ``az_deg`` (world) against a source heard along the level +x ray
    from (0, 0) at 0.05-15 m: the nearest point of that segment in azimuth is its far end (7.6 deg from (0, -2));
    one ray's own noise doubles the variance (the map's along-ray gate)."""
    cfg = SoundMapConfig()
    far = math.degrees(math.atan2(2.0, 15.0))
    return ((far - az_deg) / cfg.bearing_sigma_deg) ** 2 / 2


@pytest.mark.parametrize("track_second, az_deg, n_sources", [
    (7, -23.0, 1),      # same track, just outside the normal gate, inside the looser one: one source
    (None, -23.0, 2),   # no track id: as before, a new source
    (8, -23.0, 2),      # another track: a new source
    (7, -32.0, 2),      # same track but outside the looser gate too: a new source
])
def test_map_joins_a_tracks_rays_inside_the_looser_gate(track_second, az_deg, n_sources):
    cfg = SoundMapConfig()
    chi2 = _chi2_off_ray(az_deg)
    if az_deg == -23.0:
        assert cfg.gate_chi2 < chi2 < TRACK_GATE_FACTOR * cfg.gate_chi2
    else:
        assert chi2 > TRACK_GATE_FACTOR * cfg.gate_chi2
    m = SoundMap(cfg, ArrayMount())
    m.update([_ev(7, _ray(0.0), 1.0)], (0.0, 0.0, 0.0), 1.0)
    # heard from (0, -2) facing +y: the array-frame azimuth is the world one minus 90 deg
    m.update([_ev(track_second, _ray(az_deg - 90.0), 6.0)], (0.0, -2.0, math.pi / 2), 6.0)
    assert len(m.sources) == n_sources


def test_the_chain_puts_one_source_at_its_place():
    """Listener with poses -> map: a caller heard from the three poses is one map source, all three listens of one
    track, in her direction from where the robot stands (0.5 m of baseline crossing at 11 deg does not fix her
    range: that takes more listens)."""
    world = _World([(1.5, 1.5, 0.2)], talking={0}, noise_deg=1.0, seed=3)
    lis = _listener(world)
    m = SoundMap(SoundMapConfig(), ArrayMount())
    for i, pose in enumerate(POSES):
        if i:
            lis.clock.sleep(DRIVE_S)
        world.pose = pose
        res = lis.listen(1.0, 0.0, 0.0, pose=pose)
        m.update(res.evidence, pose, lis.clock.now())
    assert len(m.sources) == 1
    src = m.sources[0]
    assert src.n_listens == 3
    x, y, _ = POSES[-1]
    az = math.degrees(math.atan2(src.position[1] - y, src.position[0] - x))
    assert abs(az - math.degrees(math.atan2(1.5 - y, 1.5 - x))) < 5
    assert {r.track_id for r in src.history} == {res.evidence[0].track_id}
