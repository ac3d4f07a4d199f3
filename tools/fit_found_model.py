"""Fit the found model (``robot.found``) on the benchmark's train split, and measure its trade-off curve.

    python tools/fit_found_model.py collect [--first 0 --count 48 --workers 2]   # runs -> assessments.csv.gz
    python tools/fit_found_model.py fit                                         # -> robot/models/found_model.json
    python tools/fit_found_model.py curve [--first 200 --count 24 --p 0.5 0.7 0.8 0.9 0.95]

``--driving`` (each command): the runs also hear while driving (``RescueConfig.listen_while_driving``), their
data ``assessments_driving.csv.gz`` and model ``robot/models/found_model_driving.json``: bearings heard on the
way add listens between the standing ones, so a cue such as support means less per listen there.

``collect`` runs the behaviour on train scenarios (seed = index) and writes every P(find) judgement it made
(``RescueBehaviour.finder.assessments``: the cues' features per source per listen) with its label from the simulator's
truth: 1 when a victim not yet found lies within ``FIND_RADIUS_M`` of the report (the map's estimate) and the robot's
true base within ``BASE_RADIUS_M`` of her (``ssl_sim.scoring``'s find), else 0.

``fit`` fits the weights by logistic regression with a Gaussian prior around each cue's physical weight (maximum a
posteriori, scipy.optimize, deterministic: where the data is silent a weight keeps its physics), and from the same
data the per-listen confirm probability (P(a listen at her estimate reaches p_find | she is there)); the prior
density of victims comes from the train split's generated rooms. It writes the model with its provenance and the
fit's figures (calibration, weights) into ``experiments/found_model/``.

``curve`` runs other train scenarios (not those fitted on) at several ``p_find`` values and writes false finds per
run against the mean time to find (``experiments/found_model/p_find_curve.{json,png}``).
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import csv
import gzip
import io
import json
import math
import multiprocessing
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy import optimize

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from robot.found import BASE_RADIUS_M, CUES, FIND_RADIUS_M, default_model_path  # noqa: E402
from robot.rescue_config import RescueConfig  # noqa: E402

OUT = ROOT / "experiments" / "found_model"
DATA = OUT / "assessments.csv.gz"


def data_path(driving: bool = False) -> Path:
    """The assessments of the runs that listen standing, or that also hear while driving (``--driving``)."""
    return OUT / "assessments_driving.csv.gz" if driving else DATA
NAMES = [c.name for c in CUES]
#: Prior mean of each weight (log-odds per unit of the cue), from the cue's physics: what it should add where the
#: train data is silent. The generated victims' mouths lie 0.15-0.48 m up and the array 0.27 m, so steep bearings,
#: echoes below a mouth and contacts at a voiced target are rare in the data; a mouth 0.1 m up (a lying victim) is
#: heard 20-35 deg down from within 0.3 m. depression 6: a bearing 30 deg down (sin 0.5) multiplies the odds by 20;
#: range_agreement 1.5: a floor range that matches the estimate, x4.5; level_rise 0.8 per 10 dB (inverse-square:
#: +12 dB from 2 m to 0.5 m); coherence 4 per unit of SRP-PHAT peak power (direct sound dominates within the critical
#: distance); voice and position 0.8 per unit of log-odds (the map's own probabilities, overconfident: its covariance
#: ignores reflections); distance -1.5 per m and beyond_reach -6 per m (the base must end within 1.5 m of her);
#: echo -3, near_machine -2, near_found -4 (the sound is another source's); contact +2 (a victim under rubble is
#: touched); triangulated +1; support, consistency, crossing, at_loudest, heard: 0 (no physical expectation of the
#: size).
PRIOR = {"voice": 0.8, "position": 0.8, "support": 0.0, "consistency": 0.0, "crossing": 0.0, "distance": -1.5,
         "beyond_reach": -6.0, "at_loudest": 0.0, "depression": 6.0, "range_agreement": 1.5, "level_rise": 0.8,
         "coherence": 4.0, "heard": 0.0, "echo": -3.0, "near_machine": -2.0, "near_found": -4.0, "contact": 2.0,
         "triangulated": 1.0}
# Precision of the Gaussian prior on each weight (1 / variance; the bias has none), chosen by 4-fold
# cross-validation over scenarios on the fit data: held-out log-loss 0.2377 / 0.2366 / 0.2360 / 0.2368 / 0.2388 at
# 0.3 / 1 / 3 / 10 / 30.
L2 = 3.0
P_FIND = RescueConfig().p_find   # the threshold the confirm probability is measured at (the behaviour's default)


# ----------------------------------------------------------------------------- collecting
def _label_run(index: int, p_find: float | None = None, confirm: float | None = None, driving: bool = False
               ) -> tuple[list[dict], dict]:
    """Run train scenario ``index`` (``driving``: hearing while driving too); its assessments with labels, and
    the run's find summary."""
    from ssl_sim.runner import RescueRun
    from ssl_sim.suite import generate

    sc = generate("train", index)
    if p_find is not None:
        sc = replace(sc, behaviour=replace(sc.behaviour, p_find=p_find))
    sc = replace(sc, behaviour=replace(sc.behaviour, listen_while_driving=driving))
    if confirm is not None:
        sc = replace(sc, pursuit=replace(sc.pursuit, confirm_probability=confirm))
    run = RescueRun(sc)
    result = run.run()
    victims = np.array([s.position[:2] for s in run.sources[: run.n_victims]], float)
    found_at = {k: float(e["time_s"]) for k, e in run.found.items()}
    rows = []
    for a in run.behaviour.finder.assessments:
        _, x, y, _, _ = run._pose_at(a.time)
        rep = np.asarray(a.position, float)
        ok = [k for k, v in enumerate(victims) if found_at.get(k, math.inf) >= a.time
              and np.hypot(*(rep - v)) <= FIND_RADIUS_M and np.hypot(x - v[0], y - v[1]) <= BASE_RADIUS_M]
        rows.append({"scenario": index, "time": round(a.time, 3), "source": a.source_id,
                     **{k: round(float(a.features.get(k, 0.0)), 6) for k in NAMES}, "label": int(bool(ok))})
    times = [e["time_s"] for e in run.found.values()]
    summary = {"scenario": index, "victims": run.n_victims, "found": len(run.found),
               "false_finds": sum(1 for d in run.declarations if d["kind"] == "false_find"),
               "too_far": sum(1 for d in run.declarations if d["kind"] == "too_far"),
               "find_times": times, "time_limit_s": sc.time_limit_s, "spl": result.get("spl")}
    return rows, summary


