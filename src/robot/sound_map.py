"""World-frame sound-source map: bearings heard from many poses -> source positions, classes and states.

Frames. Evidence directions are in the ARRAY frame (the array is level and its axes are the robot's:
azimuth CCW from forward, elevation up). The map is in the odometry/world frame (x, y, z in m, z up);
the array centre is ``robot.mount.ArrayMount.height_m`` above the floor at the robot's (x, y).
``SoundMap.update`` is the only place that converts between them, with the pose at which the audio was captured.

Estimator (per source), after Sasaki et al.'s self-motion triangulation (bearings from many robot poses,
RANSAC against wrong bearings) and Michaud et al. (IROS 2020: triangulated bearings from poses 30-140 deg
apart give < 0.3 m):

* every listen toward the source is a ray (array centre, world direction) kept in its history;
* the position minimises the squared azimuth/elevation residuals of its inlier rays plus a soft prior on
  the height (people and machines are on or near the floor: ``source_height_m`` +- ``source_height_sigma_m``).
  The prior makes a single ray a point too (the elevation-with-array-height range cue, as in the old
  behaviour) and is outweighed as soon as rays from other poses triangulate;
* robust: RANSAC over ray pairs (and single rays with the height prior) picks the hypothesis with most
  rays within ``inlier_deg``; Gauss-Newton refines on those inliers; rays off by more (reflections,
  occlusion in rubble: An et al. ICRA 2018 measure 0.8 m errors from them) are kept but ignored;
* covariance: the inverse of the Gauss-Newton normal matrix at the bearing noise ``bearing_sigma_deg``
  (elevation: ``elevation_sigma_deg``; a ray heard while driving ``moving_elevation_sigma_deg``);
* association of a new ray: Mahalanobis gate on the (azimuth, elevation) innovation with
  ``S = H P H^T + R`` (chi-square, 2 degrees of freedom) -- a source known only along one ray accepts a
  ray from a new pose anywhere along that first ray. The track id is a second association: a track that fed a
  source keeps feeding it while its rays stay within ``TRACK_GATE_FACTOR`` (2) times the gate's chi-square.
  Two rays of one update never join one source.

Class: each inlier listen is independent evidence: the victim probability is the sigmoid of the sum of
the listens' voice log-odds (prior 0.5), clipped to +-``max_log_odds`` so either class can be overturned.
Per-listen evidence (``robot.listening``: ``VOICE_P`` for a listen whose beam had speech, ``NON_VOICE_P`` for one
without) is the likelihood ratio measured on the benchmark's train split (``tools/fit_voice_evidence.py``): a
listen with speech adds +1.9, one without -0.5, at every beam level (faint beams are no weaker evidence: a
calling victim's beam has speech in 56 % of listens below -60 dB re full scale, 35-43 % above -54 dB). One listen
with speech outweighs about four without: a caller who pauses stays a victim, a machine or an echo heard in a few
listens without a speech frame becomes an interferer. Victim at or above
``victim_probability``, interferer at or below ``interferer_probability``, unknown between.
State: ``UNVISITED`` -> ``APPROACHING`` -> ``FOUND`` (set by the behaviour), or ``REJECTED`` (visited and
still no voice: a machine). A found source stays found: rays that associate to it, or a new source born
within ``merge_distance_m`` of it, are absorbed.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum
from typing import ClassVar, Protocol, Sequence

import numpy as np

from robot.config_values import need
from robot.mount import ArrayMount
from robot.odometry import Pose2D, pose_at

__all__ = ["BearingEvidence", "DISTINCT_POSES_M", "SoundMapConfig", "SourceClass", "SourceState", "Listen",
           "MapSource", "SoundMap", "pose_at", "triangulate"]


class BearingEvidence(Protocol):
    """What the map needs from one listen toward one source (``robot.hearing.TrackEvidence`` has it)."""

    track_id: int | None           # tracker id (None: untracked per-window detection)
    direction: np.ndarray          # (3,) unit vector, ARRAY frame
    time: float                    # s, stream time
    voice_probability: float       # 0..1
    level_db: float                # beam level toward it (dB re full-scale sine)
    activity: float                # 0..1


class SourceClass(str, Enum):
    VICTIM = "victim"
    INTERFERER = "interferer"
    UNKNOWN = "unknown"


class SourceState(str, Enum):
    UNVISITED = "unvisited"
    APPROACHING = "approaching"
    FOUND = "found"
    REJECTED = "rejected"


@dataclass(frozen=True)
class SoundMapConfig:
    """Parameters of the map (SI units; ``*_deg`` in degrees)."""

    source_height_m: float = 0.2           # prior mean height of a source: a lying/sitting victim, a machine
    source_height_sigma_m: float = 0.3     # ... and its spread (a person standing is ~2 sigma)
    bearing_sigma_deg: float = 5.0         # azimuth noise of one listen (SRP-PHAT in RT60 0.6 s rubble: median
    #                                        errors 2-5 deg in the shipped runs' listens)
    elevation_sigma_deg: float = 8.0       # elevation is worse on the cube (floor reflections)
    # A bearing heard while driving: the ego-noise template leaves mostly the band below 3 kHz, where the elevation
    # lobe is broad and reads low (likely taking in the floor reflection) by a bias shared by the drive's windows
    # (-2.9 / -2.4 deg mean at 1-2 / 2-3 m against -1.0 / -0.4 standing, docs/design/ego_noise.md), which a dozen
    # such rays do not average away. Three times the standing noise: nine of them weigh in elevation as one standing listen, so the source's
    # range comes from the standing listens and the drive's azimuths.
    moving_elevation_sigma_deg: float = 24.0
    inlier_deg: float = 12.0               # RANSAC: a ray this close to the hypothesis supports it
    gate_chi2: float = 13.8                # association gate: chi-square 2 dof, 99.9 %
    ransac_hypotheses: int = 96            # random ray pairs per refit (plus every single ray)
    min_pair_angle_deg: float = 15.0       # two rays must cross at least this much to triangulate (3 bearing
    #                                        sigmas: a shallower crossing puts the point anywhere along the rays)
    merge_distance_m: float = 0.5          # two sources closer than this (horizontally) are one
    max_rays: int = 120                    # history kept per source (newest)
    forget_s: float = 40.0                 # a source with < 3 listens unheard this long is dropped
    victim_probability: float = 0.6        # class thresholds on the accumulated voice probability
    interferer_probability: float = 0.15   # (0.15: four listens without speech from the prior)
    max_log_odds: float = 6.0              # |sum of listen log-odds| cap
    max_range_m: float = 15.0              # no source farther than this from where it was heard
    min_range_m: float = 0.05              # ... nor nearer (horizontally) than this: not inside the array's mast. A
    #                                        mouth can be right below the bumper ring (0.16 m): a caller heard at
    #                                        -67 deg elevation lies 6 cm out, which a 0.2 m floor would refuse
    seed: int = 0                          # RANSAC sampling
    max_table_mb: float = 512.0            # refuse RANSAC tables (hypotheses x rays) that would need more memory

    @property
    def ransac_table_mb(self) -> float:
        """Peak memory (MB) of one refit at ``max_rays`` rays: every candidate point (hypotheses, all pairs when
        fewer, plus one per ray) against every ray. Measured with tracemalloc: 53-63 bytes per (candidate, ray)
        (the (candidates, rays, 3) vectors of ``_ray_angle`` and their temporaries); 64 taken."""
        n, h = self.max_rays, self.ransac_hypotheses
        pairs = n * (n - 1) // 2
        draws = 4 * h if h < pairs else 0     # random pairs drawn (2 x 4 h int64) when not every pair is tried
        return 64.0 * (draws / 4 + (min(h, pairs) + n) * n) / 1e6

    #: Fields that no longer exist (robot.config_values.field_values refuses them, saying where they went).
    RETIRED: ClassVar[dict[str, str]] = {
        "array_height_m": "MOVED: the array's height is robot.mount.ArrayMount.height_m (ssl-robot: --set "
                          "mount.height_m=...; in simulation the robot model's cube height, set by the simulator)",
        **{name: "a listen without speech counts the same at every beam level: measured on the train split, faint "
                 "beams are no weaker evidence (tools/fit_voice_evidence.py)"
           for name in ("silent_loud_db", "silent_faint_db", "silent_faint_weight")}}

    def __post_init__(self) -> None:
        need(self, self.source_height_sigma_m > 0, "source_height_sigma_m", "> 0 m")
        need(self, 0 < self.bearing_sigma_deg < 45, "bearing_sigma_deg", "in (0, 45) degrees")
        need(self, 0 < self.elevation_sigma_deg < 45, "elevation_sigma_deg", "in (0, 45) degrees")
        need(self, 0 < self.moving_elevation_sigma_deg < 90, "moving_elevation_sigma_deg", "in (0, 90) degrees")
        need(self, 0 < self.inlier_deg < 90, "inlier_deg", "in (0, 90) degrees")
        need(self, self.gate_chi2 > 0, "gate_chi2", "> 0")
        need(self, self.ransac_hypotheses >= 1, "ransac_hypotheses", "an integer >= 1")
        need(self, 0 <= self.min_pair_angle_deg < 90, "min_pair_angle_deg", "in [0, 90) degrees")
        need(self, self.merge_distance_m >= 0, "merge_distance_m", ">= 0 m")
        need(self, self.max_rays >= 2, "max_rays", "an integer >= 2")
        need(self, self.forget_s > 0, "forget_s", "> 0 s")
        need(self, 0 <= self.interferer_probability <= self.victim_probability <= 1, "victim_probability",
             f"in [interferer_probability ({self.interferer_probability}), 1]")
        need(self, self.max_log_odds > 0, "max_log_odds", "> 0")
        need(self, 0 < self.min_range_m < self.max_range_m, "min_range_m", "in (0, max_range_m) m")
        need(self, self.seed >= 0, "seed", "an integer >= 0 (numpy's generators take no negative seed)")
        need(self, self.max_table_mb > 0, "max_table_mb", "> 0 MB")
        if self.ransac_table_mb > self.max_table_mb:
            field = "max_rays" if self.max_rays ** 2 * 64 > self.ransac_table_mb * 1e6 / 2 else "ransac_hypotheses"
            need(self, False, field,
                 f"a RANSAC table within max_table_mb={self.max_table_mb:g} MB: ransac_hypotheses="
                 f"{self.ransac_hypotheses} x max_rays={self.max_rays} needs about {_size(self.ransac_table_mb)}")


def _size(mb: float) -> str:
    return f"{mb / 1e6:.1f} TB" if mb >= 1e6 else f"{mb / 1e3:.1f} GB" if mb >= 1e3 else f"{mb:.0f} MB"


@dataclass(frozen=True)
class Listen:
    """One listen toward a source: where from, which way (world frame), and what was heard."""

    time: float                    # s
    origin: tuple[float, float, float]   # array centre, world frame (m)
    direction: tuple[float, float, float]  # unit vector, world frame
    track_id: int | None
    voice_probability: float
    level_db: float
    activity: float
    moving: bool = False           # heard while the robot drove (its elevation is less certain)


@dataclass(frozen=True)
class MapSource:
    """A snapshot of one mapped source (world frame)."""

    id: int
    position: np.ndarray           # (3,) x, y, z (m), world frame
    covariance: np.ndarray         # (3, 3) m^2
    victim_probability: float      # 0..1
    cls: SourceClass
    state: SourceState
    n_listens: int                 # listens associated
    n_inliers: int                 # listens consistent with the position
    first_time: float              # s
    last_time: float               # s, last listen
    last_level_db: float           # beam level of the last listen
    max_level_db: float
    history: tuple[Listen, ...]
    found_time: float | None = None
    baseline_m: float = 0.0        # largest horizontal distance between two listening poses of its inliers
    crossing_deg: float = 0.0      # largest crossing angle of two inlier bearings from different poses
    min_crossing_deg: float = 15.0  # the map's min_pair_angle_deg

    @property
    def triangulated(self) -> bool:
        """Its range comes from geometry, not only from the height prior: two inlier bearings from different
        poses cross at ``min_pair_angle_deg`` or more (15 deg: 3 bearing sigmas). A baseline alone is not
        enough: 0.3 m seen from a caller 4 m away subtends 4 deg, less than the bearing noise, and the range of
        such bearings comes from the elevation and the height prior (about 1 m for a far caller heard near the
        horizon), not from where she is."""
        return self.crossing_deg >= self.min_crossing_deg

    @property
    def horizontal_sigma_m(self) -> float:
        """sqrt of the largest eigenvalue of the horizontal covariance (m): the 1-sigma ellipse's long axis."""
        return float(math.sqrt(max(np.linalg.eigvalsh(self.covariance[:2, :2]).max(), 0.0)))

    def distance_to(self, xy) -> float:
        return float(math.hypot(self.position[0] - xy[0], self.position[1] - xy[1]))


