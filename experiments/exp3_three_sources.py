"""Experiment 3 (paper Fig. 12 / Fig. 17 text): three simultaneous sources at 200 cm.

Sources at (az, el) = (-135, 35), (90, 75), (145, 60) deg, all talking at once (three
different synthetic voices, 62.5 dB SPL each at 1 m). The SRP-PHAT power over the whole
sphere is drawn as a heat map and a surface with the three strongest peaks marked; the
measured directions are set beside the true ones and the paper's. Two estimates per trial:
``map`` - the three strongest peaks of the SRP map summed over the whole recording (the
paper's method); ``pooled`` - per-window peaks pooled into a direction density (see
``experiments.common.pooled_localize``). The array stands at
1.2 m (the 75 deg source is then 3.13 m high, under the 3.5 m ceiling).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.common import (
    LOCALIZER_NOTE, POOLED_NOTE, RESULTS, Lab, Outcome, Timer, Truth, localizer, match,
                                md_table, pooled_localize, record, score, write_csv, script_main)

TRUTHS = [Truth(-135.0, 35.0, 2.0), Truth(90.0, 75.0, 2.0), Truth(145.0, 60.0, 2.0)]
PAPER = [(-130.0, 32.0), (87.0, 73.0), (144.0, 60.0)]
LAB = Lab(array_height_m=1.2)


def paper_angular_errors() -> list[float]:
    """Great-circle error (deg) of each source as the paper measured it."""
    return [float(np.rad2deg(np.arccos(np.clip(t.direction @ Truth(a, e, 1.0).direction, -1, 1))))
            for t, (a, e) in zip(TRUTHS, PAPER)]


def srp_map_image(loc, x, n_az: int = 361, n_el: int = 181):
    """Fine-grid SRP power resampled onto a regular (el, az) image for plotting (nearest grid point)."""
    from scipy.spatial import cKDTree

    p = loc.srp_fine(loc.window_gcc(x))
    az = np.linspace(-np.pi, np.pi, n_az)
    el = np.linspace(-np.pi / 2, np.pi / 2, n_el)
    A, E = np.meshgrid(az, el)
    u = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], axis=-1)
    _, idx = cKDTree(loc.fine_grid.directions).query(u.reshape(-1, 3))
    return np.rad2deg(az), np.rad2deg(el), p[idx].reshape(E.shape)


def run(quick: bool = False, out_dir: Path = RESULTS, seed0: int = 0) -> Outcome:
    trials = 2 if quick else 10
    loc = localizer(3)
    rows, first_x, first_pooled = [], None, None
    with Timer() as tm:
        for k in range(trials):
            seed = seed0 + 31 * k + 3
            x = record(LAB, TRUTHS, seed)
            pooled = pooled_localize(x, 3)
            if first_x is None:
                first_x, first_pooled = x, pooled
            for method, dets in (("map", loc.locate(x).detections), ("pooled", pooled)):
                for i, (t, det, _) in enumerate(match(dets, TRUTHS)):
                    rows.append({"method": method, "trial": k, "seed": seed, "source": i + 1, "az_true": t.azimuth_deg,
                                 "el_true": t.elevation_deg, **score(det, t)})
    out_dir.mkdir(parents=True, exist_ok=True)
    write_csv(out_dir / "exp3_three_sources.csv", rows)

    import matplotlib.pyplot as plt

    az, el, img = srp_map_image(loc, first_x)
    res0 = loc.locate(first_x)
    fig = plt.figure(figsize=(14, 5.5))
    ax = fig.add_subplot(1, 2, 1)
    im = ax.pcolormesh(az, el, img, shading="auto", cmap="viridis")
    fig.colorbar(im, ax=ax, label="SRP-PHAT power (normalised)")
    for i, t in enumerate(TRUTHS):
        ax.plot(t.azimuth_deg, t.elevation_deg, "w+", ms=14, mew=2, label="true" if i == 0 else None)
        ax.plot(*PAPER[i], "rx", ms=10, mew=2, label="paper measured" if i == 0 else None)
    for i, d in enumerate(res0.detections):
        ax.plot(np.rad2deg(d.azimuth), np.rad2deg(d.elevation), "o", mfc="none", mec="orange", ms=14, mew=2,
                label="ours: 3 strongest map peaks" if i == 0 else None)
    for i, d in enumerate(first_pooled):
        ax.plot(np.rad2deg(d.azimuth), np.rad2deg(d.elevation), "s", mfc="none", mec="magenta", ms=10, mew=2,
                label="ours: pooled per-window peaks" if i == 0 else None)
    ax.set_xlabel("azimuth (deg)")
    ax.set_ylabel("elevation (deg)")
    ax.set_title("SRP-PHAT map, three simultaneous talkers at 2 m (trial 0)")
    # Below the axes: inside, the legend hid the spurious third map peak (lower left in trial 0).
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, fontsize=8, facecolor="0.6")  # grey: white "+" shows
    ax3 = fig.add_subplot(1, 2, 2, projection="3d")
    A, E = np.meshgrid(az[::3], el[::3])
    ax3.plot_surface(A, E, img[::3, ::3], cmap="viridis", linewidth=0, antialiased=True)
    ax3.set_xlabel("azimuth (deg)")
    ax3.set_ylabel("elevation (deg)")
    ax3.set_zlabel("power")
    ax3.set_title("Surface plot (cf. paper Fig. 12)")
    fig.tight_layout()
    fig.savefig(out_dir / "exp3_three_sources.png", dpi=110)
    plt.close(fig)

    trows = []
    summary = {"trials": trials}
    for method in ("map", "pooled"):
        for i, t in enumerate(TRUTHS):
            r = [x for x in rows if x["source"] == i + 1 and x["method"] == method]
            az_m, el_m = np.array([x["az_meas"] for x in r]), np.array([x["el_meas"] for x in r])
            ang = np.array([x["ang_err"] for x in r])
            trows.append([method, i + 1, t.azimuth_deg, t.elevation_deg, PAPER[i][0], PAPER[i][1],
                          f"{np.nanmean(az_m):.1f} ± {np.nanstd(az_m):.1f}", f"{np.nanmean(el_m):.1f} ± {np.nanstd(el_m):.1f}",
                          float(np.nanmedian(ang)), f"{int(np.sum(ang < 10))}/{len(r)}"])
        ang_all = np.array([x["ang_err"] for x in rows if x["method"] == method])
        summary[method] = {"median_ang_err": float(np.nanmedian(ang_all)), "found_within_10": int(np.sum(ang_all < 10)),
                           "n": int(ang_all.size)}
    table = md_table(["method", "source", "true az", "true el", "paper az", "paper el", "ours az (mean ± sd)",
                      "ours el (mean ± sd)", "ours median angular err", "found within 10 deg"], trows)
    sm, sp = summary["map"], summary["pooled"]
    md = f"""### 3. Three simultaneous sources at 200 cm (paper Fig. 12)

Set-up: {LAB.describe()}; three different voices at once. Localizer: {LOCALIZER_NOTE}. Second estimate
("pooled"): {POOLED_NOTE}. {trials} trials.

![three sources](exp3_three_sources.png)

{table}

Detections are matched to the true sources by minimum total angular error (Hungarian assignment). Whole-recording
map peaks: {sm['found_within_10']}/{sm['n']} source-trials within 10 deg (median error {sm['median_ang_err']:.1f} deg) -
sources 2 (90, 75) and 3 (145, 60) are only 24 deg apart and merge into one lobe of the summed map, so the third peak
is often a spurious one. Pooled per-window peaks: {sp['found_within_10']}/{sp['n']} within 10 deg (median
{sp['median_ang_err']:.1f} deg): in short windows one talker usually dominates, so the talkers separate.
Azimuth near the zenith (source 2 at el 75 deg) is poorly conditioned; the angular error column is the fair measure.
"""
    return Outcome("exp3_three_sources", md, ["exp3_three_sources.csv", "exp3_three_sources.png"], tm.seconds, summary)


def main() -> None:
    script_main(run, __doc__)


if __name__ == "__main__":
    main()