def _pool(fn, args, workers: int):
    ctx = multiprocessing.get_context("spawn")
    with cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as ex:
        return list(ex.map(fn, *zip(*args)))


def collect(first: int, count: int, workers: int, p_find: float | None = None, driving: bool = False) -> None:
    out = _pool(_label_run, [(i, p_find, None, driving) for i in range(first, first + count)], workers)
    data = data_path(driving)
    rows = [r for rs, _ in out for r in rs]
    OUT.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=["scenario", "time", "source", *NAMES, "label"], lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    with gzip.GzipFile(data, "wb", mtime=0) as f:   # mtime 0: the same rows give the same file
        f.write(buf.getvalue().encode())
    found = sum(s["found"] for _, s in out)
    print(f"collected {len(rows)} assessments ({sum(r['label'] for r in rows)} positive) from {count} train "
          f"scenarios {first}..{first + count - 1}; the collecting model found {found} of "
          f"{sum(s['victims'] for _, s in out)} victims -> {data.relative_to(ROOT)}")


# ----------------------------------------------------------------------------- fitting
def load_data(path: Path = DATA) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    with gzip.open(path, "rt") as f:
        rows = list(csv.DictReader(f))
    X = np.array([[float(r[k]) for k in NAMES] for r in rows], float)
    y = np.array([int(r["label"]) for r in rows], float)
    return X, y, rows