@dataclass
class _Source:
    id: int
    rays: list[Listen] = field(default_factory=list)
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    covariance: np.ndarray = field(default_factory=lambda: np.eye(3))
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    state: SourceState = SourceState.UNVISITED
    found_time: float | None = None
    max_level_db: float = -math.inf


# ----------------------------------------------------------------------------- geometry
LEVEL_RAY_RANGE_M = 3.0   # range guessed for a bearing that does not point down to the height prior
DISTINCT_POSES_M = 0.15   # two listens at least this far apart (horizontally) are from different poses
TRACK_GATE_FACTOR = 2.0   # a ray's chi-square may reach this times gate_chi2 at the source its track id fed
NEAR_CROSSING_M = 0.5     # a source heard along one ray takes a new ray only where it crosses that ray this far
#                           (horizontally) from the new ray's origin or farther (see ``SoundMap._along_ray``)
TIE_RAD = 1e-6            # angles (rad) closer than this are equal when hypotheses are ranked: far below any
#                           bearing noise, far above the rounding that differs between BLAS kernels (1e-9 rad)


def _baseline(rays: Sequence[Listen]) -> float:
    """Largest horizontal distance (m) between two listening positions of ``rays``."""
    return _spread(np.array([r.origin for r in rays]).reshape(-1, 3))


