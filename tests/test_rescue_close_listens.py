"""Close listens outweigh far ones: the rescue behaviour checked against a scripted world's truth (the fake HAL of
``test_rescue``: ideal drive, detections from the true pose). Truth is the scoring's find (``robot.found``): the
report within ``FIND_RADIUS_M`` of the caller with the robot's base within ``BASE_RADIUS_M`` of her.

Behavioural: the outcomes of the scripted worlds depend on the fitted found model (robot/models/found_model.json),
not on a rule."""
import math

import numpy as np
import pytest

from robot.coverage import CoverageConfig
from robot.hal import DriveStatus

from robot.found import BASE_RADIUS_M, FIND_RADIUS_M
from robot.rescue import Decision, RescueConfig
from robot.mount import ArrayMount
from robot.sound_map import SoundMap
from test_rescue import Det, FakeLocalizer, Result, Source, World, WorldDrive, always_speech, found_events, make

H = ArrayMount().height_m


#: Cases the fitted found model still declares falsely (reports 0.6-1.5 m from the caller): the measured limit of
#: its cues (docs/design/behaviour.md, "What the fit says"). Strict: a model that gets them right makes these fail
#: until the mark is removed.
KNOWN_FALSE_FIND = pytest.mark.xfail(strict=True, reason="the fitted found model declares this case falsely")


class _Ev:
    """One bearing as map evidence (array frame = world frame: yaw 0)."""

    def __init__(self, toward, origin, voice=0.9, level_db=-40.0):
        v = np.asarray(toward, float) - [origin[0], origin[1], H]
        self.direction = v / np.linalg.norm(v)
        self.track_id, self.time, self.voice_probability, self.level_db, self.activity = None, 0.0, voice, level_db, 1.0


def _level_from(caller, origin):
    """The beam level (dB) of ``caller`` heard from ``origin`` as the fake localizer gives it (1/r): a ghost's bearings
    were the caller's sound, as loud as she was there."""
    return caller.level_db - 20 * math.log10(math.dist(caller.position, (origin[0], origin[1], H)))


def test_restart_from_keeps_only_the_listens_heard_there():
    # Two callers; one bearing to each from two poses 2.6 m apart cross at a ghost (2.4, 1.2) the map takes for one
    # source (1.3 m and 2.2 m from where they were heard: a crossing that could be a mouth).
    a, b = np.array([4.0, 2.0, 0.1]), np.array([2.4, 3.5, 0.1])
    m = SoundMap()
    (_, sid), = m.update([_Ev(a, (0.0, 0.0))], (0.0, 0.0, 0.0), 1.0)
    (_, sid2), = m.update([_Ev(b, (2.4, -1.0))], (2.4, -1.0, 0.0), 2.0)
    assert sid2 == sid                                     # two callers' rays cross: one (ghost) source
    ghost = m.source(sid)
    assert min(np.hypot(*(ghost.position[:2] - p[:2])) for p in (a, b)) > 1.0
    assert m.restart_from(sid, (2.4, -1.0)) == 1
    s = m.source(sid)
    # now along the bearing heard at (2.4, -1.0), toward caller b, with its range open again
    off = math.atan2(s.position[1] + 1.0, s.position[0] - 2.4) - math.atan2(b[1] + 1.0, b[0] - 2.4)
    assert abs(off) < math.radians(2)
    assert s.horizontal_sigma_m > 1.0 and not s.triangulated


class EchoLocalizer(FakeLocalizer):
    """Every source also heard a second time 5 deg off its azimuth, 35 deg below the horizon (a steep duplicate,
    as light rubble's SRP gave 1-1.6 m from callers) and as loud, in every other listen."""

    def locate(self, samples):
        res = super().locate(samples)
        if self.calls % 2:
            return res
        echoes = [Det(d.azimuth + math.radians(5.0), math.radians(-35.0), d.power, d.level_db, d.voice)
                  for d in res.detections]
        return Result(echoes + res.detections)


def _first_find(config, localizer):
    caller = Source((2.2, 0.6, 0.1), 64.0)
    w = World([caller], seed=4)
    return _find_at_first_declaration(make(w, config, localizer=localizer(w), speech=always_speech), w, caller, 60)


def _find_at_first_declaration(b, w, caller, steps):
    """Step ``b`` up to ``steps`` cycles; at the first declaration (robot's true distance to ``caller``, the report's
    distance to her) in m, or None if none was made."""
    for _ in range(steps):
        found = found_events(b.step())
        if found:
            x, y, _ = w.pose()
            return (math.hypot(x - caller.position[0], y - caller.position[1]),
                    math.dist(found[0].data.position, caller.position[:2]))
        if b.done:
            break
    return None


def _is_find(at):
    return at is not None and at[0] <= BASE_RADIUS_M and at[1] <= FIND_RADIUS_M


