"""Shared set-up of the paper's experiments: the simulated lab, trials, scoring, output files.

The lab (our assumption; the paper does not describe its room): 7 x 6 x 3.5 m, surfaces of
uniform absorption giving an Eyring RT60 of 0.5 s (a furnished lab), diffuse HVAC-like
background noise of 35 dB SPL at the array, the sensor model of ``ssl_sim.acoustics.sensor``
(16 kHz, 16 bit, -26 dBFS/Pa, 32 dB SPL self-noise, 0.5 dB gain mismatch), and the
paper's 62.5 dB SPL (at 1 m) source playing continuous synthetic calls for help.

The array stands at a fixed place with its axes along the room's (robot yaw 0); its height
is chosen per experiment so that every source position of that experiment fits between the
floor and the ceiling (the paper's el = -45 deg at 3 m and el = -90 deg at 1.5 m put the
source below the array: we raise the array on a stand, as in a lab set-up, and say so).
"""
from __future__ import annotations

import argparse

import csv
import time
from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import numpy as np  # noqa: E402
from scipy.optimize import linear_sum_assignment  # noqa: E402

from ssl_core.grid import angular_distance, direction_from_angles  # noqa: E402
from ssl_core.localizer import Localizer, LocalizerConfig  # noqa: E402
from ssl_sim.acoustics import (AcousticConfig, AcousticSimulator, AmbientNoise, ArrayMount,  # noqa: E402
                               RobotPose, SoundSource, continuous_voice, point_at)
from ssl_sim.world import Room, World  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"           # the committed full results
QUICK_RESULTS = Path(__file__).resolve().parent / "out" / "quick"  # scratch (git-ignored) for --quick runs
SPEAKERS = ("male", "female", "male_low", "female_high", "child", "male_high", "female_low", "elderly_male")


@dataclass(frozen=True)
class Lab:
    """A simulated lab set-up (world frame m, s, dB SPL)."""

    room_size: tuple[float, float, float] = (7.0, 6.0, 3.5)
    rt60_s: float = 0.5
    noise_db_spl: float = 35.0
    noise_spectrum: str = "hvac"
    array_xy: tuple[float, float] = (3.3, 2.8)
    array_height_m: float = 1.7
    level_db_spl: float = 62.5
    duration_s: float = 2.0
    ism_order: int = 3
    build_error_m: float = 0.002

    @property
    def pose(self) -> RobotPose:
        return RobotPose(self.array_xy[0], self.array_xy[1], 0.0, yaw=0.0)

    @property
    def mount(self) -> ArrayMount:
        return ArrayMount(height_m=self.array_height_m, build_error_m=self.build_error_m, build_seed=0)

    @property
    def centre(self) -> np.ndarray:
        return self.mount.centre_world(self.pose)

    def describe(self) -> str:
        return (f"room {self.room_size[0]:g} x {self.room_size[1]:g} x {self.room_size[2]:g} m, Eyring RT60 "
                f"{self.rt60_s:g} s, diffuse {self.noise_spectrum} noise {self.noise_db_spl:g} dB SPL, array centre at "
                f"({self.centre[0]:.1f}, {self.centre[1]:.1f}, {self.centre[2]:.2f}) m, source {self.level_db_spl:g} dB SPL "
                f"at 1 m, {self.duration_s:g} s per trial, capsules off their nominal places by "
                f"{self.build_error_m * 1e3:g} mm rms per axis (one fixed as-built array)")


@dataclass(frozen=True)
class Truth:
    """A source placed relative to the array: angles in degrees (array frame), distance in m."""

    azimuth_deg: float
    elevation_deg: float
    distance_m: float
    level_db_spl: float | None = None

    @property
    def direction(self) -> np.ndarray:
        return direction_from_angles(np.deg2rad(self.azimuth_deg), np.deg2rad(self.elevation_deg))


