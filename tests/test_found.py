"""P(find) (robot.found): each cue's feature against geometry computed here, the model's arithmetic and file checks.

Nothing here depends on the fitted weights' values: only on their signs where a test says so (a positive weight
raises P(find) as its feature grows), so the tests hold for the hand-set weights and for any fit."""
import json
import math
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from robot.found import (BASE_RADIUS_M, CUES, FIND_RADIUS_M, MACHINE_RADIUS_M, Finder, FoundContext, FoundModel, Heard,
                         default_model_path, is_echo)
from robot.mount import ArrayMount
from robot.sound_map import Listen, MapSource, SoundMapConfig, SourceClass, SourceState

H = ArrayMount().height_m                 # array centre above the floor (m)
MOUTH = SoundMapConfig().source_height_m  # the map's source height prior (m)


def source(x=2.0, y=0.0, sigma=0.2, p=0.9, cls=SourceClass.VICTIM, levels=(), crossing=0.0, sid=1):
    """A map source at world (x, y, MOUTH) with a circular horizontal 1-sigma ``sigma`` (m)."""
    hist = tuple(Listen(float(i), (0.0, 0.0, H), (1.0, 0.0, 0.0), None, 0.9, lv, 1.0) for i, lv in enumerate(levels))
    return MapSource(sid, np.array([x, y, MOUTH]), np.diag([sigma ** 2, sigma ** 2, 0.09]), p, cls,
                     SourceState.UNVISITED, len(levels), len(levels), 0.0, 0.0, -40.0, -40.0, hist,
                     crossing_deg=crossing)


def ctx(s=None, xy=(0.0, 0.0), heard=None, **kw):
    return FoundContext(s if s is not None else source(), xy, H, MOUTH, heard, **kw)


def feature(name, c):
    (cue,) = [q for q in CUES if q.name == name]
    return cue.feature(c)


# --- each cue against geometry -------------------------------------------------------------------------------

def test_depression_is_the_sine_of_the_downward_bearing():
    assert feature("depression", ctx(heard=Heard(math.radians(-30.0), -40.0, 0.5))) == pytest.approx(0.5)
    assert feature("depression", ctx(heard=Heard(math.radians(-90.0), -40.0, 0.5))) == pytest.approx(1.0)
    assert feature("depression", ctx(heard=Heard(math.radians(10.0), -40.0, 0.5))) == 0.0     # up: none
    assert feature("depression", ctx()) == 0.0                                                  # not heard


@pytest.mark.parametrize("d", [0.4, 0.8, 1.5])
def test_range_agreement_is_one_where_the_bearing_meets_the_mouth_at_the_maps_distance(d):
    # The array at H, a mouth at MOUTH: a bearing toward a mouth d m away points atan((H - MOUTH) / d) down.
    s = source(x=d, y=0.0)
    toward = -math.atan2(H - MOUTH, d)
    assert feature("range_agreement", ctx(s, heard=Heard(toward, -40.0, 0.5))) == pytest.approx(1.0, abs=1e-9)
    # The same bearing toward a mouth 0.5 m farther (or nearer) than the map says: another sound.
    for off in (0.5, -0.5):
        if d + off > 0.05:
            other = -math.atan2(H - MOUTH, d + off)
            assert feature("range_agreement", ctx(s, heard=Heard(other, -40.0, 0.5))) < 0.1
    assert feature("range_agreement", ctx(s, heard=Heard(math.radians(5.0), -40.0, 0.5))) == 0.0   # up: none


@pytest.mark.parametrize("sigma", [0.15, 0.2, 0.3, 0.5, 1.0])
def test_position_is_the_log_odds_of_the_gaussian_mass_within_the_find_radius(sigma):
    # Circular Gaussian: mass within r is 1 - exp(-r^2 / 2 s^2), so its log-odds is log(exp(r^2 / 2 s^2) - 1).
    r = FIND_RADIUS_M
    want = math.log(math.exp(r * r / (2 * sigma * sigma)) - 1.0)
    assert feature("position", ctx(source(sigma=sigma))) == pytest.approx(want, rel=1e-9)


