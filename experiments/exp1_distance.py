"""Experiment 1 (paper Fig. 11): localization error against distance.

Source at azimuth -4 deg, elevation -45 deg, moved from 50 cm to 300 cm in 10 cm steps;
mean squared error of azimuth and elevation per distance over several trials (different
voices, noise, sensor gain errors per seed). The array is raised to 2.4 m so that the
source at 3 m (2.12 m below the array) stays above the floor (0.28 m).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.common import (RESULTS, Lab, Outcome, Timer, Truth, localizer, md_table, record, score,
                                script_main, write_csv)

AZ, EL = -4.0, -45.0
LAB = Lab(array_height_m=2.4)
#: Control: the same geometry 1.2 m higher in a 5 m high room, so the source never comes near the floor.
HIGH = Lab(room_size=(7.0, 6.0, 5.0), array_height_m=3.6)


def run(quick: bool = False, out_dir: Path = RESULTS, seed0: int = 0) -> Outcome:
    distances = np.round(np.arange(0.5, 3.0001, 0.5 if quick else 0.1), 2)
    trials = 2 if quick else 10
    rows = []

    def trials_at(lab: Lab, setup: str, d: float) -> None:
        truth = Truth(AZ, EL, float(d))
        for k in range(trials):
            seed = seed0 + 100 * k + int(round(d * 100))
            res = localizer(1).locate_summed(record(lab, [truth], seed))
            det = res.detections[0] if res.detections else None
            rows.append({"setup": setup, "distance_m": float(d), "trial": k, "seed": seed, **score(det, truth)})

    with Timer() as tm:
        for d in distances:
            trials_at(LAB, "lab", d)
        for d in distances[::5] if not quick else distances[-1:]:
            trials_at(HIGH, "high_room", d)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_csv(out_dir / "exp1_distance.csv", rows)

    def per_distance(setup: str) -> list[dict]:
        out = []
        for d in sorted({x["distance_m"] for x in rows if x["setup"] == setup}):
            r = [x for x in rows if x["distance_m"] == d and x["setup"] == setup]
            az = np.array([x["az_err"] for x in r])
            el = np.array([x["el_err"] for x in r])
            out.append({"d": d, "mse_az": float(np.nanmean(az**2)), "mse_el": float(np.nanmean(el**2)),
                        "sd_az": float(np.nanstd(az)), "sd_el": float(np.nanstd(el)), "mean_az": float(np.nanmean(az)),
                        "mean_el": float(np.nanmean(el)), "miss": int(np.sum(np.isnan(az)))})
        return out

    per_d, per_high = per_distance("lab"), per_distance("high_room")

    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    dd = [p["d"] * 100 for p in per_d]
    ax[0].plot(dd, [p["mse_az"] for p in per_d], "o-", label="azimuth")
    ax[0].plot(dd, [p["mse_el"] for p in per_d], "s-", label="elevation")
    hd = [p["d"] * 100 for p in per_high]
    ax[0].plot(hd, [p["mse_az"] for p in per_high], "o--", color="tab:blue", mfc="none", label="azimuth, 5 m high room")
    ax[0].plot(hd, [p["mse_el"] for p in per_high], "s--", color="tab:orange", mfc="none",
               label="elevation, 5 m high room")
    ax[0].set_xlabel("distance (cm)")
    ax[0].set_ylabel("mean squared error (deg$^2$)")
    ax[0].set_title(f"MSE vs distance ({trials} trials/point)")
    ax[0].grid(alpha=0.3)
    ax[0].legend()
    for key, mk, lab in (("az_err", "o", "azimuth"), ("el_err", "s", "elevation")):
        e = np.array([[x[key] for x in rows if x["distance_m"] == p["d"] and x["setup"] == "lab"] for p in per_d])
        ax[1].errorbar(dd, np.nanmean(e, axis=1), yerr=np.nanstd(e, axis=1), fmt=mk + "-", capsize=2, label=lab)
    ax[1].axhline(0, color="k", lw=0.8)
    ax[1].set_xlabel("distance (cm)")
    ax[1].set_ylabel("error, mean +- sd (deg)")
    ax[1].set_title(f"Signed error (source at az {AZ:g}, el {EL:g} deg)")
    ax[1].grid(alpha=0.3)
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(out_dir / "exp1_distance.png", dpi=110)
    plt.close(fig)

    near = [p for p in per_d if p["d"] <= 1.5]
    far = [p for p in per_d if p["d"] > 1.5]
    table = md_table(["distance (cm)", "MSE az (deg²)", "MSE el (deg²)", "mean az err", "sd az", "mean el err", "sd el",
                      "misses"],
                     [[int(round(p["d"] * 100)), p["mse_az"], p["mse_el"], p["mean_az"], p["sd_az"], p["mean_el"],
                       p["sd_el"], p["miss"]] for p in per_d])
    trend = (f"Mean MSE over 50-150 cm: azimuth {np.mean([p['mse_az'] for p in near]):.1f} deg², elevation "
             f"{np.mean([p['mse_el'] for p in near]):.1f} deg²; over 160-300 cm: azimuth "
             f"{np.mean([p['mse_az'] for p in far]):.1f} deg², elevation {np.mean([p['mse_el'] for p in far]):.1f} deg².")
    high = md_table(["distance (cm)", "MSE az (deg²)", "MSE el (deg²)", "mean el err", "sd el"],
                    [[int(round(p["d"] * 100)), p["mse_az"], p["mse_el"], p["mean_el"], p["sd_el"]] for p in per_high])
    md = f"""### 1. Error against distance (paper Fig. 11)

Set-up: {LAB.describe()}. Source at azimuth {AZ:g} deg, elevation {EL:g} deg, 50-300 cm
({'quick: 50 cm steps' if quick else '10 cm steps'}), {trials} trials per distance (seeds vary voice, noise and
sensor gains). The array is raised to {LAB.array_height_m} m so that the farthest source (2.12 m below it) stays
above the floor.

![distance]({'exp1_distance.png'})

Paper: Fig. 11 shows the azimuth MSE growing gradually with distance (no numbers are given in the text); the
authors attribute it to microphone sensitivity. Ours: {trend}

{table}

Why the elevation error grows beyond 2 m here: at el = -45 deg the far source nears the floor (0.28 m above it at
3 m), and the floor reflection arrives a few samples after the direct sound from a nearby direction, pulling the
peak down. Control run - the same geometry 1.2 m higher in a 5 m high room ({HIGH.describe()}), where the source
stays >= 1.5 m above the floor:

{high}
"""
    return Outcome("exp1_distance", md, ["exp1_distance.csv", "exp1_distance.png"], tm.seconds,
                   {"per_distance": per_d, "trials": trials})


def main() -> None:
    script_main(run, __doc__)


if __name__ == "__main__":
    main()
