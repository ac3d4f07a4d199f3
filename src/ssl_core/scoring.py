"""Scoring per-window detections against a truth time series of source directions.

The truth is the JSON ``ssl-rescue record`` writes beside its WAV: ``time_s`` (frame centres, s) and, per source,
``azimuth_deg`` / ``elevation_deg`` in the ARRAY frame and ``sounding`` (bool) on every frame; ``name`` optional.

Definitions (angles are great-circle angles between unit vectors, degrees):

- A window is scored at the truth frame nearest to its centre; a source is *sounding* in the window when it
  sounds in that frame.
- Within a window, detections and sounding sources are paired greedily, closest pair first, each at most once,
  and only within ``tolerance_deg``: a paired detection is a *hit* of its source.
- Per source: *detection rate* = windows with a hit / windows where it sounds; *error* = the angle of its hits
  (median, 90th percentile, over its hit windows).
- A *false alarm* is a detection paired with no source (none sounding within ``tolerance_deg``, or that source
  taken by a closer detection). *False-alarm rate* = false alarms / all detections; also per window.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: Default pairing tolerance (deg): a detection this close to a sounding source counts as a hit.
DEFAULT_TOLERANCE_DEG = 20.0


def _unit(az_deg, el_deg) -> np.ndarray:
    a, e = np.radians(np.asarray(az_deg, float)), np.radians(np.asarray(el_deg, float))
    return np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], axis=-1)


@dataclass(frozen=True)
class Truth:
    """Truth directions: ``times`` (frames,) s; ``directions`` (sources, frames, 3) unit vectors, array frame;
    ``sounding`` (sources, frames) bool; ``names`` one per source."""

    times: np.ndarray
    directions: np.ndarray
    sounding: np.ndarray
    names: tuple[str, ...]

    @classmethod
    def from_dict(cls, d: dict, where: str = "truth") -> Truth:
        """From the truth JSON's dict; ``ValueError`` naming the field and what was expected otherwise."""
        if not isinstance(d, dict):
            raise ValueError(f"{where}: expected a JSON object with 'time_s' and 'sources'")
        times = d.get("time_s")
        if not isinstance(times, list) or not times:
            raise ValueError(f"{where}: 'time_s' missing or empty, expected the frame times (s)")
        sources = d.get("sources")
        if not isinstance(sources, list) or not sources:
            raise ValueError(f"{where}: 'sources' missing or empty, expected a list of sources")
        n = len(times)
        dirs, on, names = [], [], []
        for k, s in enumerate(sources):
            if not isinstance(s, dict):
                raise ValueError(f"{where}: sources[{k}]: expected an object")
            for key in ("azimuth_deg", "elevation_deg", "sounding"):
                v = s.get(key)
                if not isinstance(v, list) or len(v) != n:
                    got = "nothing" if v is None else f"{len(v)} values" if isinstance(v, list) else type(v).__name__
                    raise ValueError(f"{where}: sources[{k}].{key}: expected a list of {n} values (one per time_s), "
                                     f"got {got}")
            try:
                dirs.append(_unit(s["azimuth_deg"], s["elevation_deg"]))
            except (TypeError, ValueError):
                raise ValueError(f"{where}: sources[{k}]: azimuth_deg / elevation_deg must be numbers") from None
            on.append(np.asarray(s["sounding"], dtype=bool))
            names.append(str(s.get("name", f"source {k + 1}")))
        t = np.asarray(times, float)
        if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)):
            raise ValueError(f"{where}: 'time_s': expected increasing finite times (s)")
        return cls(t, np.stack(dirs), np.stack(on), tuple(names))

    def at(self, time_s: float) -> int:
        """Index of the frame nearest to ``time_s``."""
        k = int(np.searchsorted(self.times, time_s))
        if k > 0 and (k == len(self.times) or time_s - self.times[k - 1] <= self.times[k] - time_s):
            k -= 1
        return k


@dataclass
class SourceScore:
    name: str
    windows_sounding: int = 0
    hits: int = 0
    errors_deg: list[float] = field(default_factory=list)

    @property
    def detection_rate(self) -> float:
        return self.hits / self.windows_sounding if self.windows_sounding else math.nan

    def to_dict(self) -> dict:
        e = np.asarray(self.errors_deg)
        return {"name": self.name, "windows_sounding": self.windows_sounding, "hits": self.hits,
                "detection_rate": _r(self.detection_rate, 4),
                "error_median_deg": _r(float(np.median(e)) if e.size else math.nan, 2),
                "error_p90_deg": _r(float(np.percentile(e, 90)) if e.size else math.nan, 2)}


def _r(v: float, nd: int):
    return None if not math.isfinite(v) else round(v, nd)


class Scorer:
    """Accumulates the scores of detections window by window (see the module docstring for the definitions)."""

    def __init__(self, truth: Truth, tolerance_deg: float = DEFAULT_TOLERANCE_DEG) -> None:
        if not (math.isfinite(tolerance_deg) and 0 < tolerance_deg < 180):
            raise ValueError(f"tolerance_deg: expected an angle in (0, 180) deg, got {tolerance_deg}")
        self.truth = truth
        self.tolerance_deg = float(tolerance_deg)
        self.sources = [SourceScore(n) for n in truth.names]
        self.windows = 0
        self.detections = 0
        self.false_alarms = 0

    def add(self, centre_time_s: float, directions: np.ndarray) -> None:
        """One window: its centre time (s, same clock as the truth) and its detections' unit vectors (n, 3)."""
        f = self.truth.at(centre_time_s)
        on = np.flatnonzero(self.truth.sounding[:, f])
        d = np.asarray(directions, float).reshape(-1, 3)
        self.windows += 1
        self.detections += len(d)
        for k in on:
            self.sources[k].windows_sounding += 1
        paired = 0
        if len(d) and len(on):
            ang = np.degrees(np.arccos(np.clip(d @ self.truth.directions[on, f].T, -1.0, 1.0)))  # (dets, sounding)
            free_d, free_s = np.ones(len(d), bool), np.ones(len(on), bool)
            for flat in np.argsort(ang, axis=None):
                i, j = np.unravel_index(flat, ang.shape)
                if ang[i, j] > self.tolerance_deg:
                    break
                if free_d[i] and free_s[j]:
                    free_d[i] = free_s[j] = False
                    src = self.sources[on[j]]
                    src.hits += 1
                    src.errors_deg.append(float(ang[i, j]))
                    paired += 1
        self.false_alarms += len(d) - paired

    @property
    def false_alarm_rate(self) -> float:
        """False alarms / all detections (nan without detections)."""
        return self.false_alarms / self.detections if self.detections else math.nan

    def to_dict(self) -> dict:
        return {"tolerance_deg": self.tolerance_deg, "windows": self.windows, "detections": self.detections,
                "false_alarms": self.false_alarms, "false_alarm_rate": _r(self.false_alarm_rate, 4),
                "false_alarms_per_window": _r(self.false_alarms / self.windows if self.windows else math.nan, 4),
                "sources": [s.to_dict() for s in self.sources]}
