"""Multi-source tracking on the unit sphere: per-window detections in, tracks with stable ids out.

In the spirit of ODAS's SST (Grondin and Michaud 2019, "Lightweight and optimized sound source
localization and tracking methods for open and closed microphone array configurations", Robotics and
Autonomous Systems 113): one Kalman filter per source on the unit sphere, detections explained as a
tracked source, a new source or a false detection, tentative tracks confirmed after consistent
windows, and tracks deleted after a silence. All vectors are in the **array frame** of the latest
window; angles inside are rad, times s.

Model (:class:`SphereKalman`), per track, state ``x = [u, v]``: direction ``u`` (unit vector) and its
rate ``v = du/dt`` (1/s, tangent to the sphere at ``u``). The velocity is driven by white acceleration
of spectral density ``sigma_a^2`` (``acceleration_sigma_deg``, rad/s^2) and decays with time constant
``tau`` (``speed_memory_s``; tau -> inf is ODAS's constant-velocity model):

    predict  x <- F x,  P <- F P F^T + Q,   F = [[I, tau (1 - a) I], [0, a I]],  a = exp(-dt / tau),
             Q = sigma_a^2 [[dt^4/4 I, dt^3/2 I], [dt^3/2 I, dt^2 I]]
    then     u <- u / |u|,  v <- T v,   T = I - u u^T
    and after each update also  P <- B P B^T,  B = diag(T, T)

This keeps the state on the sphere (ODAS renormalises and projects the velocity the same way; projecting
``P`` too removes the radial variance a unit vector cannot have). A detection ``z`` is
measured in the tangent plane at ``u`` through the sphere's log map, ``r = E^T (z - (u.z) u) theta /
sin(theta)`` (``E`` a 3x2 orthonormal tangent basis, ``theta`` the angle between ``u`` and ``z``), with
``H = [E^T, 0]`` and ``R = sigma_r^2 I_2``; ``sigma_r`` comes from the detection's SRP power
(:meth:`TrackerConfig.sigma_of_power`). The update is ODAS's probability-weighted one:

    S = H P H^T + R,  K = P H^T S^-1,  x <- x + w K r,  P <- P - w K H P

with ``w`` the posterior probability that the detection belongs to the track.

Association, as ODAS's: a detection ``j`` of SRP power ``E_j`` is a tracked source ``i``, a new
source or a false detection, with likelihoods

    l_ij = P_track p(E_j | active) N(r_ij; 0, S_ij),   l_new = P_new p(E_j | active) / 4 pi,
    l_false = P_false p(E_j | inactive) / 4 pi

(directions per steradian, new and false sources uniform on the sphere; ``p(E | .)`` log-normal,
:meth:`TrackerConfig.power_likelihoods`). The joint assignment maximising the product of likelihoods
(each track and detection used at most once; "new or false" always available) is a linear assignment
(``scipy.optimize.linear_sum_assignment``); a pair is only chosen if ``l_ij > l_new + l_false``, which
is the gate: about 11 deg around a settled track for strong detections, up to ~30 deg for weak ones.
``w_ij = l_ij / (sum_k l_kj + l_new + l_false)``. An unassigned detection that is a new source with
posterior ``theta_new`` or more starts a tentative track.

Lifecycle: a tentative track is confirmed (and gets the next id, never reused) after
``confirm_hits`` associated detections within its first ``confirm_windows`` windows, and dropped
otherwise; a confirmed track coasts (predicted, not updated) through pauses and is deleted once no
detection was associated for ``silence_s``.

False-alarm design: a false detection starts a tentative track only if its power makes it a new
source with probability ``theta_new`` (power >= 0.064 for the defaults; false peaks are mostly
weaker), and that track is confirmed only if ``confirm_hits - 1`` more fall into its gate (a cap of
solid angle ``Omega`` ~ 0.12 sr for strong detections) within ``confirm_windows - 1`` windows. For
strong false detections uniform on the sphere at ``r`` per window that happens at about
``r C(7, 2) (r Omega / 4 pi)^2`` per window: at ``r = 0.1`` (ten times the 1 % of windows the
localizer's gate is meant to let through) 1.8e-6, one false track per ~15 h of audio. Measured
(tests/test_tracking.py): none in 10 min at that rate, none in 10 min of false peaks with the measured
false-peak powers in half the windows; at one such false peak in every window, 3 per 10 min.

Activity: a two-state (sounding / silent) Bayes filter per track. Between windows the state switches
with the rates of conversational talk spurts and pauses (``talk_s``, ``pause_s``); a window is
"hit" with probability ``w`` (the association posterior), and hits are seen with probability
``detect_probability`` when sounding and ``false_hit_probability`` when silent.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

from ssl_core.grid import azimuth_elevation
from ssl_core.detection import DegreesMixin, Detection

_FOUR_PI = 4.0 * np.pi

# The per-window gate (LocalizerConfig.min_significance) for detections that feed a Tracker. Looser
# than the localizer's standalone 7 (about 0.3 % false windows): the tracker's confirmation is the
# false-alarm control. Measured: one talker at 1.5 m, RT60 0.5 s, SNR 5 dB (tests/test_tracking.py, six
# directions) tracked within 10 deg in 35 of 36 active seconds at 5, 29 at 7 (confirmation comes later);
# 3 x 60 s of diffuse hvac/pink/white noise at 5: false detections in 5-10 % of windows, no confirmed track.
TRACKING_MIN_SIGNIFICANCE = 5.0


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker parameters. Angles in degrees (user-facing), times in s, probabilities in [0, 1]."""

    # Detection direction error (deg, 1 sigma per tangent axis) against SRP power, interpolated in log
    # power: (power, sigma) pairs. Measured with ssl_core.localizer (default windows, min_power 0) on one
    # talker at 1.5 m, RT60 0.5 s, SNR 20 and 5 dB, six directions (errors over 25 deg left to the
    # false-detection model): 1.7 deg at power 0.1-0.2, 3.3 at 0.08-0.1, 6.1 at 0.06-0.08, 7.1-7.7 below.
    measurement_sigma: tuple[tuple[float, float], ...] = ((0.05, 7.5), (0.07, 6.1), (0.09, 3.3), (0.115, 1.7))
    # Motion: velocity with white acceleration (sigma_a) that decays with time constant speed_memory_s
    # (an integrated Ornstein-Uhlenbeck velocity), so a paused talker's noisy velocity estimate stops
    # extrapolating. Chosen by a sweep (tests/test_tracking.py scenarios): sigma_a 10 deg/s^2 and 3 s
    # follow a talker walking 30 deg/s within 9 deg and let a static talker's track drift ~8 deg at most
    # through a 1.5 s pause; 20 deg/s^2 drifts 10 deg, 10 deg/s^2 with a 2 s memory lags the walker by 11 deg.
    acceleration_sigma_deg: float = 10.0      # deg/s^2
    speed_memory_s: float = 3.0               # s
    # A new track starts nearly at rest, as in ODAS (its velocity prior is sigmaQ^2 = 1e-6): velocities
    # fitted to a few noisy detections otherwise carry a sparse talker's track away (measured with the
    # localizer's significance gate, SNR 5 dB: 10 deg/s tracked 26 of 36 active seconds,
    # 5 deg/s 29); a walker is picked up through sigma_a.
    initial_speed_sigma_deg: float = 5.0      # deg/s
    # Hypothesis priors: ODAS defaults (config/odaslive/*.cfg, sst: Ptrack, Pnew, Pfalse).
    p_track: float = 0.8
    p_new: float = 0.1
    p_false: float = 0.1
    theta_new: float = 0.9                    # ODAS theta_new: P(new source) needed to start a track
    # Power of a detection given a sounding source (active) or none (inactive): log-normal, as ODAS's
    # active/inactive Gaussians on its power. Measured on ssl_core.localizer's default windows (128 ms,
    # 300-6000 Hz, min_power 0), one talker at 1.5 m, RT60 0.5 s: detections within 10 deg of the talker
    # have median power 0.11 (SNR 20 dB) and 0.058 (SNR 5 dB), those over 20 deg off (reflections, noise
    # in pauses) 0.022 (5-95 %: 0.012-0.055, i.e. +-0.2 decades). active_power sits between the two
    # talker medians, nearer the weak one the tracker must not lose.
    active_power: float = 0.07
    inactive_power: float = 0.022
    power_spread_decades: float = 0.22
    # Birth: 3 hits in the first 8 windows (1 s of 128 ms windows). ODAS asks N_prob = 5 frames of 8 ms
    # with mean P(tracked) >= 0.8. Speech reaches the localizer in syllable bursts of 1-3 windows with
    # gaps of 3-8 (measured at SNR 5 dB with the significance gate): 3-of-5 confirmed such
    # talkers seconds late (19 of 36 active seconds tracked; 3-of-8: 26, and 29 with the slow start
    # below). 3-of-8 keeps strong false detections in 10 % of windows to ~1 false track per 15 h
    # (module docstring).
    confirm_hits: int = 3
    confirm_windows: int = 8
    # Death after 4 s without a detection. ODAS uses up to 2 s (N_inactive = 250 frames of 8 ms) for
    # conversation; victims call with longer gaps: on 30 s of ssl_sim victim_voice calls (one per 2.5 s
    # period, 90 % of periods) at 2 m, RT60 0.5 s, SNR 20 / 5 dB (three seeds each), 2 s gave 2-5 ids per
    # victim, 4 s one id in 4 of the 6 runs and 2-3 in the others (measured).
    silence_s: float = 4.0
    # Activity filter. Mean talk spurt 1.0 s and pause 1.6 s of conversational speech: ITU-T P.59
    # (artificial conversational speech; 1.004 s and 1.587 s). Hit rates: the localizer
    # detects an active talker in ~90 % of 128 ms windows at SNR 20 dB, fewer in noise; a
    # silent source's gate (~0.1 sr, 1 % of the sphere) catches a false peak in at most a few % of windows.
    talk_s: float = 1.0
    pause_s: float = 1.6
    detect_probability: float = 0.8
    false_hit_probability: float = 0.05
    # History kept per track: a dozen call-and-pause cycles of a victim (ssl_sim victim_voice calls every
    # 2.5 s), with memory bounded on a long run.
    history_s: float = 30.0

    def __post_init__(self) -> None:
        def need(ok: bool, name: str, expected: str) -> None:
            if not ok:
                raise ValueError(f"TrackerConfig.{name}={getattr(self, name)!r}: expected {expected}")

        table = np.asarray(self.measurement_sigma, float)
        need(table.ndim == 2 and table.shape[1] == 2 and len(table) >= 1 and np.all(table > 0)
             and np.all(np.diff(table[:, 0]) > 0), "measurement_sigma",
             "(power, sigma_deg) pairs with positive values and increasing power")
        for name in ("speed_memory_s", "acceleration_sigma_deg", "initial_speed_sigma_deg", "active_power",
                     "inactive_power", "power_spread_decades", "talk_s", "pause_s", "silence_s", "history_s"):
            need(np.isfinite(getattr(self, name)) and getattr(self, name) > 0, name, "a finite number > 0")
        for name in ("p_track", "p_new", "p_false"):
            need(0 < getattr(self, name) < 1, name, "a probability in (0, 1)")
        need(0 <= self.theta_new < 1, "theta_new", "a probability in [0, 1)")
        need(self.active_power > self.inactive_power, "active_power", f"> inactive_power ({self.inactive_power})")
        need(0 < self.false_hit_probability < self.detect_probability < 1, "detect_probability",
             f"a probability in (false_hit_probability={self.false_hit_probability}, 1)")
        need(isinstance(self.confirm_hits, (int, np.integer)) and self.confirm_hits >= 1, "confirm_hits",
             "an integer >= 1")
        need(isinstance(self.confirm_windows, (int, np.integer)) and self.confirm_windows >= self.confirm_hits,
             "confirm_windows", f"an integer >= confirm_hits ({self.confirm_hits})")

    def power_likelihoods(self, power: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Densities of SRP ``power`` given an active and an inactive source (per decade of power)."""
        x = np.log10(np.maximum(np.asarray(power, float), 1e-9))
        s = self.power_spread_decades

        def density(mean: float) -> np.ndarray:
            return np.exp(-0.5 * ((x - np.log10(mean)) / s) ** 2) / (np.sqrt(2 * np.pi) * s)

        return density(self.active_power), density(self.inactive_power)

    def sigma_of_power(self, power: np.ndarray) -> np.ndarray:
        """Direction error (rad, 1 sigma per tangent axis) of detections with SRP ``power``: the
        ``measurement_sigma`` table interpolated in log power, held constant beyond its ends."""
        table = np.asarray(self.measurement_sigma, float)
        x = np.log(np.maximum(np.asarray(power, float), 1e-9))
        return np.deg2rad(np.interp(x, np.log(table[:, 0]), table[:, 1]))


@dataclass(frozen=True)
class Track(DegreesMixin):
    """One tracked source, in the ARRAY frame at the time of the last update (see module docstring)."""

    id: int                        # stable, unique per Tracker, never reused
    direction: np.ndarray          # (3,) unit vector, array frame
    velocity: np.ndarray           # (3,) d(direction)/dt (1/s), array frame, tangent to the sphere
    activity: float                # probability (0..1) that the source is sounding now
    power: float                   # SRP power of the last associated detection
    level_db: float                # beam level of the last associated detection (dB re full-scale sine)
    first_time: float              # s, stream time the track was born
    last_time: float               # s, stream time of the last associated detection
    n_updates: int                 # detections associated so far

    @property
    def azimuth(self) -> float:
        """rad, CCW from the array's +x, in (-pi, pi]."""
        return float(azimuth_elevation(self.direction)[0])

    @property
    def elevation(self) -> float:
        """rad, up from the array's x-y plane."""
        return float(azimuth_elevation(self.direction)[1])


@dataclass(frozen=True)
class TrackHistory:
    """Associated detections of one track (oldest first, at most ``history_s`` back)."""

    times: np.ndarray              # (n,) s, stream time of each window
    power: np.ndarray              # (n,) SRP power
    level_db: np.ndarray           # (n,) beam level (dB re full-scale sine)


def _tangent_basis(u: np.ndarray) -> np.ndarray:
    """Orthonormal bases (n, 3, 2) of the planes tangent to unit vectors ``u`` (n, 3): ``e1 = a x u``
    normalised, with ``a = +z`` (``+x`` near the poles), and ``e2 = u x e1``."""
    x, y, z = u.T
    polar = np.abs(z) >= 0.9
    E = np.empty((len(u), 3, 2))
    e1, e2 = E[:, :, 0], E[:, :, 1]
    e1[:, 0], e1[:, 1], e1[:, 2] = np.where(polar, 0.0, -y), np.where(polar, -z, x), np.where(polar, y, 0.0)
    e1 /= np.sqrt((e1 * e1).sum(axis=1))[:, None]
    e2[:, 0] = y * e1[:, 2] - z * e1[:, 1]
    e2[:, 1] = z * e1[:, 0] - x * e1[:, 2]
    e2[:, 2] = x * e1[:, 1] - y * e1[:, 0]
    return E


class SphereKalman:
    """Kalman filter on the unit sphere with a decaying velocity, batched over tracks (see the module
    docstring; ``Q`` is the white-acceleration one, exact for ``dt << speed_memory_s``).

    States are ``x`` (n, 6) = [direction, velocity] and ``P`` (n, 6, 6); methods return new arrays.
    """

    def __init__(self, config: TrackerConfig):
        self.config = config
        self.sigma_a = np.deg2rad(config.acceleration_sigma_deg)
        self.sigma_v0 = np.deg2rad(config.initial_speed_sigma_deg)
        self.tau = config.speed_memory_s
        self._cached_dt: float | None = None

    def initial(self, z: np.ndarray, sigma_r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """States of new tracks at detections ``z`` (m, 3) with direction errors ``sigma_r`` (m,) rad."""
        m = len(z)
        var = np.concatenate([np.repeat(sigma_r[:, None] ** 2, 3, 1), np.full((m, 3), self.sigma_v0**2)], axis=1)
        return self._on_sphere(np.concatenate([z, np.zeros((m, 3))], axis=1),
                               np.einsum("ni,ij->nij", var, np.eye(6)))

    @staticmethod
    def rotate(x: np.ndarray, P: np.ndarray, rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Express states in a rotated frame: ``u, v <- R u, R v``, ``P <- B P B^T`` with ``B = diag(R, R)``."""
        B = np.kron(np.eye(2), rotation)
        return x @ B.T, B @ P @ B.T

    def predict(self, x: np.ndarray, P: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """``dt`` s ahead. ``P`` keeps a small radial part here: only its tangent part is ever read
        (``innovations``), and ``update`` / ``initial`` project it."""
        F, Q = self._transition(dt)
        return self._unit(x @ F.T), F @ P @ F.T + Q

    def _transition(self, dt: float) -> tuple[np.ndarray, np.ndarray]:
        """F and Q for a step of ``dt`` s (cached: windows have a constant length)."""
        dt = round(dt, 9)  # window times are sums of floats: k * 0.128 - (k - 1) * 0.128 varies in the last bits
        if self._cached_dt != dt:
            decay = np.exp(-dt / self.tau)
            F = np.kron([[1.0, self.tau * (1 - decay)], [0.0, decay]], np.eye(3))
            Q = self.sigma_a**2 * np.kron([[dt**4 / 4, dt**3 / 2], [dt**3 / 2, dt**2]], np.eye(3))
            self._cached_dt, self._cached_FQ = dt, (F, Q)
        return self._cached_FQ

    def innovations(self, x: np.ndarray, P: np.ndarray, z: np.ndarray, sigma_r: np.ndarray):
        """Log-map residuals ``r`` (n, m, 2), their covariances ``S`` (n, m, 2, 2) and the tangent bases
        ``E`` (n, 3, 2) of detections ``z`` (m, 3) against tracks ``x``."""
        u = x[:, :3]
        E = _tangent_basis(u)
        c = np.clip(z @ u.T, -1.0, 1.0).T                     # (n, m) cos of the angle
        t = z[None] - c[..., None] * u[:, None]               # (n, m, 3) tangent components
        s = np.sqrt((t * t).sum(axis=-1))
        scale = np.where(s > 1e-12, np.arctan2(s, c) / np.maximum(s, 1e-12), 1.0)
        r = (t @ E) * scale[..., None]
        HPH = E.transpose(0, 2, 1) @ P[:, :3, :3] @ E
        S = HPH[:, None] + (sigma_r**2)[None, :, None, None] * np.eye(2)
        return r, S, E

    @staticmethod
    def likelihood(r: np.ndarray, S: np.ndarray) -> np.ndarray:
        """Gaussian density (per steradian, tangent-plane approximation) of residuals ``r`` (..., 2)."""
        a, b, c = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
        det = a * c - b * b
        d2 = (c * r[..., 0] ** 2 - 2 * b * r[..., 0] * r[..., 1] + a * r[..., 1] ** 2) / det
        return np.exp(-0.5 * d2) / (2 * np.pi * np.sqrt(det))

    def update(self, x, P, r, S, E, w) -> tuple[np.ndarray, np.ndarray]:
        """Probability-weighted update of tracks ``x`` by residuals ``r`` (n, 2), ``S`` (n, 2, 2), ``E``
        (n, 3, 2) with weights ``w`` (n,)."""
        PHt = P[:, :, :3] @ E                                  # (n, 6, 2)
        a, b, c = S[:, 0, 0], S[:, 0, 1], S[:, 1, 1]
        S_inv = np.stack([c, -b, -b, a], axis=1).reshape(-1, 2, 2) / (a * c - b * b)[:, None, None]
        K = PHt @ S_inv
        x = x + w[:, None] * (K @ r[:, :, None])[:, :, 0]
        P = P - w[:, None, None] * K @ PHt.transpose(0, 2, 1)
        return self._on_sphere(x, 0.5 * (P + P.transpose(0, 2, 1)))

    @staticmethod
    def _unit(x: np.ndarray) -> np.ndarray:
        """States with unit ``u`` and ``v`` tangent at it."""
        u = x[:, :3] / np.sqrt((x[:, :3] ** 2).sum(axis=1))[:, None]
        return np.concatenate([u, x[:, 3:] - np.sum(u * x[:, 3:], axis=1, keepdims=True) * u], axis=1)

    @classmethod
    def _on_sphere(cls, x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``_unit`` states and ``P`` projected on the tangent planes (module docstring)."""
        x = cls._unit(x)
        u = x[:, :3]
        B = np.zeros(P.shape)
        B[:, :3, :3] = B[:, 3:, 3:] = np.eye(3) - u[:, :, None] * u[:, None, :]
        return x, B @ P @ B.transpose(0, 2, 1)


@dataclass
class _Tracks:
    """All live tracks (tentative and confirmed) as parallel arrays; ``id`` 0 = tentative."""

    x: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    P: np.ndarray = field(default_factory=lambda: np.zeros((0, 6, 6)))
    id: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    key: np.ndarray = field(default_factory=lambda: np.zeros(0, int))   # internal serial (history key)
    activity: np.ndarray = field(default_factory=lambda: np.zeros(0))
    power: np.ndarray = field(default_factory=lambda: np.zeros(0))
    level_db: np.ndarray = field(default_factory=lambda: np.zeros(0))
    first_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    last_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    n_updates: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    windows: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # windows seen since birth
    range_m: np.ndarray = field(default_factory=lambda: np.zeros(0))  # assumed source range (translation)

    def __len__(self) -> int:
        return len(self.id)

    def select(self, keep: np.ndarray) -> _Tracks:
        return _Tracks(**{k: v[keep] for k, v in vars(self).items()})

    def extend(self, other: _Tracks) -> _Tracks:
        return _Tracks(**{k: np.concatenate([v, getattr(other, k)]) for k, v in vars(self).items()})

    def track(self, i: int) -> Track:
        return Track(int(self.id[i]), self.x[i, :3].copy(), self.x[i, 3:].copy(), float(self.activity[i]),
                     float(self.power[i]), float(self.level_db[i]), float(self.first_time[i]),
                     float(self.last_time[i]), int(self.n_updates[i]))


class Tracker:
    """Multi-source tracker over per-window detections; see the module docstring for the model."""

    def __init__(self, config: TrackerConfig = TrackerConfig()):
        self.config = config
        self.model = SphereKalman(config)
        self._next_id = 1
        self.reset()

    def reset(self) -> None:
        """Forget every track (ids keep counting up: an id is never reused)."""
        self._tracks = _Tracks()
        self._time: float | None = None
        self._history: dict[int, list[tuple[float, float, float]]] = {}
        self._next_key = 0
        self._det_keys = np.zeros(0, int)

    def update(self, detections: Sequence[Detection], time: float,
               rotation: np.ndarray | None = None, translation: np.ndarray | None = None,
               source_range: float = 2.0) -> list[Track]:
        """Advance to window time ``time`` (s) with this window's ``detections``. Pass every window, also
        those without detections: tracks coast and age by the stream time.

        ``rotation``: 3x3 R mapping the PREVIOUS array frame's vectors into the CURRENT array frame
        (``v_now = R @ v_prev``), e.g. from an odometry/IMU yaw change ``dpsi``: ``R = Rz(-dpsi)``.
        ``translation``: the array centre's displacement (m) since the previous window, in the CURRENT
        array frame; each track's source, at its range (``source_range`` m when the track was born, then
        carried along by the geometry), is then seen from the new centre: ``u <- (r u - t) / |r u - t|``,
        its covariance through that map's Jacobian. Without it (None) a moving array's tracks lag by the
        parallax ``|t| sin(angle) / r`` per window. Returns the confirmed tracks, by id.
        """
        z, power, level = self._measurements(detections)
        R = None if rotation is None else self._check_rotation(rotation)
        t = None if translation is None else self._check_translation(translation)
        if not (np.isfinite(source_range) and source_range > 0):
            raise ValueError(f"source_range={source_range!r}: expected a finite range > 0 m")
        dt = self._advance(time)
        sigma_r = self.config.sigma_of_power(power)
        self._predict(dt, R)
        if t is not None:
            self._translate(t)
        pairs, w, new, innovations = self._associate(z, sigma_r, power)
        # which track (internal key) each detection updated or started: read back by ``detection_ids``
        det_keys = np.full(len(z), -1)
        det_keys[pairs[:, 1]] = self._tracks.key[pairs[:, 0]]
        det_keys[np.flatnonzero(new)] = self._next_key + np.arange(int(np.count_nonzero(new)))
        self._correct(pairs, w, innovations, power, level, time)
        self._update_activity(pairs, w, dt)
        self._delete(time)
        self._initiate(z[new], sigma_r[new], power[new], level[new], time, float(source_range))
        self._confirm()
        self._det_keys = det_keys
        return self.tracks()

    def detection_ids(self) -> list[int | None]:
        """Per detection of the last ``update`` (in its order): the id of the confirmed track it updated or
        started, or None (a false detection, or a track still tentative or dropped in that update)."""
        tr = self._tracks
        ids = dict(zip(tr.key.tolist(), tr.id.tolist()))
        return [ids.get(int(k)) or None for k in self._det_keys]

    def tracks(self) -> list[Track]:
        """The confirmed tracks after the last update, by id."""
        tr = self._tracks
        return [tr.track(i) for i in np.flatnonzero(tr.id > 0)]

    def history(self, track_id: int) -> TrackHistory:
        """Power and level of the detections associated with a live confirmed track."""
        hit = np.flatnonzero(self._tracks.id == track_id)
        if not hit.size:
            raise KeyError(f"track_id={track_id}: no live confirmed track has this id")
        h = np.array(self._history[int(self._tracks.key[hit[0]])]).reshape(-1, 3)
        return TrackHistory(h[:, 0].copy(), h[:, 1].copy(), h[:, 2].copy())

    # ------------------------------------------------------------------ steps
    def _advance(self, time: float) -> float:
        if not np.isfinite(time) or (self._time is not None and time < self._time):
            raise ValueError(f"time={time!r}: expected a finite stream time (s) >= the last one ({self._time})")
        dt = 0.0 if self._time is None else float(time) - self._time
        self._time = float(time)
        return dt

    @staticmethod
    def _measurements(detections: Sequence[Detection]):
        if not detections:
            return np.zeros((0, 3)), np.zeros(0), np.zeros(0)
        z = np.array([d.direction for d in detections], dtype=float).reshape(len(detections), 3)
        norm = np.linalg.norm(z, axis=1)
        if not np.all(np.abs(norm - 1) < 1e-3):
            raise ValueError(f"detections[{int(np.argmax(np.abs(norm - 1)))}].direction: expected a unit vector")
        return (z / norm[:, None], np.array([d.power for d in detections], float),
                np.array([d.level_db for d in detections], float))

    @staticmethod
    def _check_rotation(rotation) -> np.ndarray:
        R = np.asarray(rotation, dtype=float)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-5) or np.linalg.det(R) < 0:
            raise ValueError(f"rotation: expected a 3x3 rotation matrix (orthonormal, det +1), got {R.tolist()}")
        return R

    @staticmethod
    def _check_translation(translation) -> np.ndarray:
        t = np.asarray(translation, dtype=float)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise ValueError(f"translation: expected a finite 3-vector (m, array frame), got {translation!r}")
        return t

    def _translate(self, t: np.ndarray) -> None:
        """Re-aim every track from an array centre moved by ``t`` (m, current array frame): see ``update``."""
        tr = self._tracks
        if not len(tr) or not np.any(t):
            return
        u, r = tr.x[:, :3], tr.range_m
        p = r[:, None] * u - t[None]
        d = np.maximum(np.linalg.norm(p, axis=1), 0.05)  # a source cannot be inside the array
        u2 = p / d[:, None]
        T = np.eye(3) - u2[:, :, None] * u2[:, None, :]
        B = np.zeros((len(tr), 6, 6))
        B[:, :3, :3] = T * (r / d)[:, None, None]  # d(u2)/d(u) for a source at range r
        B[:, 3:, 3:] = T
        x = np.concatenate([u2, tr.x[:, 3:]], axis=1)
        tr.x, tr.P = self.model._on_sphere(x, B @ tr.P @ B.transpose(0, 2, 1))
        tr.range_m = d

    def _predict(self, dt: float, rotation: np.ndarray | None) -> None:
        """Move every track into the current array frame (``rotation``), then ``dt`` s forward."""
        tr = self._tracks
        if rotation is not None:
            tr.x, tr.P = self.model.rotate(tr.x, tr.P, rotation)
        tr.x, tr.P = self.model.predict(tr.x, tr.P, dt)
        tr.windows += 1

    def _associate(self, z: np.ndarray, sigma_r: np.ndarray, power: np.ndarray):
        """Best joint assignment; returns (track, detection) index pairs, their posteriors ``w``, a mask
        of detections that are a new source with probability ``theta_new``, and the innovations."""
        cfg, tr, m = self.config, self._tracks, len(z)
        e_on, e_off = cfg.power_likelihoods(power)
        l_new, l_false = cfg.p_new * e_on / _FOUR_PI, cfg.p_false * e_off / _FOUR_PI
        if not len(tr) or not m:
            return np.zeros((0, 2), int), np.zeros(0), l_new / (l_new + l_false) >= cfg.theta_new, None
        innovations = r, S, _ = self.model.innovations(tr.x, tr.P, z, sigma_r)
        lik = cfg.p_track * e_on * self.model.likelihood(r, S)   # (n, m)
        # detections x (tracks + one "new or false" column per detection); tiny likelihoods never win
        cost = np.full((m, len(tr) + m), 1e9)
        cost[:, : len(tr)] = -np.log(np.maximum(lik.T, 1e-300))
        cost[np.arange(m), len(tr) + np.arange(m)] = -np.log(np.maximum(l_new + l_false, 1e-300))
        det, col = linear_sum_assignment(cost)
        assigned = col < len(tr)
        pairs = np.stack([col[assigned], det[assigned]], axis=1)
        total = lik.sum(axis=0) + l_new + l_false
        w = lik[pairs[:, 0], pairs[:, 1]] / total[pairs[:, 1]]
        new = l_new / total >= cfg.theta_new
        new[pairs[:, 1]] = False
        return pairs, w, new, innovations

    def _correct(self, pairs, w, innovations, power, level, time: float) -> None:
        """Kalman-update the associated tracks and record their detections' power and level."""
        if not len(pairs):
            return
        tr, (i, j) = self._tracks, pairs.T
        r, S, E = innovations
        tr.x[i], tr.P[i] = self.model.update(tr.x[i], tr.P[i], r[i, j], S[i, j], E[i], w)
        tr.power[i], tr.level_db[i], tr.last_time[i] = power[j], level[j], time
        tr.n_updates[i] += 1
        for k, p, lv in zip(tr.key[i], power[j], level[j]):
            h = self._history[int(k)]
            h.append((time, float(p), float(lv)))
            while h[0][0] < time - self.config.history_s:
                h.pop(0)

    def _update_activity(self, pairs, w, dt: float) -> None:
        """Two-state Bayes filter (see module docstring); ``w`` = P(this window hit the track)."""
        cfg, tr = self.config, self._tracks
        hit = np.zeros(len(tr))
        hit[pairs[:, 0]] = w
        p_stop, p_start = 1 - np.exp(-dt / cfg.talk_s), 1 - np.exp(-dt / cfg.pause_s)
        prior = tr.activity * (1 - p_stop) + (1 - tr.activity) * p_start
        pd, pf = cfg.detect_probability, cfg.false_hit_probability
        l_on, l_off = hit * pd + (1 - hit) * (1 - pd), hit * pf + (1 - hit) * (1 - pf)
        tr.activity = l_on * prior / (l_on * prior + l_off * (1 - prior))

    def _hit_activity(self) -> float:
        """Activity after a first hit from an even prior."""
        pd, pf = self.config.detect_probability, self.config.false_hit_probability
        return pd / (pd + pf)

    def _delete(self, time: float) -> None:
        """Drop tentative tracks that missed their confirmation and tracks silent for ``silence_s``."""
        cfg, tr = self.config, self._tracks
        failed = (tr.id == 0) & (tr.windows >= cfg.confirm_windows) & (tr.n_updates < cfg.confirm_hits)
        gone = failed | (time - tr.last_time > cfg.silence_s)
        if gone.any():
            for k in tr.key[gone]:
                del self._history[int(k)]
            self._tracks = tr.select(~gone)

    def _initiate(self, z, sigma_r, power, level, time: float, source_range: float = 2.0) -> None:
        """Start a tentative track (no id yet) at each new-source detection."""
        m = len(z)
        if not m:
            return
        x, P = self.model.initial(z, sigma_r)
        keys = np.arange(self._next_key, self._next_key + m)
        self._next_key += m
        for k, p, lv in zip(keys, power, level):
            self._history[int(k)] = [(time, float(p), float(lv))]
        self._tracks = self._tracks.extend(_Tracks(
            x, P, np.zeros(m, int), keys, np.full(m, self._hit_activity()), power, level,
            np.full(m, time), np.full(m, time), np.ones(m, int), np.ones(m, int), np.full(m, source_range)))

    def _confirm(self) -> None:
        """Give tentative tracks with ``confirm_hits`` detections the next ids."""
        tr = self._tracks
        new = np.flatnonzero((tr.id == 0) & (tr.n_updates >= self.config.confirm_hits))
        tr.id[new] = np.arange(self._next_id, self._next_id + len(new))
        self._next_id += len(new)