def build_sim(lab: Lab, truths: list[Truth], seed: int, noise_db_spl: float | None = None,
              rt60_s: float | None = None, ambient: bool = True) -> AcousticSimulator:
    """The simulator of one trial: the sources of ``truths`` (each a different seeded voice) in the lab."""
    world = World(room=Room(lab.room_size), name="lab")
    centre = lab.centre
    sources = []
    for k, t in enumerate(truths):
        pos = point_at(centre, np.deg2rad(t.azimuth_deg), np.deg2rad(t.elevation_deg), t.distance_m)
        voice = continuous_voice(SPEAKERS[(seed + k) % len(SPEAKERS)], seed=1000 * seed + k, stream=k)
        sources.append(SoundSource(tuple(pos), voice, t.level_db_spl or lab.level_db_spl, name=f"src{k}"))
    level = lab.noise_db_spl if noise_db_spl is None else noise_db_spl
    cfg = AcousticConfig(rt60_s=lab.rt60_s if rt60_s is None else rt60_s, ism_order=lab.ism_order, seed=seed,
                         ambient=AmbientNoise(level, lab.noise_spectrum) if ambient else None)
    return AcousticSimulator(world, cfg, sources)


def record(lab: Lab, truths: list[Truth], seed: int, noise_db_spl: float | None = None,
           rt60_s: float | None = None) -> np.ndarray:
    """Simulate one trial: what the array hears (int16 (8, n)) during ``lab.duration_s``."""
    sim = build_sim(lab, truths, seed, noise_db_spl, rt60_s)
    return sim.listen_pose(lab.pose, lab.duration_s, t0=0.0, mount=lab.mount)


_LOCALIZERS: dict[int, Localizer] = {}


LOCALIZER_NOTE = ("ssl_core SRP-PHAT, far-field grid, 0.5 deg fine resolution, band 300-6000 Hz, the k strongest "
                  "peaks for k known sources (no power threshold), one estimate per trial over the whole recording")


def localizer(n_sources: int = 1) -> Localizer:
    """The project's SRP-PHAT localizer as the paper used it: the ``n_sources`` strongest peaks of a
    0.5 deg grid (fine enough that grid quantisation does not hide the acoustic errors), no detection
    threshold (the number of sources is known in these experiments)."""
    loc = _LOCALIZERS.get(n_sources)
    if loc is None:
        cfg = LocalizerConfig(n_sources=n_sources, resolution_deg=0.5, min_power=0.0, rel_threshold=0.0)
        loc = _LOCALIZERS[n_sources] = Localizer("cube8", cfg)
    return loc


POOLED_NOTE = ("per-window peaks (64 ms windows, the 2 strongest each) pooled over the recording into a direction "
               "density (von Mises-Fisher kernel, 4 deg), its k highest modes at least 15 deg apart")


@dataclass(frozen=True)
class PooledDetection:
    """A direction found by pooling per-window detections (array frame, rad)."""

    azimuth: float
    elevation: float
    direction: np.ndarray
    power: float


_POOL_GRID: list[np.ndarray] = []


def pooled_localize(x: np.ndarray, k: int, kappa_deg: float = 4.0, sep_deg: float = 15.0) -> list[PooledDetection]:
    """Locate ``k`` simultaneous talkers by pooling short-window SRP-PHAT peaks over the recording.

    Talkers rarely dominate the same short window (speech is sparse in time-frequency), so
    per-window peaks fall on each talker in turn; the modes of their power-weighted direction
    density separate talkers that merge in the SRP map summed over the whole recording."""
    from ssl_core.grid import fibonacci_directions

    if not _POOL_GRID:
        _POOL_GRID.append(fibonacci_directions(20000))
    grid = _POOL_GRID[0]
    key = -k
    loc = _LOCALIZERS.get(key)
    if loc is None:
        cfg = LocalizerConfig(n_sources=2, resolution_deg=1.0, min_power=0.0, rel_threshold=0.5, window_frames=4)
        loc = _LOCALIZERS[key] = Localizer("cube8", cfg)
    dets = [d for r in loc.process_all(x) for d in r.detections]
    if not dets:
        return []
    dirs = np.array([d.direction for d in dets])
    w = np.array([d.power for d in dets])
    kappa = 1.0 / np.deg2rad(kappa_deg) ** 2
    dens = np.exp(kappa * (grid @ dirs.T - 1.0)) @ w
    out = []
    for _ in range(k):
        i = int(np.argmax(dens))
        if dens[i] <= 0:
            break
        u = grid[i]
        out.append(PooledDetection(float(np.arctan2(u[1], u[0])), float(np.arcsin(np.clip(u[2], -1, 1))), u.copy(),
                                   float(dens[i])))
        dens = np.where(grid @ u > np.cos(np.deg2rad(sep_deg)), 0.0, dens)
    return out


