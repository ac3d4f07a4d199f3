"""Found as a probability: P(a victim lies within the find radius of the reported position), from the sound map's
belief about a source and the cues heard from where the robot stands.

The report is the map's estimate of the source (world frame). Each cue is a small typed object that turns what the
robot knows now into one number (a feature); the model adds the features, weighted, to a bias and reads the sum as
log-odds (logistic regression: each weight is the log-likelihood ratio per unit of its cue, the bias the prior
log-odds)::

    P(find) = 1 / (1 + exp(-(bias + sum_k w_k * f_k)))

The weights are fitted on the benchmark's train split by ``tools/fit_found_model.py`` (labels from the simulator's
truth: a victim not yet found within ``FIND_RADIUS_M`` of the report with the robot's base within
``BASE_RADIUS_M`` of her, the scoring's definition of a find) and stored with their provenance in
``robot/models/found_model.json``. A cue switched off by name (``FoundModel.without``) adds nothing: the same
model without that piece of evidence.

Why these cues, physically:

* ``voice``: the map's accumulated voice log-odds of the source (the VAD on a beam toward it, listen after listen):
  a machine or its echo is no victim however well placed;
* ``position``: log-odds of the map's Gaussian mass inside the find radius around its estimate (from the
  triangulation's covariance): a tight estimate is where she is, a loose one may be metres off;
* ``support``, ``consistency``, ``crossing``: how many listens agree with the estimate, what share of its
  listens do, and how wide their bearings cross: a reflection's image moves as the robot moves, a mouth does not;
* ``distance``: how far the robot's base is from the estimate: the find needs the base near her;
* ``beyond_reach``: how far the base is beyond 1 m of the estimate (the find's base radius less its report
  radius): a hinge, as the log-odds of a find fall steeply there;
* ``depression``: the sine of how steeply the bearing heard now points down. The array is ~0.3 m up and a mouth
  ~0.2 m; a mouth within reach is heard steeply, one across the room near the horizon;
* ``range_agreement``: the range at which the bearing heard now meets the mouth height, against the map's distance:
  a steep bearing that agrees with the estimate confirms it, one that disagrees is another sound (a floor echo,
  another caller);
* ``level_rise``: how much louder the source is now than in its faintest listen (inverse-square law: a caller
  approached from 3 m to 0.5 m rises ~15 dB; a reflection rises less);
* ``at_loudest``: the level heard now against its loudest listen: approaching a mouth, its direct sound keeps
  rising;
* ``coherence``: the SRP-PHAT peak power of the bearing heard now: within the room's critical distance the direct
  sound dominates and the peak is high, sound that came around a wall or from far away is diffuse;
* ``heard``: the source was heard in this listen at all (a caller pauses; a model trained with it learns how much a
  silent listen at the estimate says);
* ``echo``: a steep bearing no louder than a shallower one in the same direction heard from this spot: the floor's
  image of a farther source, not a mouth below;
* ``near_machine``: a mapped interferer within ``MACHINE_RADIUS_M``: rubble beside a machine sends its sound back
  steep and loud;
* ``near_found``: a victim already reported within twice the find radius (her own voice again, mostly);
* ``contact``: the bumper or the range sensors stopped a drive at this source's estimate (a victim under a slab is
  touched, not reached);
* ``triangulated``: two bearings from different poses cross at the map's minimum angle or more (range from
  geometry, not from the height prior).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Protocol, Sequence

import numpy as np

from robot.events import FindCriterion
from robot.odometry import wrap_angle
from robot.sound_map import DISTINCT_POSES_M, MapSource, SourceClass, SourceState

__all__ = ["FIND_RADIUS_M", "BASE_RADIUS_M", "MACHINE_RADIUS_M", "Heard", "FoundContext", "is_echo", "Spot", "Cue",
           "CUES", "FoundModel", "Assessment", "default_model_path"]

#: The find's definition (``ssl_sim.scoring``): a report within this of a victim ...
FIND_RADIUS_M = 0.5
#: ... with the robot's base within this of her.
BASE_RADIUS_M = 1.5
#: A mapped interferer this close to a source puts the source in its reflections' reach (rubble around a machine
#: is within ~1 m of it in the scenes the benchmark generates).
MACHINE_RADIUS_M = 1.0


@dataclass(frozen=True)
class Heard:
    """The bearing heard now from one source (array frame, from the robot's current pose)."""

    elevation: float       # rad, up positive
    level_db: float        # beam level of this listen (dB)
    power: float           # normalised SRP-PHAT peak power (0..1)
    echo: bool = False     # a shallower bearing at least as loud in the same direction from this spot


@dataclass(frozen=True)
class FoundContext:
    """What the robot knows about one source when it decides: the map's snapshot ``source`` (world frame), the
    robot's base ``xy`` (world m), the array's height and a mouth's height (m above the floor), what was heard of
    it now (``heard``, None when not heard in this listen), a contact with something at it while driving at it,
    and the world (x, y) of mapped interferers."""

    source: MapSource
    xy: tuple[float, float]
    array_height_m: float
    mouth_height_m: float
    heard: Heard | None = None
    contact: bool = False
    machines: tuple[tuple[float, float], ...] = ()
    found: tuple[tuple[float, float], ...] = ()     # world (x, y) of the victims reported so far

    @property
    def distance_m(self) -> float:
        return self.source.distance_to(self.xy)


class Cue(Protocol):
    """One piece of evidence: ``feature(ctx)`` -> a finite float (0 = no evidence either way for indicators)."""

    name: str

    def feature(self, ctx: FoundContext) -> float: ...


def _disk_logit(sigma_m: float, radius_m: float) -> float:
    """log-odds of the mass of a circular Gaussian (1-sigma ``sigma_m``) within ``radius_m`` of its mean:
    P = 1 - exp(-r^2 / 2 sigma^2), so log(P / (1 - P)) = log(exp(r^2 / 2 sigma^2) - 1)."""
    a = radius_m ** 2 / (2.0 * max(sigma_m, 1e-3) ** 2)
    return float(np.clip(a + math.log(-math.expm1(-a)) if a < 30 else a, -6.0, 6.0))


@dataclass(frozen=True)
class Voice:
    name: str = "voice"

    def feature(self, ctx: FoundContext) -> float:
        p = min(max(ctx.source.victim_probability, 1e-3), 1 - 1e-3)
        return math.log(p / (1 - p))


@dataclass(frozen=True)
class Position:
    name: str = "position"

    def feature(self, ctx: FoundContext) -> float:
        return _disk_logit(ctx.source.horizontal_sigma_m, FIND_RADIUS_M)


@dataclass(frozen=True)
class Distance:
    name: str = "distance"

    def feature(self, ctx: FoundContext) -> float:
        return min(ctx.distance_m, 3.0)


@dataclass(frozen=True)
class BeyondReach:
    """How far (m) the base is beyond 1 m of the estimate: a find needs the base within 1.5 m of her, and the
    estimate is 0.1-0.5 m off her, so the log-odds fall steeply there (a hinge beside the linear ``distance``)."""

    name: str = "beyond_reach"

    def feature(self, ctx: FoundContext) -> float:
        return float(np.clip(ctx.distance_m - (BASE_RADIUS_M - FIND_RADIUS_M), 0.0, 2.0))


@dataclass(frozen=True)
class Support:
    """log(1 + listens consistent with the estimate): a position many bearings agree on."""

    name: str = "support"

    def feature(self, ctx: FoundContext) -> float:
        return math.log1p(ctx.source.n_inliers)


@dataclass(frozen=True)
class Consistency:
    """Share of the source's listens consistent with its estimate: a reflection's bearings scatter as the robot
    moves (its image moves with the geometry), a mouth's stay on one point."""

    name: str = "consistency"

    def feature(self, ctx: FoundContext) -> float:
        return ctx.source.n_inliers / max(ctx.source.n_listens, 1)


@dataclass(frozen=True)
class Crossing:
    """Sine of the widest angle two of its bearings from different poses cross at: how well geometry fixes the
    range (a narrow crossing leaves it open along the bearing)."""

    name: str = "crossing"

    def feature(self, ctx: FoundContext) -> float:
        return math.sin(math.radians(min(ctx.source.crossing_deg, 90.0)))


@dataclass(frozen=True)
class AtLoudest:
    """The level heard now against the loudest listen of it, (now - max) / 10 dB in [-3, 0]: approaching a mouth
    its direct sound keeps rising (inverse-square law), so near her the listen now is the loudest; 0 when not heard
    (``heard`` carries that)."""

    name: str = "at_loudest"

    def feature(self, ctx: FoundContext) -> float:
        if ctx.heard is None:
            return 0.0
        return float(np.clip((ctx.heard.level_db - ctx.source.max_level_db) / 10.0, -3.0, 0.0))


@dataclass(frozen=True)
class Depression:
    name: str = "depression"

    def feature(self, ctx: FoundContext) -> float:
        return 0.0 if ctx.heard is None else max(0.0, -math.sin(ctx.heard.elevation))


@dataclass(frozen=True)
class RangeAgreement:
    """exp(-(mismatch / 0.3 m)^2): 1 when the bearing's floor range equals the map's distance; 0.3 m is the range
    error of a 3 deg elevation error at 30 deg depression from a 0.1 m height difference (a choice of scale; the
    weight is fitted)."""

    name: str = "range_agreement"

    def feature(self, ctx: FoundContext) -> float:
        h = ctx.array_height_m - ctx.mouth_height_m
        if ctx.heard is None or ctx.heard.elevation >= 0 or h <= 0:
            return 0.0
        r = h / math.tan(-ctx.heard.elevation)
        return math.exp(-((r - ctx.distance_m) / 0.3) ** 2)


@dataclass(frozen=True)
class LevelRise:
    name: str = "level_rise"

    def feature(self, ctx: FoundContext) -> float:
        if ctx.heard is None:
            return 0.0
        faintest = min((r.level_db for r in ctx.source.history), default=ctx.heard.level_db)
        return float(np.clip((ctx.heard.level_db - faintest) / 10.0, 0.0, 3.0))


@dataclass(frozen=True)
class Coherence:
    name: str = "coherence"

    def feature(self, ctx: FoundContext) -> float:
        return 0.0 if ctx.heard is None else float(np.clip(ctx.heard.power, 0.0, 1.0))


@dataclass(frozen=True)
class HeardNow:
    name: str = "heard"

    def feature(self, ctx: FoundContext) -> float:
        return float(ctx.heard is not None)


@dataclass(frozen=True)
class Echo:
    name: str = "echo"

    def feature(self, ctx: FoundContext) -> float:
        return float(ctx.heard is not None and ctx.heard.echo)


@dataclass(frozen=True)
class NearMachine:
    name: str = "near_machine"

    def feature(self, ctx: FoundContext) -> float:
        if ctx.source.cls is SourceClass.INTERFERER:
            return 1.0
        p = ctx.source.position
        return float(any(math.hypot(p[0] - m[0], p[1] - m[1]) <= MACHINE_RADIUS_M for m in ctx.machines))


@dataclass(frozen=True)
class NearFound:
    """A victim already reported within twice the find radius: most likely her own voice heard again (a
    reflection, a second bearing), a second victim only rarely."""

    name: str = "near_found"

    def feature(self, ctx: FoundContext) -> float:
        p = ctx.source.position
        return float(any(math.hypot(p[0] - f[0], p[1] - f[1]) <= 2 * FIND_RADIUS_M for f in ctx.found))


@dataclass(frozen=True)
class Contact:
    name: str = "contact"

    def feature(self, ctx: FoundContext) -> float:
        return float(ctx.contact)


@dataclass(frozen=True)
class Triangulated:
    name: str = "triangulated"

    def feature(self, ctx: FoundContext) -> float:
        return float(ctx.source.triangulated)


#: A bearing within this azimuth of a shallower one (within ``SHALLOW`` of the horizon), at least as loud, heard
#: from the same spot is that one's floor echo (the cube's beam is ~30 deg wide at the speech band's low end).
ECHO_AZIMUTH = math.radians(30.0)
SHALLOW = math.radians(15.0)


def is_echo(ev, spot: Sequence) -> bool:
    """``ev`` (array-frame ``azimuth``, ``elevation`` rad, ``level_db``) is no louder than a shallower bearing
    within ``ECHO_AZIMUTH`` heard from the same spot (``spot``: every bearing heard there): the floor's image of
    a farther source. A mouth right below is the loudest sound in its direction."""
    return any(o is not ev and abs(math.remainder(o.azimuth - ev.azimuth, 2 * math.pi)) <= ECHO_AZIMUTH
               and ev.elevation < o.elevation and abs(o.elevation) < SHALLOW and ev.level_db <= o.level_db
               for o in spot)


class Spot:
    """Every bearing heard from one standing place (array frame), for ``is_echo``. Bearings compare only from
    the same pose: a move of more than ``DISTINCT_POSES_M`` or a turn of more than 5 deg starts a new spot."""

    def __init__(self) -> None:
        self.heard: list = []
        self.pose: np.ndarray | None = None

    def add(self, pose: np.ndarray, evidence: Sequence) -> None:
        """``evidence`` heard at ``pose`` (x, y m, yaw rad; odometry frame)."""
        if self.pose is None or math.hypot(*(pose[:2] - self.pose[:2])) > DISTINCT_POSES_M \
                or abs(wrap_angle(pose[2] - self.pose[2])) > math.radians(5.0):
            self.heard, self.pose = [], pose.copy()
        self.heard += evidence

    def is_echo(self, ev) -> bool:
        return is_echo(ev, self.heard)


#: Every cue, in the order of the model's weights.
CUES: tuple[Cue, ...] = (Voice(), Position(), Support(), Consistency(), Crossing(), Distance(), BeyondReach(),
                         AtLoudest(), Depression(), RangeAgreement(), LevelRise(), Coherence(),
                         HeardNow(), Echo(), NearMachine(), NearFound(), Contact(), Triangulated())

#: The find criterion reported for the cue that added most to a find's log-odds.
_CRITERION = {"depression": FindCriterion.STEEP_BEARING, "range_agreement": FindCriterion.STEEP_BEARING,
              "level_rise": FindCriterion.LEVEL_RISE, "contact": FindCriterion.CONTACT,
              "voice": FindCriterion.VOICE}


@dataclass(frozen=True)
class Assessment:
    """One source judged once: its features (by cue name), P(find) and the cue that added most log-odds."""

    time: float
    source_id: int
    position: tuple[float, float]      # the report: the map's estimate, world (x, y) m
    robot_xy: tuple[float, float]
    features: Mapping[str, float]
    probability: float
    criterion: FindCriterion

    def describe(self, weights: Mapping[str, float]) -> str:
        terms = sorted(((weights.get(k, 0.0) * v, k) for k, v in self.features.items()), reverse=True)
        top = ", ".join(f"{k} {c:+.1f}" for c, k in terms[:3] if c > 0)
        return f"P(find) {self.probability:.2f} (log-odds terms: {top or 'none positive'})"


def default_model_path(driving: bool = False) -> Path:
    """The committed model; ``driving``: the one fitted on runs that also hear while driving (its listens add
    bearings between the standing ones, so support and triangulation mean less per listen)."""
    return Path(__file__).with_name("models") / ("found_model_driving.json" if driving else "found_model.json")


@dataclass(frozen=True)
class FoundModel:
    """Logistic model of P(find): ``bias`` and one weight per cue name (log-odds per unit of the feature).
    ``disabled``: cue names whose evidence is left out."""

    bias: float
    weights: Mapping[str, float]
    cues: tuple[Cue, ...] = CUES
    disabled: frozenset[str] = frozenset()
    provenance: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        names = {c.name for c in self.cues}
        unknown = (set(self.weights) | set(self.disabled)) - names
        if unknown:
            raise ValueError(f"FoundModel.weights: unknown cue name(s) {sorted(unknown)}; expected out of "
                             f"{sorted(names)}")
        if not all(math.isfinite(float(v)) for v in (self.bias, *self.weights.values())):
            raise ValueError("FoundModel: expected finite bias and weights")

    @classmethod
    def load(cls, path: str | Path | None = None, driving: bool = False) -> "FoundModel":
        """The fitted model (``default_model_path(driving)`` unless ``path``). A missing or malformed file raises
        ``ValueError`` naming it."""
        path = Path(path) if path is not None else default_model_path(driving)
        try:
            doc = json.loads(path.read_text())
            return cls(float(doc["bias"]), {k: float(v) for k, v in doc["weights"].items()},
                       provenance=doc.get("provenance", {}))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"found model {path}: expected a JSON object with 'bias' and 'weights' ({exc})") from exc

    def without(self, *names: str) -> "FoundModel":
        """This model with the cues ``names`` switched off."""
        return FoundModel(self.bias, self.weights, self.cues, self.disabled | frozenset(names), self.provenance)

    def features(self, ctx: FoundContext) -> dict[str, float]:
        return {c.name: float(c.feature(ctx)) for c in self.cues if c.name not in self.disabled}

    def assess(self, ctx: FoundContext, time: float) -> Assessment:
        f = self.features(ctx)
        terms = {k: self.weights.get(k, 0.0) * v for k, v in f.items()}
        z = self.bias + sum(terms.values())
        p = 1.0 / (1.0 + math.exp(-min(max(z, -50.0), 50.0)))
        top = max(((v, k) for k, v in terms.items() if k in _CRITERION), default=(0.0, ""))
        crit = _CRITERION.get(top[1], FindCriterion.MAP_ESTIMATE) if top[0] > 0 else FindCriterion.MAP_ESTIMATE
        s = ctx.source
        return Assessment(time, s.id, (float(s.position[0]), float(s.position[1])), tuple(map(float, ctx.xy)), f, p,
                          crit)