def fit_logistic(X: np.ndarray, y: np.ndarray, l2: float = L2, prior: np.ndarray | None = None
                 ) -> tuple[float, np.ndarray]:
    """(bias, weights): the maximum a posteriori logistic regression, log-likelihood of ``y`` (0/1) given ``X`` plus
    a Gaussian prior of precision ``l2`` around ``prior`` (zeros if None) on the weights; L-BFGS from the prior
    (deterministic)."""
    mu = np.zeros(X.shape[1]) if prior is None else np.asarray(prior, float)

    def loss(theta):
        z = theta[0] + X @ theta[1:]
        ll = np.logaddexp(0.0, z) - y * z          # log(1 + e^z) - y z, stably
        p = 0.5 * (1.0 + np.tanh(0.5 * z))
        g = np.concatenate([[np.sum(p - y)], X.T @ (p - y)])
        g[1:] += l2 * (theta[1:] - mu)
        return float(np.sum(ll) + 0.5 * l2 * np.sum((theta[1:] - mu) ** 2)), g

    res = optimize.minimize(loss, np.concatenate([[0.0], mu]), jac=True, method="L-BFGS-B",
                            options={"maxiter": 10000, "gtol": 1e-9, "ftol": 1e-15})
    return float(res.x[0]), res.x[1:]


def confirm_probability(p: np.ndarray, X: np.ndarray, y: np.ndarray, p_find: float) -> tuple[float, np.ndarray]:
    """P(one listen at her estimate reaches ``p_find`` | she is there): the share of the positive assessments made
    with the robot within the find radius of the report whose P(find) ``p`` reaches ``p_find`` (kept within
    0.05..0.95: a listen is never certain either way); and that mask."""
    pos_at = (y == 1) & (X[:, NAMES.index("distance")] <= FIND_RADIUS_M)
    c = float(np.mean(p[pos_at] >= p_find)) if pos_at.any() else 0.3
    return min(max(c, 0.05), 0.95), pos_at


def victims_per_m2(count: int = 64) -> float:
    """Mean victims per m^2 of room floor over the first ``count`` train scenarios (generated, not run)."""
    from ssl_sim.suite import generate
    dens = []
    for i in range(count):
        sc = generate("train", i)
        size = sc.scene.world.room.size
        dens.append(len(sc.victims) / (size[0] * size[1]))
    return float(np.mean(dens))


def _git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def fit(write: bool = True, path: Path | None = None, driving: bool = False) -> dict:
    path = data_path(driving) if path is None else path
    X, y, rows = load_data(path)
    bias, w = fit_logistic(X, y, L2, np.array([PRIOR[k] for k in NAMES]))
    p = 1.0 / (1.0 + np.exp(-(bias + X @ w)))
    confirm, pos_at = confirm_probability(p, X, y, P_FIND)
    scen = sorted({int(r["scenario"]) for r in rows})
    model = {
        "bias": round(bias, 6),
        "weights": {k: round(float(v), 6) for k, v in zip(NAMES, w)},
        "provenance": {
            "fitted_by": "tools/fit_found_model.py fit (logistic regression, maximum a posteriori under a Gaussian "
                         "prior around the cues' physical weights, scipy L-BFGS-B)",
            "data": str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path),
            "train_scenarios": f"{scen[0]}..{scen[-1]}" if scen else "",
            "assessments": int(len(y)), "positives": int(y.sum()), "prior_precision": L2, "prior": PRIOR,
            "confirm_probability": round(confirm, 4), "confirm_measured_at_p_find": P_FIND,
            "confirm_listens": int(pos_at.sum()),
            "victims_per_m2": round(victims_per_m2(), 5),
        },
    }
    if write:
        default_model_path(driving).write_text(json.dumps(model, indent=2) + "\n")
        _figures(X, y, p, model, "fit_driving.png" if driving else "fit.png")
        print(f"wrote {default_model_path(driving).relative_to(ROOT)}")
    print(json.dumps(model, indent=2))
    return model


def _figures(X, y, p, model, name: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    OUT.mkdir(parents=True, exist_ok=True)
    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4))
    edges = np.linspace(0, 1, 11)
    k = np.clip(np.digitize(p, edges) - 1, 0, 9)
    mids, obs, ns = [], [], []
    for i in range(10):
        m = k == i
        if m.sum() >= 5:
            mids.append(p[m].mean()), obs.append(y[m].mean()), ns.append(int(m.sum()))
    a.plot([0, 1], [0, 1], "k:", lw=1)
    a.plot(mids, obs, "o-")
    for xm, yo, n in zip(mids, obs, ns):
        a.annotate(str(n), (xm, yo), textcoords="offset points", xytext=(4, -10), fontsize=7)
    a.set(xlabel="P(find) predicted", ylabel="share of finds (truth)", title="calibration on the fit data")
    ws = model["weights"]
    b.barh(list(ws), list(ws.values()))
    b.set(xlabel="log-odds per unit of the cue", title=f"weights (bias {model['bias']:.2f})")
    fig.tight_layout()
    fig.savefig(OUT / name, dpi=110)
    plt.close(fig)


