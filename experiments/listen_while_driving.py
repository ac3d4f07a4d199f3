"""What listening while driving costs: localization error of one 1 s block heard while the robot drives
sideways past the paper's caller, against driving speed, with and without the robot's own motor noise.

Set-up: ``ssl_sim/scenarios/paper_lab.toml`` (empty lab, RT60 0.5 s, 30 dB SPL ambient, caller 1.5 m ahead at
-4 deg calling continuously at 62.5 dB SPL at 1 m); the MuJoCo robot accelerates for 0.5 s, then the
next 1 s of audio is localized (``ssl_core`` Localizer, the scenario's settings, one source). Truth: the
caller's direction in the array frame at the middle of the block. Speeds: body twist (0, v, 0)
(sideways, so the caller stays ahead), alternating left/right over the seeds. Ego-noise:
``ssl_sim.acoustics.ego_noise`` defaults (on) or a silent drive (off): the difference is what the motors
cost; the rest is the motion itself (the array moves 0-0.3 m during the block).

Writes ``results/listen_while_driving.{csv,md}``. Run: ``python -m experiments.listen_while_driving
[--seeds 6]``.
"""
from __future__ import annotations

import argparse
import csv
import math
import warnings
from pathlib import Path

import numpy as np

from ssl_core.geometry import cube8
from ssl_core.localizer import Localizer
from ssl_sim.acoustics.ego_noise import EgoNoiseConfig
from ssl_sim.backends import array_frame_directions, make_sim_hal
from ssl_sim.scenario import load_scenario

RESULTS = Path(__file__).resolve().parent / "results"
SPEEDS = (0.0, 0.1, 0.2, 0.3)  # m/s (0.3 = EnvConfig.max_speed)


def trial(speed: float, ego: bool, seed: int) -> dict:
    sc = load_scenario("paper_lab")
    world = sc.world(seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hal = make_sim_hal(world, sources=sc.sources(world, seed), acoustic_config=sc.acoustic_config(seed),
                           ego_noise=EgoNoiseConfig() if ego else None)
    side = 1.0 if seed % 2 == 0 else -1.0
    hal.robot.set_twist(0.0, side * speed, 0.0)
    hal.audio.read(8000)  # 0.5 s: accelerate
    block = hal.audio.read(16000)
    poses = hal.audio.last_array_poses
    origin, rot = poses[len(poses) // 2]
    az, el, _ = array_frame_directions(origin, rot, np.asarray(world.victims[0].position)[None])
    moved = float(np.linalg.norm(poses[-1][0] - poses[0][0]))
    res = Localizer(cube8(), sc.localizer).locate(block.samples, block.sample_rate)
    hal.close()
    if not res.detections:
        return {"speed": speed, "ego": ego, "seed": seed, "moved_m": moved, "detected": 0,
                "az_err_deg": float("nan"), "el_err_deg": float("nan")}
    d = res.detections[0]
    return {"speed": speed, "ego": ego, "seed": seed, "moved_m": moved, "detected": 1,
            "az_err_deg": abs((math.degrees(d.azimuth - az[0]) + 180) % 360 - 180),
            "el_err_deg": abs(math.degrees(d.elevation - el[0]))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=6, help="trials per speed and ego-noise setting")
    ap.add_argument("--out", default=str(RESULTS), help="output directory")
    args = ap.parse_args(argv)
    from tqdm import tqdm

    cases = [(v, e, s) for v in SPEEDS for e in (False, True) for s in range(args.seeds)]
    rows = [trial(v, e, s) for v, e, s in tqdm(cases, desc="listen while driving", unit="trial")]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "listen_while_driving.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    lines = ["# Listening while driving (paper_lab caller, 1 s blocks)", "",
             f"{args.seeds} trials per cell (seeds 0..{args.seeds - 1}, sideways left/right alternating); "
             "median / max azimuth error of the strongest detection (deg), detection rate.", "",
             "| speed (m/s) | array moved (m) | motors silent: az err median / max | detected | "
             "motors on: az err median / max | detected |", "|---|---|---|---|---|---|"]
    for v in SPEEDS:
        cells = []
        for e in (False, True):
            r = [x for x in rows if x["speed"] == v and x["ego"] == e]
            err = np.array([x["az_err_deg"] for x in r if x["detected"]])
            cells.append(f"{np.median(err):.1f} / {np.max(err):.1f}" if err.size else "-")
            cells.append(f"{sum(x['detected'] for x in r)}/{len(r)}")
        moved = np.median([x["moved_m"] for x in rows if x["speed"] == v])
        lines.append(f"| {v:.1f} | {moved:.2f} | " + " | ".join(cells) + " |")
    (out / "listen_while_driving.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
