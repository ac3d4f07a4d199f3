"""Experiment 4 (beyond the paper): localization error against reverberation time, signal-to-noise
ratio and the number of simultaneous talkers.

Every trial draws its source directions at random (seeded): azimuth uniform, elevation
uniform in [-30, 60] deg, distance uniform in [1.2, 2.5] m, around the array at 1.5 m in
the lab room; errors are great-circle angles between detected and true directions.

* RT60 sweep 0-1 s (uniform absorption set by Eyring's formula), lab noise (35 dB SPL);
* SNR sweep -5 to 30 dB at RT60 0.5 s: diffuse pink noise whose broadband level at the
  array is the source's received level (direct + reverberant, averaged over the microphones,
  measured on the noise-free signal) minus the SNR;
* 1-4 simultaneous talkers (different voices, equal levels, at least 30 deg apart), the
  localizer asked for as many peaks as there are talkers; detections matched to talkers by
  minimum total angular error; a talker counts as found if matched within 10 deg.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.common import (
    LOCALIZER_NOTE, POOLED_NOTE, RESULTS, Lab, Outcome, Timer, Truth, build_sim,
                                localizer, match, md_table, pooled_localize, record, write_csv, script_main)

LAB = Lab(array_height_m=1.5, noise_spectrum="hvac")
FOUND_DEG = 10.0


def random_truths(rng: np.random.Generator, n: int, min_sep_deg: float = 30.0, lab: Lab = LAB,
                  clearance_m: float = 0.25) -> list[Truth]:
    """``n`` random source placements at least ``min_sep_deg`` apart, each ``clearance_m`` inside the room."""
    out: list[Truth] = []
    size = np.asarray(lab.room_size)
    while len(out) < n:
        t = Truth(float(rng.uniform(-180, 180)), float(rng.uniform(-30, 60)), float(rng.uniform(1.2, 2.5)))
        p = lab.centre + t.distance_m * t.direction
        if not np.all((p > clearance_m) & (p < size - clearance_m)):
            continue
        if all(np.rad2deg(np.arccos(np.clip(t.direction @ u.direction, -1, 1))) >= min_sep_deg for u in out):
            out.append(t)
    return out


def received_level_db(lab: Lab, truths: list[Truth], seed: int, rt60_s: float) -> float:
    """Broadband SPL (dB) of the trial's sources at the microphones, noise-free, over the frames where they sound."""
    sim = build_sim(lab, truths, seed, rt60_s=rt60_s, ambient=False)
    p = sim.pressure(lab.mount.mic_positions_world(lab.pose), 0, int(lab.duration_s * sim.config.fs))
    frames = p[:, : p.shape[1] // 160 * 160].reshape(p.shape[0], -1, 160)
    e = np.mean(frames**2, axis=(0, 2))
    active = e > e.max() * 1e-3
    return float(10 * np.log10(np.mean(e[active]) / (20e-6) ** 2))


_WINDOW_LOC: list = []
WINDOW_NOTE = ("the robot's per-window view: ssl_core's default LocalizerConfig (128 ms windows, 1.5 deg grid, "
               "detection thresholds on), strongest detection per window")


def window_errors(x: np.ndarray, truth: Truth) -> tuple[float, float]:
    """Median angular error (deg) of the per-window detections and the fraction of windows localized within FOUND_DEG."""
    from ssl_core.localizer import Localizer

    if not _WINDOW_LOC:
        _WINDOW_LOC.append(Localizer("cube8"))
    res = _WINDOW_LOC[0].process_all(x)
    errs = [np.rad2deg(np.arccos(np.clip(r.detections[0].direction @ truth.direction, -1, 1)))
            for r in res if r.detections]
    if not res:
        return np.nan, 0.0
    return (float(np.median(errs)) if errs else np.nan), float(np.sum(np.asarray(errs) < FOUND_DEG) / len(res))


def trial(truths: list[Truth], seed: int, rt60_s: float, noise_db: float | None = None, lab: Lab = LAB,
          pooled: bool = False, windows: bool = False) -> list[dict]:
    """Errors of one trial: the summed-map estimate; with ``pooled`` the pooled per-window one (one row per
    talker); with ``windows`` the per-window view (one row: median window error, fraction of windows found)."""
    x = record(lab, truths, seed, noise_db_spl=noise_db, rt60_s=rt60_s)
    methods = [("map", localizer(len(truths)).locate_summed(x).detections)]
    if pooled:
        methods.append(("pooled", pooled_localize(x, len(truths))))
    rows = [{"method": m, "ang_err": e, "found": float(e < FOUND_DEG)}
            for m, dets in methods for _, _, e in match(dets, truths)]
    if windows:
        e, f = window_errors(x, truths[0])
        rows.append({"method": "window", "ang_err": e, "found": f})
    return rows


def _stats(rows: list[dict]) -> dict:
    e = np.asarray([r["ang_err"] for r in rows], float)
    fin = e[np.isfinite(e)]
    return {"median": float(np.median(fin)) if fin.size else np.nan, "mean": float(np.mean(fin)) if fin.size else np.nan,
            "p90": float(np.percentile(fin, 90)) if fin.size else np.nan,
            "found": float(np.mean([r["found"] for r in rows])) if rows else np.nan, "n": int(e.size)}


def run(quick: bool = False, out_dir: Path = RESULTS, seed0: int = 0) -> Outcome:
    trials = 2 if quick else 20
    rt60s = [0.0, 0.5, 1.0] if quick else [round(0.1 * k, 1) for k in range(11)]
    snrs = [-5.0, 10.0, 30.0] if quick else [-5.0, 0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0]
    counts = [1, 2] if quick else [1, 2, 3, 4]
    rows = []
    with Timer() as tm:
        for rt in rt60s:
            for k in range(trials):
                seed = seed0 + 7919 * k + 11
                t = random_truths(np.random.default_rng(seed), 1)
                for r in trial(t, seed, rt, windows=True):
                    rows.append({"sweep": "rt60", "value": rt, "trial": k, "seed": seed, **r})
        snr_lab = Lab(array_height_m=LAB.array_height_m, noise_spectrum="pink")
        for k in range(trials):
            seed = seed0 + 7919 * k + 23
            t = random_truths(np.random.default_rng(seed), 1)
            sig_db = received_level_db(snr_lab, t, seed, snr_lab.rt60_s)
            for snr in snrs:
                for r in trial(t, seed, snr_lab.rt60_s, noise_db=sig_db - snr, lab=snr_lab, windows=True):
                    rows.append({"sweep": "snr", "value": snr, "trial": k, "seed": seed, **r})
        for n in counts:
            for k in range(trials):
                seed = seed0 + 7919 * k + 37 + n
                t = random_truths(np.random.default_rng(seed), n)
                for r in trial(t, seed, LAB.rt60_s, pooled=True):
                    rows.append({"sweep": "talkers", "value": float(n), "trial": k, "seed": seed, **r})
    out_dir.mkdir(parents=True, exist_ok=True)
    write_csv(out_dir / "exp4_conditions.csv", rows)

    import matplotlib.pyplot as plt

    def sel(sweep, v, method):
        return [r for r in rows if r["sweep"] == sweep and r["value"] == float(v) and r["method"] == method]

    colours = {"map": "tab:blue", "window": "tab:green", "pooled": "tab:orange"}
    sweeps = (("rt60", rt60s, "RT60 (s)", ("map", "window")), ("snr", snrs, "SNR at the array (dB)", ("map", "window")),
              ("talkers", counts, "simultaneous talkers", ("map", "pooled")))
    summary: dict = {}
    fig, axs = plt.subplots(1, 3, figsize=(17, 4.8))
    for ax, (sweep, xs, xlabel, methods) in zip(axs, sweeps):
        pos = np.arange(1, len(xs) + 1, dtype=float)
        ax2 = ax.twinx()
        for mi, method in enumerate(methods):
            st = {str(v): _stats(sel(sweep, v, method)) for v in xs}
            summary[f"{sweep}_{method}"] = st
            if method == "map":
                summary[sweep] = st
            off = (mi - 0.5) * 0.32
            data = [np.clip([r["ang_err"] for r in sel(sweep, v, method) if np.isfinite(r["ang_err"])], 0.05, 180)
                    for v in xs]
            bp = ax.boxplot(data, positions=pos + off, widths=0.28, patch_artist=True, showfliers=True,
                            flierprops={"markersize": 3})
            for b in bp["boxes"]:
                b.set_facecolor(colours[method])
                b.set_alpha(0.55)
            ax2.plot(pos + off, [100 * st[str(v)]["found"] for v in xs], "--", marker=".", lw=1,
                     color=colours[method], label=f"{method}: % found")
        ax.set_xticks(pos, [f"{v:g}" for v in xs])
        ax.set_yscale("log")
        ax.set_ylim(0.05, 200)
        ax.set_ylabel("angular error (deg), boxes")
        ax.set_xlabel(xlabel)
        ax2.set_ylim(0, 105)
        ax2.set_ylabel(f"found within {FOUND_DEG:g} deg (%), dashed")
        ax2.legend(loc="lower right", fontsize=8)
        ax.grid(alpha=0.3)
    axs[0].set_title(f"Reverberation ({LAB.noise_db_spl:g} dB SPL noise)")
    axs[1].set_title(f"SNR (RT60 {LAB.rt60_s:g} s, pink diffuse noise)")
    axs[2].set_title(f"Simultaneous talkers (RT60 {LAB.rt60_s:g} s)")
    fig.tight_layout()
    fig.savefig(out_dir / "exp4_conditions.png", dpi=110)
    plt.close(fig)

    sections = []
    for sweep, xs, name, methods in sweeps:
        sections.append(md_table([name, "method", "median err (deg)", "mean err", "90th pct", f"found < {FOUND_DEG:g} deg",
                                  "n"],
                                 [[v, m, s["median"], s["mean"], s["p90"], f"{100 * s['found']:.0f}%", s["n"]]
                                  for v in xs for m in methods for s in (summary[f"{sweep}_{m}"][str(v)],)]))
    md = f"""### 4. Beyond the paper: reverberation, noise, number of talkers

Set-up: {LAB.describe()} (RT60 and noise changed per sweep as stated). Random directions per trial (azimuth uniform,
elevation -30..60 deg, 1.2-2.5 m). Localizer: {LOCALIZER_NOTE}. {trials} trials per point; errors are great-circle
angles; "found" = matched within {FOUND_DEG:g} deg. SNR = broadband level of the received source signal (direct +
reverberant, while sounding) over the diffuse noise level at the array.

![conditions](exp4_conditions.png)

"map": one estimate per trial from the SRP map summed over the whole recording (as in the paper); "window":
{WINDOW_NOTE} - its error is the median over a trial's windows and "found" the share of its windows within
{FOUND_DEG:g} deg (pauses between calls count as misses).

Reverberation time:

{sections[0]}

Signal-to-noise ratio (RT60 {LAB.rt60_s:g} s):

{sections[1]}

Simultaneous talkers (RT60 {LAB.rt60_s:g} s, {LAB.noise_db_spl:g} dB SPL noise). "map": the k strongest peaks of the
SRP map summed over the recording; "pooled": {POOLED_NOTE}:

{sections[2]}
"""
    return Outcome("exp4_conditions", md, ["exp4_conditions.csv", "exp4_conditions.png"], tm.seconds,
                   {"trials": trials, **summary})


def main() -> None:
    script_main(run, __doc__)


if __name__ == "__main__":
    main()