# ----------------------------------------------------------------------------- trade-off curve
def curve(first: int, count: int, values: list[float], workers: int, driving: bool = False) -> None:
    X, y, _ = load_data(data_path(driving))
    m = json.loads(default_model_path(driving).read_text())
    p = 1.0 / (1.0 + np.exp(-(m["bias"] + X @ np.array([m["weights"][k] for k in NAMES]))))
    confirm = {pf: confirm_probability(p, X, y, pf)[0] for pf in values}
    tasks = [(i, pf, confirm[pf], driving) for pf in values for i in range(first, first + count)]
    out = _pool(_label_run, tasks, workers)
    rows = []
    for pf in values:
        ss = [s for (i, q, _, _), (_, s) in zip(tasks, out) if q == pf]
        times = [t for s in ss for t in s["find_times"]]
        rows.append({"p_find": pf, "confirm_probability": round(confirm[pf], 4), "runs": len(ss),
                     "too_far_per_run": sum(s["too_far"] for s in ss) / len(ss), "found": sum(s["found"] for s in ss) / sum(s["victims"] for s in ss),
                     "false_finds_per_run": sum(s["false_finds"] for s in ss) / len(ss),
                     "mean_time_to_find_s": float(np.mean(times)) if times else None})
        print(json.dumps(rows[-1]))
    OUT.mkdir(parents=True, exist_ok=True)
    name = "p_find_curve_driving" if driving else "p_find_curve"
    (OUT / f"{name}.json").write_text(json.dumps({"train_scenarios": f"{first}..{first + count - 1}",
                                                       "commit": _git_commit(), "rows": rows,
                                                       "runs": [{"p_find": t[1], **s} for t, (_, s) in zip(tasks, out)]},
                                                      indent=2) + "\n")
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(5.5, 4))
    t = [r["mean_time_to_find_s"] or np.nan for r in rows]
    ax.plot(t, [r["false_finds_per_run"] for r in rows], "o-")
    for r, ti in zip(rows, t):
        ax.annotate(f"p_find {r['p_find']:g}\nfound {r['found']:.0%}", (ti, r["false_finds_per_run"]),
                    fontsize=7, textcoords="offset points", xytext=(4, 2))
    ax.set(xlabel="mean time to find (s)", ylabel="false finds per run",
           title=f"p_find trade-off, train {first}..{first + count - 1}")
    fig.tight_layout()
    fig.savefig(OUT / f"{name}.png", dpi=110)
    plt.close(fig)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    c = sub.add_parser("collect")
    c.add_argument("--first", type=int, default=0)
    c.add_argument("--count", type=int, default=48)
    c.add_argument("--workers", type=int, default=2)
    c.add_argument("--p-find", type=float, default=None, help="the collecting behaviour's p_find (default its own)")
    f = sub.add_parser("fit")
    f.add_argument("--dry-run", action="store_true", help="print the fit, write nothing")
    k = sub.add_parser("curve")
    k.add_argument("--first", type=int, default=200)
    k.add_argument("--count", type=int, default=24)
    k.add_argument("--p", type=float, nargs="+", default=[0.5, 0.7, 0.8, 0.9, 0.95])
    k.add_argument("--workers", type=int, default=2)
    for sp in (c, f, k):
        sp.add_argument("--driving", action="store_true",
                        help="the model of runs that also hear while driving (found_model_driving.json)")
    a = ap.parse_args(argv)
    if a.cmd == "collect":
        collect(a.first, a.count, a.workers, a.p_find, a.driving)
    elif a.cmd == "fit":
        fit(write=not a.dry_run, driving=a.driving)
    else:
        curve(a.first, a.count, a.p, a.workers, a.driving)


if __name__ == "__main__":
    main()