def test_voice_is_the_log_odds_of_the_maps_victim_probability():
    for p in (0.1, 0.5, 0.9):
        assert feature("voice", ctx(source(p=p))) == pytest.approx(math.log(p / (1 - p)))


def test_distance_level_rise_and_the_neighbour_indicators():
    assert feature("distance", ctx(source(x=1.2, y=0.9))) == pytest.approx(1.5)
    # 10 dB louder than its faintest listen: 1 per 10 dB (inverse-square law: 3.2 times closer)
    s = source(levels=(-50.0, -45.0))
    assert feature("level_rise", ctx(s, heard=Heard(-0.3, -40.0, 0.5))) == pytest.approx(1.0)
    assert feature("level_rise", ctx(s, heard=Heard(-0.3, -55.0, 0.5))) == 0.0
    s = source(x=2.0, y=0.0)
    assert feature("near_machine", ctx(s, machines=((2.0 + 0.9 * MACHINE_RADIUS_M, 0.0),))) == 1.0
    assert feature("near_machine", ctx(s, machines=((2.0 + 1.1 * MACHINE_RADIUS_M, 0.0),))) == 0.0
    assert feature("near_machine", ctx(source(cls=SourceClass.INTERFERER))) == 1.0
    assert feature("near_found", ctx(s, found=((2.0, 0.9),))) == 1.0           # within twice the find radius
    assert feature("near_found", ctx(s, found=((2.0, 1.1),))) == 0.0
    assert feature("triangulated", ctx(source(crossing=20.0))) == 1.0
    assert feature("triangulated", ctx(source(crossing=5.0))) == 0.0
    assert feature("contact", ctx(contact=True)) == 1.0 and feature("contact", ctx()) == 0.0


class B:
    """A bearing heard from one spot (array frame)."""

    def __init__(self, az_deg, el_deg, level_db):
        self.azimuth, self.elevation, self.level_db = math.radians(az_deg), math.radians(el_deg), level_db


def test_is_echo_a_steep_bearing_no_louder_than_a_shallow_one_beside_it():
    shallow = B(10.0, -3.0, -40.0)
    steep = B(0.0, -35.0, -40.0)                      # 10 deg away in azimuth, as loud: the floor's image
    assert is_echo(steep, [shallow, steep])
    assert not is_echo(shallow, [shallow, steep])     # the shallow one is the source itself
    louder = B(0.0, -35.0, -37.0)                     # louder than the shallow one: a mouth below
    assert not is_echo(louder, [shallow, louder])
    far_az = B(60.0, -35.0, -45.0)                    # another direction: no image of that one
    assert not is_echo(far_az, [shallow, far_az])
    assert not is_echo(steep, [steep])                # alone from this spot
    # across the +-180 deg seam
    assert is_echo(B(-175.0, -35.0, -42.0), [B(175.0, -2.0, -42.0)])


# --- the model --------------------------------------------------------------------------------------------------

def _rich_context():
    s = source(x=0.5, y=0.1, sigma=0.25, p=0.8, levels=(-52.0,), crossing=20.0)
    return ctx(s, xy=(0.0, 0.0), heard=Heard(math.radians(-25.0), -42.0, 0.4, echo=True), contact=True,
               machines=((1.2, 0.4),), found=((0.9, 0.1),))


def test_without_a_cue_is_the_model_with_that_weight_zero():
    m = FoundModel.load()
    c = _rich_context()
    zero = FoundModel(m.bias, {**m.weights, "contact": 0.0})
    a, b = m.without("contact").assess(c, 0.0), zero.assess(c, 0.0)
    assert a.probability == pytest.approx(b.probability, rel=1e-12)
    assert "contact" not in a.features and "contact" in b.features
    assert m.assess(c, 0.0).probability != pytest.approx(a.probability) or m.weights.get("contact", 0.0) == 0.0


def test_assess_is_the_logistic_of_bias_plus_weighted_features():
    m = FoundModel.load()
    c = _rich_context()
    a = m.assess(c, 3.0)
    z = m.bias + sum(m.weights.get(k, 0.0) * v for k, v in a.features.items())
    assert a.probability == pytest.approx(1 / (1 + math.exp(-z)), rel=1e-12)
    assert a.position == (0.5, 0.1) and a.robot_xy == (0.0, 0.0) and a.time == 3.0
    assert set(a.features) == {q.name for q in CUES}


