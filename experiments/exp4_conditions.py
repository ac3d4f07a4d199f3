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

import argparse
from pathlib import Path

import numpy as np

from experiments.common import (LOCALIZER_NOTE, POOLED_NOTE, RESULTS, Lab, Outcome, Timer, Truth, build_sim,
                                localizer, match, md_table, pooled_localize, record, write_csv)

LAB = Lab(array_height_m=1.5, noise_spectrum="hvac")
FOUND_DEG = 10.0


def random_truths(rng: np.random.Generator, n: int, min_sep_deg: float = 30.0) -> list[Truth]:
    out: list[Truth] = []
    while len(out) < n:
        t = Truth(float(rng.uniform(-180, 180)), float(rng.uniform(-30, 60)), float(rng.uniform(1.2, 2.5)))
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


def trial(truths: list[Truth], seed: int, rt60_s: float, noise_db: float | None = None, lab: Lab = LAB,
          pooled: bool = False) -> list[dict]:
    """Errors of one trial: the summed-map estimate, and with ``pooled`` also the pooled per-window one."""
    x = record(lab, truths, seed, noise_db_spl=noise_db, rt60_s=rt60_s)
    methods = [("map", localizer(len(truths)).locate(x).detections)]
    if pooled:
        methods.append(("pooled", pooled_localize(x, len(truths))))
    return [{"method": m, "ang_err": e, "found": bool(e < FOUND_DEG)}
            for m, dets in methods for _, _, e in match(dets, truths)]


def _stats(errs: list[float]) -> dict:
    e = np.asarray(errs, float)
    fin = e[np.isfinite(e)]
    return {"median": float(np.median(fin)) if fin.size else np.nan, "mean": float(np.mean(fin)) if fin.size else np.nan,
            "p90": float(np.percentile(fin, 90)) if fin.size else np.nan,
            "found": float(np.mean(e < FOUND_DEG)), "n": int(e.size)}


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
                for r in trial(t, seed, rt):
                    rows.append({"sweep": "rt60", "value": rt, "trial": k, "seed": seed, **r})
        snr_lab = Lab(array_height_m=LAB.array_height_m, noise_spectrum="pink")
        for k in range(trials):
            seed = seed0 + 7919 * k + 23
            t = random_truths(np.random.default_rng(seed), 1)
            sig_db = received_level_db(snr_lab, t, seed, snr_lab.rt60_s)
            for snr in snrs:
                for r in trial(t, seed, snr_lab.rt60_s, noise_db=sig_db - snr, lab=snr_lab):
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

    fig, axs = plt.subplots(1, 3, figsize=(16, 4.5))
    summary = {}
    def errs(sweep, v, method="map"):
        return [r["ang_err"] for r in rows if r["sweep"] == sweep and r["value"] == float(v) and r["method"] == method]

    for ax, sweep, xs, xlabel in ((axs[0], "rt60", rt60s, "RT60 (s)"), (axs[1], "snr", snrs, "SNR at the array (dB)"),
                                  (axs[2], "talkers", counts, "simultaneous talkers")):
        st = [_stats(errs(sweep, v)) for v in xs]
        summary[sweep] = {str(v): s for v, s in zip(xs, st)}
        pos = np.arange(1, len(xs) + 1, dtype=float)
        methods = ("map", "pooled") if sweep == "talkers" else ("map",)
        for mi, method in enumerate(methods):
            off = (mi - (len(methods) - 1) / 2) * 0.3
            data = [np.clip(errs(sweep, v, method), 0, 180) for v in xs]
            bp = ax.boxplot(data, positions=pos + off, widths=0.25 if len(methods) > 1 else 0.5, showfliers=True,
                            patch_artist=True)
            for b in bp["boxes"]:
                b.set_facecolor("tab:blue" if method == "map" else "tab:orange")
                b.set_alpha(0.5)
            found = [100 * _stats(errs(sweep, v, method))["found"] for v in xs]
            if sweep == "talkers":
                summary.setdefault("talkers_" + method, {}).update(
                    {str(v): _stats(errs(sweep, v, method)) for v in xs})
            ax2 = ax.twinx() if mi == 0 else ax2
            ax2.plot(pos + off, found, ".-", color="red" if method == "map" else "darkred",
                     label=f"{method}: found" if sweep == "talkers" else None)
        ax.set_xticks(pos, [f"{v:g}" for v in xs])
        ax.set_yscale("symlog", linthresh=2.0)
        ax.set_ylabel("angular error (deg)")
        ax.set_xlabel(xlabel)
        ax2.set_ylim(0, 105)
        ax2.set_ylabel(f"found within {FOUND_DEG:g} deg (%)", color="r")
        if sweep == "talkers":
            ax2.legend(loc="center right", fontsize=8)
        ax.grid(alpha=0.3)
    axs[0].set_title(f"Error vs reverberation ({LAB.noise_db_spl:g} dB SPL noise)")
    axs[1].set_title(f"Error vs SNR (RT60 {LAB.rt60_s:g} s, pink diffuse noise)")
    axs[2].set_title(f"Error vs talkers (blue: summed map, orange: pooled windows)")
    fig.tight_layout()
    fig.savefig(out_dir / "exp4_conditions.png", dpi=110)
    plt.close(fig)

    sections = []
    for sweep, xs, name in (("rt60", rt60s, "RT60 (s)"), ("snr", snrs, "SNR (dB)")):
        sections.append(md_table([name, "median err (deg)", "mean err", "90th pct", f"found < {FOUND_DEG:g} deg", "n"],
                                 [[v, s["median"], s["mean"], s["p90"], f"{100 * s['found']:.0f}%", s["n"]]
                                  for v, s in ((v, summary[sweep][str(v)]) for v in xs)]))
    sections.append(md_table(["talkers", "method", "median err (deg)", "mean err", "90th pct", f"found < {FOUND_DEG:g} deg",
                              "n"],
                             [[v, m, s["median"], s["mean"], s["p90"], f"{100 * s['found']:.0f}%", s["n"]]
                              for v in counts for m in ("map", "pooled")
                              for s in (summary["talkers_" + m][str(v)],)]))
    md = f"""### 4. Beyond the paper: reverberation, noise, number of talkers

Set-up: {LAB.describe()} (RT60 and noise changed per sweep as stated). Random directions per trial (azimuth uniform,
elevation -30..60 deg, 1.2-2.5 m). Localizer: {LOCALIZER_NOTE}. {trials} trials per point; errors are great-circle
angles; "found" = matched within {FOUND_DEG:g} deg. SNR = broadband level of the received source signal (direct +
reverberant, while sounding) over the diffuse noise level at the array.

![conditions](exp4_conditions.png)

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
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out", type=Path, default=RESULTS)
    a = ap.parse_args()
    print(run(a.quick, a.out).markdown)


if __name__ == "__main__":
    main()