def wrap_deg(a) -> np.ndarray:
    """Angle difference wrapped to (-180, 180]."""
    return -((-(np.asarray(a, float) + 180.0)) % 360.0 - 180.0)


def match(detections, truths: list[Truth]) -> list[tuple[Truth, object | None, float]]:
    """Assign detections to truths minimising the total angular error (Hungarian); unmatched -> None."""
    if not detections:
        return [(t, None, np.inf) for t in truths]
    d = np.array([[np.rad2deg(angular_distance(det.direction, t.direction)) for det in detections] for t in truths])
    rows, cols = linear_sum_assignment(d)
    out = [(t, None, np.inf) for t in truths]
    for r, c in zip(rows, cols):
        out[r] = (truths[r], detections[c], float(d[r, c]))
    return out


def score(det, truth: Truth) -> dict:
    """Measured angles and errors (deg) of one detection against its truth."""
    if det is None:
        return {"az_meas": np.nan, "el_meas": np.nan, "az_err": np.nan, "el_err": np.nan, "ang_err": np.nan}
    az, el = np.rad2deg(det.azimuth), np.rad2deg(det.elevation)
    return {"az_meas": az, "el_meas": el, "az_err": float(wrap_deg(az - truth.azimuth_deg)),
            "el_err": el - truth.elevation_deg,
            "ang_err": float(np.rad2deg(angular_distance(det.direction, truth.direction)))}


def write_csv(path: Path, rows: list[dict]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    keys = list(rows[0]) if rows else []
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.4f}" if isinstance(v, float) else v) for k, v in r.items()})


def read_csv(path: Path) -> list[dict]:
    with open(path) as f:
        return list(csv.DictReader(f))


def md_table(header: list[str], rows: list[list]) -> str:
    fmt = [[(f"{v:.1f}" if isinstance(v, (float, np.floating)) else str(v)) for v in r] for r in rows]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(r) + " |" for r in fmt]
    return "\n".join(lines)


@dataclass
class Outcome:
    """What an experiment produced: files (relative to its output dir) and a markdown section."""

    name: str
    markdown: str
    files: list[str] = field(default_factory=list)
    seconds: float = 0.0
    summary: dict = field(default_factory=dict)


class Timer:
    def __enter__(self):
        self.t = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.seconds = time.perf_counter() - self.t


__all__ = ["Lab", "Truth", "build_sim", "record", "localizer", "match", "score", "wrap_deg", "write_csv", "read_csv",
           "md_table", "Outcome", "Timer", "RESULTS", "QUICK_RESULTS", "LOCALIZER_NOTE", "POOLED_NOTE", "pooled_localize"]


def script_main(run, doc: str | None) -> None:
    """Command line of one experiment script: ``[--quick] [--out DIR]``, prints its markdown."""
    ap = argparse.ArgumentParser(description=doc)
    ap.add_argument("--quick", action="store_true", help=f"few trials, written to {QUICK_RESULTS} by default")
    ap.add_argument("--out", type=Path, default=None, help=f"default {RESULTS} ({QUICK_RESULTS} with --quick)")
    a = ap.parse_args()
    out = a.out or (QUICK_RESULTS if a.quick else RESULTS)
    if a.quick and out.resolve() == RESULTS.resolve():
        ap.error(f"--quick must not overwrite the committed full results in {RESULTS}")
    print(run(a.quick, out).markdown)