def test_a_steep_duplicate_of_a_shallow_bearing_is_no_found_cue():
    # A duplicate 35 deg down as loud as the caller's shallow bearing (the floor's image) would put her at the
    # robot's feet; the first declaration is her, where she is.
    at = _first_find(RescueConfig(max_victims=1), EchoLocalizer)
    assert _is_find(at), at


class ReverberantLocalizer(FakeLocalizer):
    """Beyond ``direct_m`` from the robot (past the room's critical distance: around a wall, metres off) a caller
    is heard mostly as reverberation: a weak SRP-PHAT peak (power 0.06, the scenarios' floor) whose elevation is
    spurious, 35 deg down as behind_partition seed 4 gave 3.9 m from the caller. Closer, her direct sound
    dominates: her true bearing at power 0.5."""

    direct_m = 1.5

    def locate(self, samples):
        res = super().locate(samples)
        x, y, _ = self.world.pose()
        (caller,) = self.world.sources
        if math.hypot(caller.position[0] - x, caller.position[1] - y) <= self.direct_m:
            return res
        return Result([Det(d.azimuth, math.radians(-35.0), 0.06, d.level_db, d.voice) for d in res.detections])


def test_a_steep_bearing_with_a_weak_srp_peak_is_no_found_cue():
    # From beyond 1.5 m she is heard as reverberation, 35 deg down at a weak peak; the first declaration is her.
    caller = Source((2.6, 0.4, 0.1), 64.0)
    w = World([caller], seed=2)
    at = _find_at_first_declaration(make(w, RescueConfig(max_victims=1), localizer=ReverberantLocalizer(w)), w,
                                    caller, 60)
    assert _is_find(at), at


@KNOWN_FALSE_FIND
def test_a_tight_ghost_short_of_the_caller_is_not_declared_and_the_caller_found():
    # A ghost placed by three crossing bearings 1.2 m in front of the robot; the real caller 2.2 m beyond it.
    caller = Source((3.6, 0.0, 0.1), 64.0)
    w = World([caller], start=(1.4, 0.3, 0.0), seed=5)
    b = make(w, RescueConfig(max_victims=1))
    ghost = np.array([1.5, 0.0, 0.15])
    (_, sid), = b.map.update([_Ev(ghost, (0.5, -0.8), level_db=_level_from(caller, (0.5, -0.8)))],
                             (0.5, -0.8, 0.0), 0.0)
    for origin in ((0.6, 0.9), (0.2, 0.1)):
        b.map.update([_Ev(ghost, origin, level_db=_level_from(caller, origin))], (*origin, 0.0), 0.0)
    assert b.map.source(sid).horizontal_sigma_m < 0.3 and b.map.source(sid).distance_to((1.4, 0.3)) < 0.45
    at = _find_at_first_declaration(b, w, caller, 40)
    assert _is_find(at), at


def test_wedged_on_debris_turns_in_place_and_moves_on_instead_of_stuck():
    class Wedged(WorldDrive):
        """A wheel against a debris plate: the drive reports every translation stalled (the bumper free) until
        the robot has turned in place; then the wheels meet the plate at other angles and it drives."""

        freed = False

        def set_twist(self, vx, vy, omega):
            if vx == 0.0 and vy == 0.0 and omega != 0.0:
                self.freed = True
            super().set_twist(vx, vy, omega)

        def status(self):
            st = super().status()
            moving = any(c.twist[0] or c.twist[1] for c in self.commands[-1:])
            return DriveStatus(bumper=st.bumper, stalled=moving and not self.freed)

    w = World([Source((3.0, 0.0, 0.1), 65.0)])
    w.drive = Wedged(w, (0.0, 0.0, 0.0))
    b = make(w, RescueConfig(max_victims=1))
    ev = b.run(max_time=120.0)
    assert not any(e.decision is Decision.STUCK for e in ev)
    assert any(e.decision is Decision.RECOVER and "after turning in place" in e.reason for e in ev)
    assert ev[-1].decision is Decision.ALL_FOUND
    x, y, _ = w.pose()
    assert math.hypot(x - 3.0, y) <= BASE_RADIUS_M  # truth: it drove on to the caller ...
    assert math.dist(b.victims[0].position, (3.0, 0.0)) <= FIND_RADIUS_M   # ... and reported her where she is