class Finder:
    """The found stage: P(find) of every unfound map source heard now or whose estimate is within reach of a find
    (the base within ``BASE_RADIUS_M`` of a victim within ``FIND_RADIUS_M`` of the estimate). Keeps the bearings
    heard from the current standing place (``spot``, for the echo cue) and every assessment (``assessments``, the
    data of the fit: tools/fit_found_model.py)."""

    def __init__(self, model: FoundModel, array_height_m: float, mouth_height_m: float) -> None:
        self.model, self.array_height_m, self.mouth_height_m = model, array_height_m, mouth_height_m
        self.spot = Spot()
        self.assessments: list[Assessment] = []

    def judge(self, sources: Sequence[MapSource], xy, heard: Mapping[int, object], now: float,
              machines: tuple[tuple[float, float], ...] = (), found: tuple[tuple[float, float], ...] = (),
              contact: int | None = None) -> list[tuple[MapSource, Assessment]]:
        """``sources`` judged from the base at ``xy`` (world m), most probable first. ``heard``: this listen's
        evidence by source id (array frame); ``machines``, ``found``: world (x, y) of the mapped interferers and
        of the victims reported so far; ``contact``: the source touched at its estimate."""
        xy = (float(xy[0]), float(xy[1]))
        out = []
        for s in sources:
            if s.state is SourceState.FOUND or (s.id not in heard and s.id != contact
                                                and s.distance_to(xy) > BASE_RADIUS_M + FIND_RADIUS_M):
                continue
            ev = heard.get(s.id)
            h = None if ev is None else Heard(ev.elevation, ev.level_db, ev.power, self.spot.is_echo(ev))
            ctx = FoundContext(s, xy, self.array_height_m, self.mouth_height_m, h, s.id == contact, machines, found)
            a = self.model.assess(ctx, now)
            self.assessments.append(a)
            out.append((s, a))
        return sorted(out, key=lambda sa: -sa[1].probability)