def _spread(o: np.ndarray) -> float:
    """Largest horizontal distance (m) between two of the origins ``o`` (n, 3)."""
    return float(np.max(np.linalg.norm(o[:, None, :2] - o[None, :, :2], axis=-1))) if len(o) > 1 else 0.0


def _crossing_deg(rays: Sequence[Listen]) -> float:
    """Largest angle (deg) between the horizontal directions of two of ``rays`` heard from different poses
    (origins >= ``DISTINCT_POSES_M`` apart): how well their bearings cross, i.e. fix the range."""
    if len(rays) < 2:
        return 0.0
    return _crossing_of(np.array([r.origin for r in rays]), np.array([r.direction for r in rays]))


def _crossing_of(o: np.ndarray, d: np.ndarray) -> float:
    """``_crossing_deg`` of rays given as origins (n, 3) and directions (n, 3)."""
    if len(o) < 2:
        return 0.0
    apart = np.linalg.norm(o[:, None, :2] - o[None, :, :2], axis=-1) >= DISTINCT_POSES_M
    az = np.arctan2(d[:, 1], d[:, 0])
    cross = np.abs(_wrap(az[:, None] - az[None]))
    return float(np.degrees(np.max(np.where(apart, cross, 0.0))))


def _along_mean_ray(o: np.ndarray, d: np.ndarray, cfg: SoundMapConfig) -> tuple[np.ndarray, np.ndarray]:
    """Position and covariance of a source heard from one place only: on its rays' mean at the height prior's
    range, at most 3 m, with a range 1-sigma of at least 3 m (it is a guess) and the bearing noise across.
    Gauss-Newton on such rays has no range to converge to: from six near-level rays of one pose it wandered to
    points 5-25 m away on any side, leaving no inlier."""
    origin = o.mean(axis=0)
    u = d.mean(axis=0)
    u /= max(float(np.linalg.norm(u)), 1e-12)
    # (a bearing a few degrees below level puts the height prior 2-15 m out: within the elevation noise of
    # 8 deg, no range at all, so no guess beyond the level rays' one)
    r = float(_on_prior_height(origin[None], u[None], cfg)[0] @ u - origin @ u)
    r = min(max(r, cfg.min_range_m), LEVEL_RAY_RANGE_M)
    p = origin + r * u
    across = (r * math.tan(math.radians(cfg.bearing_sigma_deg))) ** 2 / len(o)
    along = max(r, LEVEL_RAY_RANGE_M) ** 2     # the range is a guess: the planner must know it
    uu = np.outer(u, u)
    cov = along * uu + across * (np.eye(3) - uu)
    cov[2, 2] = max(cov[2, 2], cfg.source_height_sigma_m ** 2)
    return p, cov