def test_model_file_errors_name_the_file(tmp_path):
    good = json.loads(default_model_path().read_text())
    unknown = tmp_path / "unknown.json"
    unknown.write_text(json.dumps({**good, "weights": {**good["weights"], "loudness": 1.0}}))
    with pytest.raises(ValueError, match=r"unknown\.json.*loudness"):
        FoundModel.load(unknown)
    no_bias = tmp_path / "no_bias.json"
    no_bias.write_text(json.dumps({k: v for k, v in good.items() if k != "bias"}))
    with pytest.raises(ValueError, match=r"no_bias\.json.*'bias'"):
        FoundModel.load(no_bias)
    with pytest.raises(ValueError, match=r"missing\.json"):
        FoundModel.load(tmp_path / "missing.json")
    with pytest.raises(ValueError, match="unknown cue"):
        FoundModel(0.0, {"loudness": 1.0})
    with pytest.raises(ValueError, match="finite"):
        FoundModel(float("nan"), {})


class _Fixed:
    """A cue of ``name`` whose feature is fixed (to sweep one cue with every other held)."""

    def __init__(self, name, value):
        self.name, self.value = name, value

    def feature(self, c):
        return self.value


@pytest.mark.parametrize("name", [q.name for q in CUES])
def test_p_find_moves_monotonically_with_each_cue_by_its_weights_sign(name):
    m = FoundModel.load()
    w = m.weights.get(name, 0.0)
    c = _rich_context()
    ps = []
    for v in np.linspace(0.0, 3.0, 7):
        cues = tuple(_Fixed(name, float(v)) if q.name == name else q for q in CUES)
        ps.append(replace(m, cues=cues).assess(c, 0.0).probability)
    d = np.diff(ps)
    if w > 0:
        assert np.all(d > 0), (name, ps)
    elif w < 0:
        assert np.all(d < 0), (name, ps)
    else:
        assert np.all(d == 0)


def test_the_model_shipped_loads_with_every_weight_a_known_cue():
    m = FoundModel.load()
    assert set(m.weights) <= {q.name for q in CUES} and math.isfinite(m.bias)
    assert 0 < float(m.provenance.get("confirm_probability", 0.3)) < 1


def test_finder_judges_unfound_sources_heard_now_or_within_reach_most_probable_first():
    """Reach: the base within BASE_RADIUS_M of a victim within FIND_RADIUS_M of the estimate."""
    reach = BASE_RADIUS_M + FIND_RADIUS_M
    near = source(x=1.0, sid=1)                                  # within reach, not heard now
    far_heard = source(x=reach + 2.0, sigma=1.5, sid=2)          # beyond reach but heard now
    far = source(x=reach + 0.1, sid=3)                           # beyond reach and silent: not judged
    found = replace(source(x=0.5, sid=4), state=SourceState.FOUND)  # found: never judged again
    finder = Finder(FoundModel.load(), H, MOUTH)
    ev = SimpleNamespace(azimuth=0.0, elevation=math.radians(-5.0), level_db=-40.0, power=0.3)  # array frame
    judged = finder.judge([near, far_heard, far, found], (0.0, 0.0), {2: ev}, now=3.0)
    assert sorted(s.id for s, _ in judged) == [1, 2]
    probs = [a.probability for _, a in judged]
    assert probs == sorted(probs, reverse=True)
    assert [a.source_id for a in finder.assessments] == [1, 2] and all(a.time == 3.0 for a in finder.assessments)
    # each one judged by the model on the context it was in
    for s, a in judged:
        heard = None if s.id != 2 else Heard(ev.elevation, ev.level_db, ev.power, False)
        assert a.probability == pytest.approx(finder.model.assess(ctx(s, heard=heard), 3.0).probability)
    # a contact at a source beyond reach brings it in
    assert 3 in [s.id for s, _ in finder.judge([far], (0.0, 0.0), {}, now=4.0, contact=3)]
