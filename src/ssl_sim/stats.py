"""Statistics of rescue runs: means with 95 % bootstrap intervals over scenarios, paired comparisons of two code
versions on the same scenarios, and the divergence between two BLAS kernels.

A *unit* is one scenario instance, ``(scenario, seed)``: runs of it under several BLAS kernels are averaged into
one unit first, so a kernel repeat never counts as an extra scenario. Intervals are percentile bootstraps over
units (``numpy``, seeded: the same rows give the same interval). A paired difference is "outside chance" only
when its interval excludes 0. Definitions and why: ``docs/design/scoring.md``.

Rows are dicts with at least ``scenario``, ``seed``, ``success``, ``n_found``, ``n_victims``, ``spl``,
``false_finds``, ``find_times_s`` (times of this run's finds, s) and ``position_errors_m`` (reported position
against the truth per find, m); optional ``family`` (default: the scenario name) and ``blas``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np

__all__ = ["Interval", "METRICS", "bootstrap_mean", "run_metrics", "units", "summarize", "paired_comparison",
           "kernel_divergence", "family_of"]

#: metric -> (label, unit) of the per-run values the tables report.
METRICS = {"success": ("success rate", ""), "victims_found": ("victims found", ""), "spl": ("SPL", ""),
           "time_to_find_s": ("time to find", "s"), "false_finds": ("false finds per run", ""),
           "position_error_m": ("position error", "m")}
N_BOOT = 4000
LEVEL = 0.95


@dataclass(frozen=True)
class Interval:
    """A mean and its ``level`` bootstrap interval over ``n`` units (nan when there are none)."""

    mean: float
    lo: float
    hi: float
    n: int

    def excludes_zero(self) -> bool:
        return self.n > 0 and (self.lo > 0 or self.hi < 0)

    def fmt(self, digits: int = 3) -> str:
        if self.n == 0 or not math.isfinite(self.mean):
            return "-"
        return f"{self.mean:.{digits}f} [{self.lo:.{digits}f}, {self.hi:.{digits}f}]"

    def as_dict(self, prefix: str) -> dict[str, float | int | None]:
        def r(x: float) -> float | None:
            return round(float(x), 4) if math.isfinite(x) else None
        return {prefix: r(self.mean), f"{prefix}_lo": r(self.lo), f"{prefix}_hi": r(self.hi)}


def bootstrap_mean(values: Iterable[float], n_boot: int = N_BOOT, level: float = LEVEL, seed: int = 0) -> Interval:
    """Mean of ``values`` (nan dropped) with its percentile bootstrap interval (``n_boot`` resamples)."""
    x = np.asarray([v for v in values if v is not None], float)
    x = x[np.isfinite(x)]
    if not x.size:
        return Interval(math.nan, math.nan, math.nan, 0)
    if not 0 < level < 1:
        raise ValueError(f"level: expected 0 < level < 1, got {level}")
    rng = np.random.default_rng(seed)
    means = x[rng.integers(0, x.size, size=(n_boot, x.size))].mean(axis=1)
    a = (1 - level) / 2
    lo, hi = np.quantile(means, [a, 1 - a])
    return Interval(float(x.mean()), float(lo), float(hi), int(x.size))


def _nanmean(xs: Sequence[float]) -> float:
    xs = [float(x) for x in xs if x is not None and math.isfinite(float(x))]
    return float(np.mean(xs)) if xs else math.nan


def run_metrics(row: dict) -> dict[str, float]:
    """Per-run values of :data:`METRICS` (nan: not defined for this run, e.g. no find to time)."""
    return {"success": float(bool(row["success"])),
            "victims_found": row["n_found"] / row["n_victims"] if row["n_victims"] else math.nan,
            "spl": float(row["spl"]), "false_finds": float(row["false_finds"]),
            "time_to_find_s": _nanmean(row.get("find_times_s", ())),
            "position_error_m": _nanmean(row.get("position_errors_m", ()))}


def family_of(row: dict) -> str:
    return str(row.get("family") or row["scenario"])


def units(rows: Sequence[dict]) -> dict[tuple[str, int], dict[str, float]]:
    """Per ``(scenario, seed)``: :func:`run_metrics` averaged over its runs (several BLAS kernels), plus family."""
    by: dict[tuple[str, int], list[dict]] = {}
    for r in rows:
        by.setdefault((str(r["scenario"]), int(r["seed"])), []).append(r)
    out = {}
    for key, rs in by.items():
        ms = [run_metrics(r) for r in rs]
        out[key] = {m: _nanmean([x[m] for x in ms]) for m in METRICS}
        out[key]["family"] = family_of(rs[0])
    return out


def summarize(rows: Sequence[dict], group: Callable[[dict], str] | None = None, seed: int = 0) -> list[dict]:
    """Per family (``group(unit) -> name``, default the unit's family) and over all rows ("all"): the number of
    scenarios and every metric's mean with its 95 % bootstrap interval (``<metric>``, ``_lo``, ``_hi``)."""
    us = units(rows)
    group = group or (lambda u: u["family"])
    groups: dict[str, list[dict]] = {}
    for u in us.values():
        groups.setdefault(group(u), []).append(u)
    if len(groups) > 1:
        groups["all"] = list(us.values())
    out = []
    for name, members in groups.items():
        row: dict = {"family": name, "scenarios": len(members)}
        for m in METRICS:
            row.update(bootstrap_mean([u[m] for u in members], seed=seed).as_dict(m))
        out.append(row)
    return out


def paired_comparison(new_rows: Sequence[dict], old_rows: Sequence[dict], metrics: Sequence[str] | None = None,
                      seed: int = 0) -> list[dict]:
    """new - old per metric, paired on the ``(scenario, seed)`` units both ran: the mean difference with its
    95 % bootstrap interval over those units and ``outside_chance`` (the interval excludes 0)."""
    a, b = units(new_rows), units(old_rows)
    keys = sorted(set(a) & set(b))
    out = []
    for m in metrics or list(METRICS):
        d = [a[k][m] - b[k][m] for k in keys]
        iv = bootstrap_mean(d, seed=seed)
        out.append({"metric": m, "pairs": iv.n, "new": _nanmean([a[k][m] for k in keys]),
                    "old": _nanmean([b[k][m] for k in keys]), **iv.as_dict("difference"),
                    "outside_chance": iv.excludes_zero()})
    return out


def _outcome(row: dict) -> tuple:
    """What a run achieved: which victims were found, and how many false finds."""
    found = row.get("found_victims")
    if found is None:
        found = sorted(k for k, t in row.get("victim_times", {}).items() if t is not None)
    return tuple(sorted(found)), int(row["false_finds"])


def kernel_divergence(rows: Sequence[dict]) -> list[dict]:
    """For every pair of BLAS kernels in ``rows`` (field ``blas``): over the ``(scenario, seed)`` units run under
    both, the share whose outcome (victims found, false finds) differs and the share whose SPL differs at all."""
    by: dict[str, dict[tuple[str, int], dict]] = {}
    for r in rows:
        by.setdefault(str(r.get("blas", "")), {})[(str(r["scenario"]), int(r["seed"]))] = r
    ks = sorted(by)
    out = []
    for i, k1 in enumerate(ks):
        for k2 in ks[i + 1:]:
            common = sorted(set(by[k1]) & set(by[k2]))
            if not common:
                continue
            diff = [_outcome(by[k1][u]) != _outcome(by[k2][u]) for u in common]
            spl = [abs(float(by[k1][u]["spl"]) - float(by[k2][u]["spl"])) > 1e-9 for u in common]
            out.append({"kernels": f"{k1 or 'cpu'} vs {k2 or 'cpu'}", "runs": len(common),
                        "outcome_differs": round(float(np.mean(diff)), 4),
                        "spl_differs": round(float(np.mean(spl)), 4)})
    return out