def test_a_bearing_heard_beside_a_single_ray_joins_it_only_where_they_cross_away_from_the_robot():
    far, other = np.array([3.0, 0.0, 0.1]), np.array([1.2, -2.0, 0.1])
    m = SoundMap()
    (_, sid), = m.update([_Ev(far, (0.0, 0.0))], (0.0, 0.0, 0.0), 1.0)
    # From a spot 0.1 m beside that ray, the other caller's bearing crosses it 0.1 m away: a separate source.
    (_, sid2), = m.update([_Ev(other, (1.0, 0.1))], (1.0, 0.1, 0.0), 2.0)
    assert sid2 != sid
    # A bearing of the far caller from 1.4 m beside the first ray crosses it at her: the same source, there.
    (_, sid3), = m.update([_Ev(far, (1.0, 1.4))], (1.0, 1.4, 0.0), 3.0)
    assert sid3 == sid
    assert np.hypot(*(m.source(sid).position[:2] - far[:2])) < 0.3


class SteepLocalizer(FakeLocalizer):
    """Every bearing heard 3.5 deg steeper than the truth (the floor reflection pulling the SRP-PHAT peak down: the
    caller behind half_buried_slab's slab was heard 15.2-15.7 deg down where the truth was 12.5)."""

    def locate(self, samples):
        res = super().locate(samples)
        return Result([Det(d.azimuth, d.elevation - math.radians(3.5), d.power, d.level_db, d.voice)
                       for d in res.detections])


def _at_a_ghost_short_of_the_caller(config, localizer=FakeLocalizer):
    """The robot 0.3 m from a tight estimate that lies 0.65 m short of the caller on her bearing (as a caller behind
    a slab was mapped at its edge), in a 4 x 4 m room (the search area); (robot's true distance to her, report's
    distance to her) at the first declaration, or None."""
    caller = Source((2.0, 0.0, 0.1), 64.0)
    w = World([caller], start=(1.05, 0.0, 0.0), seed=7)
    b = make(w, config, localizer=localizer(w), coverage=CoverageConfig(area=(-0.5, -2.0, 3.5, 2.0)))
    ghost = np.array([1.35, 0.0, 0.15])
    for origin in ((0.3, -0.9), (0.4, 0.9), (0.0, 0.1)):
        b.map.update([_Ev(ghost, origin, level_db=_level_from(caller, origin))], (*origin, 0.0), 0.0)
    return _find_at_first_declaration(b, w, caller, 25)


@KNOWN_FALSE_FIND
def test_a_tight_map_estimate_short_of_the_caller_is_no_find():
    # Heard at -12 deg from 0.95 m: the tight estimate 0.3 m away is 0.65 m short of her (beyond the find radius);
    # the first declaration reports her, not it.
    at = _at_a_ghost_short_of_the_caller(RescueConfig(max_victims=1))
    assert _is_find(at), at


@KNOWN_FALSE_FIND
def test_a_map_estimate_short_of_the_bearings_range_is_no_find():
    # Heard 15.4 deg down (truth 11.9) from 0.95 m: that bearing meets a mouth 0.1 m above the floor 0.73 m away,
    # past the estimate (range agreement low); the first declaration reports her, not the estimate.
    at = _at_a_ghost_short_of_the_caller(RescueConfig(max_victims=1), SteepLocalizer)
    assert _is_find(at), at


class FloorImageLocalizer(FakeLocalizer):
    """Every machine also heard in the first two listens at its floor image: the same azimuth, the elevation
    of the source mirrored in the floor (z -> -z: seen from the array at height h, ``-atan((h + z) / r)``), 3.6 dB
    weaker (as the pump of dense_pump seed 3: +2 and -37 deg)."""

    def locate(self, samples):
        res = super().locate(samples)
        if self.calls > 2:
            return res
        x, y, _ = self.world.pose()
        images = []
        for d, s in zip(res.detections, sorted(self.world.sources, key=lambda s: -self._level(s, x, y))):
            if not s.voice:
                r = math.hypot(s.position[0] - x, s.position[1] - y)
                el = -math.atan2(self.world.array_height + s.position[2], r)
                images.append(Det(d.azimuth, el, d.power * 0.3, d.level_db - 3.6, False))
        return Result(res.detections + images)

    def _level(self, s, x, y):
        d3 = math.dist(s.position, (x, y, self.world.array_height))
        return s.level_db - 20 * math.log10(max(d3, 0.05))


def test_the_floor_image_of_a_machine_above_the_array_is_no_victim():
    # A pump standing higher than the array, 0.9 m away (heard +4 deg up); its floor image -39 deg down at its
    # azimuth, weaker, in the first two listens (a step apart: the image triangulates). No one calls: truth, no victim.
    pump = Source((0.9, 0.0, 0.36), 75.0, voice=False)
    w = World([pump], seed=8)
    ev = make(w, RescueConfig(max_victims=1), localizer=FloorImageLocalizer(w)).run(max_time=60.0)
    steep = [e for e in ev if e.decision is Decision.HEARD and min(c.elevation for c in e.data.candidates) < -0.5]
    assert len(steep) == 2                       # the image was heard, steep, in both listens
    assert not found_events(ev)