def _angles(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rho = np.hypot(v[..., 0], v[..., 1])
    return np.arctan2(v[..., 1], v[..., 0]), np.arctan2(v[..., 2], rho)


def _jacobian(v: np.ndarray) -> np.ndarray:
    """d(az, el)/dp for rays with p - o = v ``(n, 3)`` -> ``(n, 2, 3)``."""
    rho2 = np.maximum(v[:, 0] ** 2 + v[:, 1] ** 2, 1e-12)
    rho = np.sqrt(rho2)
    r2 = rho2 + v[:, 2] ** 2
    j = np.zeros((len(v), 2, 3))
    j[:, 0, 0], j[:, 0, 1] = -v[:, 1] / rho2, v[:, 0] / rho2
    j[:, 1, 0] = -v[:, 0] * v[:, 2] / (r2 * rho)
    j[:, 1, 1] = -v[:, 1] * v[:, 2] / (r2 * rho)
    j[:, 1, 2] = rho / r2
    return j


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _ray_angle(origins: np.ndarray, dirs: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Angle (rad) between each ray and the direction from its origin to each point: ``(n_points, n_rays)``."""
    v = points[:, None, :] - origins[None, :, :]
    norm = np.maximum(np.linalg.norm(v, axis=-1), 1e-9)
    return np.arccos(np.clip(np.sum(v * dirs[None], axis=-1) / norm, -1.0, 1.0))


def triangulate(origins, directions, cfg: SoundMapConfig = SoundMapConfig(),
                rng: np.random.Generator | None = None, elevation_sigma_deg: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robust position of one source from rays (world frame): ``(position (3,), covariance (3, 3), inliers (n,))``.

    ``origins``: (n, 3) array centres (m); ``directions``: (n, 3) unit vectors toward the source;
    ``elevation_sigma_deg``: (n,) each ray's elevation noise (deg; None: ``cfg.elevation_sigma_deg`` for all)."""
    o = np.asarray(origins, float).reshape(-1, 3)
    d = np.asarray(directions, float).reshape(-1, 3)
    if len(o) != len(d) or not len(o):
        raise ValueError(f"origins/directions: expected the same number (>= 1) of rays, got {len(o)} and {len(d)}")
    el_sigma = np.full(len(o), cfg.elevation_sigma_deg) if elevation_sigma_deg is None \
        else np.asarray(elevation_sigma_deg, float).reshape(-1)
    if len(el_sigma) != len(o):
        raise ValueError(f"elevation_sigma_deg: expected one per ray ({len(o)}), got {len(el_sigma)}")
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    rng = rng if rng is not None else np.random.default_rng(cfg.seed)
    hyp = [_on_prior_height(o, d, cfg)]
    n = len(o)
    if n >= 2:
        if n * (n - 1) // 2 <= cfg.ransac_hypotheses:      # few rays: every pair
            pairs = np.stack(np.triu_indices(n, 1), axis=1)
        else:
            i = rng.integers(0, n, size=4 * cfg.ransac_hypotheses)
            j = rng.integers(0, n, size=4 * cfg.ransac_hypotheses)
            ok = i != j
            pairs = np.unique(np.sort(np.stack([i[ok], j[ok]], 1), axis=1), axis=0)[:cfg.ransac_hypotheses]
        hyp.append(_closest_points(o[pairs[:, 0]], d[pairs[:, 0]], o[pairs[:, 1]], d[pairs[:, 1]], cfg))
    cand = np.concatenate(hyp)
    cand = cand[np.all(np.isfinite(cand), axis=1)]
    err = _ray_angle(o, d, cand)
    inl = err <= math.radians(cfg.inlier_deg)
    # Most inliers, then the smallest summed inlier angle counted in whole microradians, ties to the earliest.
    # Rays that meet nowhere leave one hypothesis per ray, each ray's own point at the height prior, with one
    # inlier at angle 0 up to float rounding: compared raw, that tie went to whichever the BLAS kernel rounded
    # lower. The earliest ray is the one the source was founded on: it stays there until two rays agree elsewhere.
    k = int(np.lexsort((np.round(np.where(inl, err, 0).sum(1) / TIE_RAD), -inl.sum(1)))[0])
    best, mask = cand[k], inl[k]
    if not np.any(mask):
        mask = np.zeros(n, bool)
        mask[-1] = True
    if _spread(o[mask]) < DISTINCT_POSES_M:   # all from one place: no parallax at all
        p, cov = _along_mean_ray(o[mask], d[mask], cfg)
        return p, cov, _ray_angle(o, d, p[None])[0] <= math.radians(cfg.inlier_deg)
    p, cov = _refine(o[mask], d[mask], best, cfg, el_sigma[mask])
    mask = _ray_angle(o, d, p[None])[0] <= math.radians(cfg.inlier_deg)
    if np.any(mask):
        p, cov = _refine(o[mask], d[mask], p, cfg, el_sigma[mask])
    return p, cov, mask


def _on_prior_height(o: np.ndarray, d: np.ndarray, cfg: SoundMapConfig) -> np.ndarray:
    """Each ray continued to the prior source height (the elevation range cue); level rays to 3 m."""
    dz = cfg.source_height_m - o[:, 2]
    t = np.where(d[:, 2] * dz > 1e-3 * np.abs(dz), dz / np.where(np.abs(d[:, 2]) > 1e-9, d[:, 2], 1e-9),
                 LEVEL_RAY_RANGE_M)
    t = np.clip(t, 0.2, cfg.max_range_m)
    return o + t[:, None] * d


def _closest_points(o1, d1, o2, d2, cfg: SoundMapConfig) -> np.ndarray:
    """Midpoints of the closest approach of ray pairs; NaN where they are near-parallel or meet behind."""
    w = o1 - o2
    b = np.sum(d1 * d2, axis=1)
    dd, e = np.sum(d1 * w, axis=1), np.sum(d2 * w, axis=1)
    den = 1 - b**2
    par = den < math.sin(math.radians(max(cfg.min_pair_angle_deg, 1e-3))) ** 2
    den = np.where(par, 1.0, den)
    t1 = (b * e - dd) / den
    t2 = (e - b * dd) / den
    p = 0.5 * (o1 + t1[:, None] * d1 + o2 + t2[:, None] * d2)
    bad = par | (t1 < 0.05) | (t2 < 0.05) | (t1 > cfg.max_range_m) | (t2 > cfg.max_range_m)
    p[bad] = np.nan
    return p


def _refine(o: np.ndarray, d: np.ndarray, p0: np.ndarray, cfg: SoundMapConfig, el_sigma_deg: np.ndarray,
            iters: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """Gauss-Newton on the (az, el) residuals plus the height prior; returns (p, covariance).
    ``el_sigma_deg``: (n,) each ray's elevation noise."""
    az_m, el_m = _angles(d)
    w = np.stack([np.full(len(o), 1 / math.radians(cfg.bearing_sigma_deg) ** 2),
                  1 / np.radians(el_sigma_deg) ** 2], axis=1)   # (n, 2)
    wz = 1 / cfg.source_height_sigma_m**2
    p = p0.astype(float).copy()
    for _ in range(iters):
        v = p - o
        az, el = _angles(v)
        r = np.stack([_wrap(az - az_m), el - el_m], axis=1)  # (n, 2)
        j = _jacobian(v)
        a = np.einsum("nki,nk,nkj->ij", j, w, j)
        g = np.einsum("nki,nk,nk->i", j, w, r)
        a[2, 2] += wz
        g[2] += wz * (p[2] - cfg.source_height_m)
        a += np.eye(3) * 1e-6
        step = np.linalg.solve(a, -g)
        # Keep the point in front of every inlier ray (a step through an origin flips its bearings).
        norm = float(np.linalg.norm(step))
        if norm > 1.0:
            step *= 1.0 / norm
        p = p + step
        # A source is not inside the robot: keep it min_range_m (horizontally) from every listening pose.
        v = p[None, :2] - o[:, :2]
        rho = np.hypot(v[:, 0], v[:, 1])
        k = int(np.argmin(rho))
        if rho[k] < cfg.min_range_m:
            u = v[k] / rho[k] if rho[k] > 1e-9 else d[k, :2] / max(float(np.hypot(*d[k, :2])), 1e-9)
            p[:2] = o[k, :2] + cfg.min_range_m * u
        if norm < 1e-4:
            break
    cov = np.linalg.inv(a)
    return p, 0.5 * (cov + cov.T)


# ----------------------------------------------------------------------------- the map
class SoundMap:
    """Sound sources in the world frame, built from listens at known poses (see the module docstring)."""

    def __init__(self, config: SoundMapConfig = SoundMapConfig(), mount: ArrayMount = ArrayMount()) -> None:
        self.config, self.mount = config, mount
        self._sources: list[_Source] = []
        self._next_id = 1  # numbered from 1, as the victims found are, in everything the behaviour prints
        self._track_to_source: dict[int, int] = {}
        self._merged_into: dict[int, int] = {}  # merged source id -> the id that absorbed it
        self._rng = np.random.default_rng(config.seed)
        self.time = 0.0

    # -- reading ------------------------------------------------------------------------
    @property
    def sources(self) -> list[MapSource]:
        """All mapped sources, oldest first."""
        return [self._snapshot(s) for s in self._sources]

    def source(self, source_id: int) -> MapSource:
        return self._snapshot(self._get(source_id))

    def unfound_victims(self, min_probability: float | None = None) -> list[MapSource]:
        """Sources classified (or, with ``min_probability``, at least that likely) victim and not found."""
        out = []
        for s in self.sources:
            if s.state is SourceState.FOUND:
                continue
            ok = s.cls is SourceClass.VICTIM if min_probability is None else s.victim_probability >= min_probability
            if ok:
                out.append(s)
        return out

    def interferers(self) -> list[np.ndarray]:
        """World (x, y) m of the mapped sources classified interferer and not found: their sound masks the callers
        near them."""
        return [s.position[:2] for s in self.sources if s.cls is SourceClass.INTERFERER and s.state is not SourceState.FOUND]

    # -- writing ------------------------------------------------------------------------
    def update(self, evidence: Sequence[BearingEvidence], pose: Pose2D | Sequence[float], time: float,
               moving: bool = False) -> list[tuple[BearingEvidence, int]]:
        """Fold in one listen's evidence heard at ``pose``; returns (evidence, source id) pairs.

        ``evidence``: directions in the ARRAY frame (level array, axes the robot's).
        ``pose``: (x m, y m, yaw rad) of the robot in the world/odometry frame when the audio was captured.
        ``time``: s, the listen's time (stream time of the evidence). ``moving``: heard while the robot drove (its
        elevations weigh with ``moving_elevation_sigma_deg`` in the source's position)."""
        x, y, yaw = (float(v) for v in pose)
        if not all(map(math.isfinite, (x, y, yaw, time))):
            raise ValueError(f"pose/time: expected finite numbers, got pose={tuple(pose)!r}, time={time!r}")
        self.time = float(time)
        c, s = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        origin = np.array([x, y, self.mount.height_m])
        rays = []
        for ev in evidence:
            u = np.asarray(ev.direction, float).reshape(3)
            nu = float(np.linalg.norm(u))
            if not nu > 0 or not math.isfinite(nu):
                raise ValueError(f"evidence.direction: expected a nonzero finite 3-vector, got {ev.direction!r}")
            rays.append((ev, rot @ (u / nu)))
        out = []
        taken: set[int] = set()
        # Most confident rays first: they claim their source before weaker ones.
        for ev, d in sorted(rays, key=lambda r: -float(r[0].activity)):
            sid = self._associate(ev, origin, d, taken)
            listen = Listen(float(time), tuple(origin), tuple(d), ev.track_id, float(ev.voice_probability),
                            float(ev.level_db), float(ev.activity), bool(moving))
            if sid is None:
                src = _Source(self._next_id)
                self._next_id += 1
                self._sources.append(src)
            else:
                src = self._get(sid)
            src.rays.append(listen)
            del src.rays[:-self.config.max_rays]
            src.max_level_db = max(src.max_level_db, listen.level_db)
            self._refit(src)
            if ev.track_id is not None:
                self._track_to_source[int(ev.track_id)] = src.id
            taken.add(src.id)
            out.append((ev, src.id))
        self._merge()
        self._forget()
        alive = {s.id for s in self._sources}
        return [(ev, self._resolve(sid)) for ev, sid in out if self._resolve(sid) in alive]

    def update_moving(self, evidence: Sequence[BearingEvidence], trajectory, window_s: float
                      ) -> list[tuple[BearingEvidence, int]]:
        """``update`` for evidence heard while the robot moved: each piece at the pose interpolated at the
        middle of its analysis window (``ev.time`` is the window's end, ``window_s`` s its length; a 1 s
        listen at 0.3 m/s moves the array 0.3 m, so the pose at either end would be up to 0.15 m off).
        ``trajectory``: (k, 4) rows ``(time s, x m, y m, yaw rad)`` in stream time, increasing. Evidence of
        one window time is one ``update`` (its rays still never join one source)."""
        if not (math.isfinite(window_s) and window_s >= 0):
            raise ValueError(f"window_s: expected a finite length >= 0 s, got {window_s!r}")
        out: list[tuple[BearingEvidence, int]] = []
        groups: dict[float, list[BearingEvidence]] = {}
        for ev in evidence:
            groups.setdefault(float(ev.time), []).append(ev)
        for t in sorted(groups):
            out += self.update(groups[t], pose_at(trajectory, t - 0.5 * window_s), t, moving=True)
        return out

    def set_state(self, source_id: int, state: SourceState, time: float | None = None) -> None:
        """Behaviour's verdict; a found source never goes back."""
        src = self._get(source_id)
        if src.state in (SourceState.FOUND, SourceState.REJECTED) and state is not SourceState.FOUND:
            return
        if src.state is SourceState.FOUND:
            return
        src.state = SourceState(state)
        if src.state is SourceState.FOUND:
            src.found_time = self.time if time is None else float(time)

    def restart_from(self, source_id: int, xy, radius_m: float = DISTINCT_POSES_M) -> int:
        """Keep only the listens of a source heard within ``radius_m`` (horizontally) of ``xy`` (world m) and
        refit: the behaviour's verdict that the bearings heard here, close to its estimate, refute the older ones
        (two callers' rays that crossed into one ghost, a reflection). Returns the number of listens kept."""
        src = self._get(source_id)
        keep = [r for r in src.rays if math.hypot(r.origin[0] - xy[0], r.origin[1] - xy[1]) <= radius_m]
        if not keep:
            raise ValueError(f"xy: source {source_id} was never heard within {radius_m} m of {tuple(xy)!r}")
        src.rays = keep
        self._refit(src)
        return len(keep)

    def add_found(self, position, time: float) -> int:
        """Record a source found without having been mapped (e.g. touched): a found source at ``position``."""
        p = np.asarray(position, float).reshape(-1)
        src = _Source(self._next_id, position=np.array([p[0], p[1], p[2] if p.size > 2 else
                                                        self.config.source_height_m]),
                      covariance=np.diag([0.1, 0.1, self.config.source_height_sigma_m]) ** 2,
                      state=SourceState.FOUND, found_time=float(time))
        self._next_id += 1
        self._sources.append(src)
        return src.id

    # -- internals ----------------------------------------------------------------------
    def _get(self, source_id: int) -> _Source:
        sid = self._resolve(source_id)
        for s in self._sources:
            if s.id == sid:
                return s
        raise KeyError(f"source_id: no mapped source {source_id}")

    def _resolve(self, sid: int) -> int:
        while sid in self._merged_into:
            sid = self._merged_into[sid]
        return sid

    def _mahalanobis(self, src: _Source, origin: np.ndarray, d: np.ndarray) -> float:
        cfg = self.config
        v = (src.position - origin)[None]
        if float(np.linalg.norm(v)) < 1e-6:
            return math.inf
        az, el = _angles(v)
        az_m, el_m = _angles(d[None])
        r = np.array([_wrap(az_m - az)[0], (el_m - el)[0]])
        h = _jacobian(v)[0]
        s = h @ src.covariance @ h.T + np.diag([math.radians(cfg.bearing_sigma_deg) ** 2,
                                                 math.radians(cfg.elevation_sigma_deg) ** 2])
        return float(r @ np.linalg.solve(s, r))

    def _along_ray(self, src: _Source, origin: np.ndarray, d: np.ndarray) -> float:
        """Chi-square of the best agreement of ray (``origin``, ``d``) with a source heard from one place only:
        the source lies somewhere along its mean ray between ``min_range_m`` and ``max_range_m`` (its range is
        unknown), so the new ray must point at some point of that segment. The linearised gate of
        ``_mahalanobis`` fails here: its point estimate sits at the height prior's range, often < 1 m out, and
        its range spread reaches the robot itself, from which any bearing fits (a caller's ray heard 0.1 m beside
        a ray toward another caller 62 deg away would be taken, and the two triangulate into a ghost between
        them)."""
        cfg = self.config
        o = np.array([r.origin for r in src.rays]).mean(axis=0)
        u = np.array([r.direction for r in src.rays]).sum(axis=0)
        u /= max(float(np.linalg.norm(u)), 1e-12)
        ranges = np.geomspace(cfg.min_range_m, cfg.max_range_m, 64)
        v = o[None] + ranges[:, None] * u[None] - origin[None]
        az, el = _angles(v)
        az_m, el_m = _angles(d[None])
        inflate = 1.0 + 1.0 / len(src.rays)   # the mean ray's own noise
        chi2 = (_wrap(az - az_m) ** 2 / math.radians(cfg.bearing_sigma_deg) ** 2
                + (el - el_m) ** 2 / math.radians(cfg.elevation_sigma_deg) ** 2) / inflate
        # Heard from a spot on (or beside) that ray, any bearing crosses it right there: no evidence (a mouth that
        # close would be heard steeply, as a source of its own), else two callers' rays heard a few decimetres
        # apart triangulate into a ghost beside the robot. The best agreement itself must lie that far out: the
        # gate (3.7 bearing sigmas, 18 deg) lets a point 0.5 m out pass for a ray that meets the segment 0.3 m
        # out, and the refit would then move the source onto that near crossing.
        best = int(np.argmin(chi2))
        return float(chi2[best]) if math.hypot(v[best, 0], v[best, 1]) >= NEAR_CROSSING_M else math.inf

    def _associate(self, ev: BearingEvidence, origin: np.ndarray, d: np.ndarray, taken: set[int]) -> int | None:
        cfg = self.config
        tracked = self._resolve(self._track_to_source.get(int(ev.track_id), -1)) if ev.track_id is not None else None
        scores = []
        for s in self._sources:
            if s.id in taken:
                continue
            if s.state is SourceState.REJECTED \
                    and _ray_angle(origin[None], d[None], s.position[None])[0, 0] > math.radians(cfg.inlier_deg):
                # Rejected (a reflection, a machine) is a verdict on a place: a bearing that does not point there is
                # another source's, not a reason to move it (measured in a scripted test: a ghost rejected 0.65 m
                # short of a caller took her rays, moved onto her and hid her for the rest of the run).
                continue
            m = self._mahalanobis(s, origin, d) if not s.rays or _crossing_deg(s.rays) >= cfg.min_pair_angle_deg \
                else self._along_ray(s, origin, d)   # (no rays: placed by add_found, a point with its covariance)
            if s.id == tracked and m <= TRACK_GATE_FACTOR * cfg.gate_chi2:
                # The tracker already tied this bearing to the track that fed this source, in the array frame
                # with the robot's motion removed: a second, independent association. The map's gate alone is
                # tight where its covariance is optimistic (a few rays at the nominal bearing sigma, a range from
                # the height prior). Twice the chi-square is the gate of a bearing noise sqrt(2) larger; a true
                # ray falls outside it with probability exp(-gate_chi2) (1e-6 at 13.8), and a track the tracker
                # carried onto another source far off still fails it.
                return s.id
            if m <= cfg.gate_chi2:
                scores.append((m, s.id))
        if not scores:
            return None
        return min(scores)[1]

    def _refit(self, src: _Source) -> None:
        o = np.array([r.origin for r in src.rays])
        d = np.array([r.direction for r in src.rays])
        src.position, src.covariance, src.inliers = triangulate(o, d, self.config, self._rng,
                                                                self._elevation_sigmas(src.rays))

    def _elevation_sigmas(self, rays) -> np.ndarray:
        """Each ray's elevation noise (deg): standing or heard while driving."""
        cfg = self.config
        return np.array([cfg.moving_elevation_sigma_deg if r.moving else cfg.elevation_sigma_deg for r in rays])

    def _merge(self) -> None:
        """Join two sources that one position explains: close horizontally (or within each other's
        uncertainty), and the union of their rays is mostly inliers of one triangulation. A found source
        absorbs anything close to it."""
        cfg = self.config
        changed = True
        while changed:
            changed = False
            for a in self._sources:
                for b in self._sources:
                    if a.id >= b.id or not self._mergeable(a, b):
                        continue
                    keep, drop = (a, b) if (a.state is SourceState.FOUND or b.state is not SourceState.FOUND) \
                        else (b, a)
                    keep.rays = sorted(keep.rays + drop.rays, key=lambda r: r.time)[-cfg.max_rays:]
                    keep.max_level_db = max(keep.max_level_db, drop.max_level_db)
                    if keep.state is not SourceState.FOUND and drop.state is SourceState.APPROACHING:
                        keep.state = SourceState.APPROACHING
                    if keep.rays:
                        self._refit(keep)
                    self._merged_into[drop.id] = keep.id
                    self._sources.remove(drop)
                    changed = True
                    break
                if changed:
                    break

    def _mergeable(self, a: _Source, b: _Source) -> bool:
        cfg = self.config
        dp = a.position - b.position
        close = math.hypot(dp[0], dp[1]) <= cfg.merge_distance_m
        if close and (a.state is SourceState.FOUND or b.state is SourceState.FOUND):
            return True
        if not close and float(dp @ np.linalg.solve(a.covariance + b.covariance, dp)) > 16.3:  # chi2 3 dof 99.9 %
            return False
        if a.state is SourceState.FOUND or b.state is SourceState.FOUND:
            return False
        for r, o in ((a, b), (b, a)):
            if r.state is SourceState.REJECTED:   # a verdict on a place: only what points there joins it
                od = np.array([x.direction for x in o.rays]).reshape(-1, 3)
                oo = np.array([x.origin for x in o.rays]).reshape(-1, 3)
                return bool(len(od)) and bool(np.all(_ray_angle(oo, od, r.position[None])[0]
                                                     <= math.radians(cfg.inlier_deg)))
        rays = a.rays + b.rays
        o = np.array([r.origin for r in rays])
        d = np.array([r.direction for r in rays])
        p, _, inl = triangulate(o, d, cfg, self._rng, self._elevation_sigmas(rays))
        heard_at = {a.id: o[:len(a.rays), :2], b.id: o[len(a.rays):, :2]}
        for one, other in ((a, b), (b, a)):
            # A source heard along one ray joins another only where their rays cross away from where the other was
            # heard, the association's rule (``_along_ray``): a merge must not make the ghost association refused.
            if _crossing_deg(one.rays) < cfg.min_pair_angle_deg \
                    and np.hypot(*(heard_at[other.id] - p[:2]).T).min(initial=math.inf) < NEAR_CROSSING_M:
                return False
        return bool(inl[:len(a.rays)].mean() >= 0.7 and inl[len(a.rays):].mean() >= 0.7)

    def _forget(self) -> None:
        cfg = self.config
        self._sources = [s for s in self._sources if s.state is not SourceState.UNVISITED
                         or len(s.rays) >= 3 or self.time - s.rays[-1].time <= cfg.forget_s]

    def _snapshot(self, s: _Source) -> MapSource:
        cfg = self.config
        inl = [r for r, ok in zip(s.rays, s.inliers) if ok] if len(s.inliers) == len(s.rays) else list(s.rays)
        p = np.clip([r.voice_probability for r in inl], 1e-3, 1 - 1e-3)
        log_odds = float(np.clip(np.sum(np.log(p / (1 - p))), -cfg.max_log_odds, cfg.max_log_odds))
        pv = 1.0 / (1.0 + math.exp(-log_odds))
        if pv >= cfg.victim_probability:
            cls = SourceClass.VICTIM
        elif pv <= cfg.interferer_probability:
            cls = SourceClass.INTERFERER
        else:
            cls = SourceClass.UNKNOWN
        times = [r.time for r in s.rays]
        baseline = _baseline(inl)
        return MapSource(s.id, s.position.copy(), s.covariance.copy(), pv, cls, s.state, len(s.rays), len(inl),
                         min(times, default=s.found_time or 0.0), max(times, default=s.found_time or 0.0),
                         s.rays[-1].level_db if s.rays else -math.inf, s.max_level_db, tuple(s.rays), s.found_time,
                         baseline, _crossing_deg(inl), cfg.min_pair_angle_deg)
