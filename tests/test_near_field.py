"""Range from the wavefront's curvature (ssl_core.near_field) against exact spherical and plane waves and a
reverberant room: a near mouth focuses at its range, a far source and a plane wave do not."""
import numpy as np
import pytest

from signals import plane_wave, point_source, room_talker, speech_like
from ssl_core.geometry import cube8
from ssl_core.localizer import Localizer
from ssl_core.near_field import FocusScan

FS = 16000


@pytest.fixture(scope="module")
def loc():
    return Localizer("cube8")


def _direction(az_deg: float, el_deg: float) -> np.ndarray:
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


@pytest.mark.parametrize("r", [0.2, 0.3, 0.45])
@pytest.mark.parametrize("az_deg,el_deg", [(40.0, -25.0), (200.0, -10.0)])
def test_a_near_point_source_focuses_at_its_range(loc, r, az_deg, el_deg):
    u = _direction(az_deg, el_deg)
    x = point_source(cube8().positions, r * u, speech_like(FS, FS, seed=3), FS)
    res = loc.locate(x)
    f = loc.focus(res, res.detections[0].direction)
    assert f.range_m == pytest.approx(r, abs=0.051)      # the scan's range step near r
    assert f.gain > 1.03


def test_curvature_fades_with_range_and_a_plane_wave_has_none(loc):
    u = _direction(120.0, -15.0)
    s = speech_like(FS, FS, seed=4)
    gains = []
    for r in (0.25, 0.5, 1.0, 3.0):
        res = loc.locate(point_source(cube8().positions, r * u, s, FS))
        gains.append(loc.focus(res, res.detections[0].direction).gain)
    assert np.all(np.diff(gains) < 0), gains                # D^2 / 8r: the path-difference excess falls with r
    assert gains[-1] < 1.01
    res = loc.locate(plane_wave(cube8().positions, u, s, FS))
    f = loc.focus(res, res.detections[0].direction)
    assert f.range_m == np.inf and f.gain == 1.0


def test_in_a_reverberant_room_a_mouth_at_0_3_m_focuses_and_one_at_2_m_does_not(loc):
    u = _direction(60.0, -15.0)
    m = cube8().positions
    near = loc.locate(room_talker(m, u, 1.0, FS, seed=5, rt60_s=0.6, distance_m=0.3))
    far = loc.locate(room_talker(m, u, 1.0, FS, seed=5, rt60_s=0.6, distance_m=2.0))
    f_near = loc.focus(near, near.detections[0].direction)
    f_far = loc.focus(far, far.detections[0].direction)
    assert f_near.range_m <= 0.45 and f_near.gain > 1.03
    assert f_far.gain < 1.02


def test_bad_input_is_named(loc):
    with pytest.raises(ValueError, match="gcc"):
        loc._focus.scan(np.zeros((3, 5)), [1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="ranges_m"):
        FocusScan(cube8(), FS * 4, 40, ranges_m=(0.0, 0.5))


def test_nothing_heard_has_no_focus(loc):
    res = loc.locate(np.zeros((8, FS)))
    assert loc.focus(res, [1.0, 0.0, 0.0]) is None

