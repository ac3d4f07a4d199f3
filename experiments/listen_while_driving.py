"""What listening while driving costs, and what the ego-noise suppression wins back: localization error of
one 1 s block heard while the robot drives sideways past the paper's caller, against driving speed, with the
motors silent, with their noise and no suppression, and with each suppression method of
:mod:`ssl_core.ego_noise` alone and together.

Set-up: ``ssl_sim/scenarios/paper_lab.toml`` (empty lab, RT60 0.5 s, 30 dB SPL ambient, caller 1.5 m ahead at
-4 deg calling continuously at 62.5 dB SPL at 1 m); the MuJoCo robot accelerates for 0.5 s, then the
next 1 s of audio is localized (``ssl_core`` Localizer, the scenario's settings, one source). Truth: the
caller's direction in the array frame at the middle of the block. Speeds: body twist (0, v, 0)
(sideways, so the caller stays ahead), alternating left/right over the seeds. Ego-noise:
``ssl_sim.acoustics.ego_noise`` defaults (on) or a silent drive (off). Suppression: motor positions from
``robot.ego_calibration.MotorMount`` (the robot's layout, not the simulator's); "cone": the search skips
directions within 30 deg of a motor while the wheels turn; "lag mask": each motor's near-field TDOAs are
zeroed in every pair's GCC; "template": the spectral bin weights, the template from
``robot.ego_calibration.calibrate_ego_noise`` run first in the same room with the caller silent (another
acoustic seed), wheel speeds from the drive's encoders (mean of the readings before and after the block).
Controls on the silent drive's block: "motors silent, template + cone" weighs it as if the motors sounded, so the
processing's own effect shows apart from the motors' residue; the two bands localize it in the lower or the upper
part of the voice band only.

Two tables: the azimuth error, and the signed elevation error (detection - truth; negative: read low).

Writes ``results/listen_while_driving.{csv,md}``. Run: ``python -m experiments.listen_while_driving
[--seeds 6]``.
"""
from __future__ import annotations

import argparse
import csv
import math
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from robot.ego_calibration import MotorMount, calibrate_ego_noise
from ssl_core.ego_noise import EgoNoiseSuppressor, EgoNoiseTemplate
from ssl_core.geometry import cube8
from ssl_core.localizer import Localizer
from ssl_sim.acoustics.ego_noise import EgoNoiseConfig
from ssl_sim.backends import array_frame_directions, make_sim_hal
from ssl_sim.scenario import load_scenario

RESULTS = Path(__file__).resolve().parent / "results"
SPEEDS = (0.0, 0.1, 0.2, 0.3)  # m/s (0.3 = EnvConfig.max_speed)
#: (label, motors audible, suppression methods)
MODES = (("motors silent", False, None), ("motors on, no suppression", True, None),
         ("spatial: lag mask + cone", True, "spatial"), ("spectral: template", True, "spectral"),
         ("template + cone (default)", True, "default"), ("template + lag mask + cone", True, "all"),
         ("motors silent, template + cone", False, "default"), ("motors silent, 300-3000 Hz", False, None),
         ("motors silent, 2000-6000 Hz", False, None))
#: controls that localize with the scenario's localizer in another band (Hz)
BANDS = {"motors silent, 300-3000 Hz": (300.0, 3000.0), "motors silent, 2000-6000 Hz": (2000.0, 6000.0)}
CALIBRATION_SEED = 100


def calibrate(seed: int = CALIBRATION_SEED) -> EgoNoiseTemplate:
    """The drive's template, recorded in the scenario's room with nobody calling."""
    sc = load_scenario("paper_lab")
    world = sc.world(sc.seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hal = make_sim_hal(world, sources=[], acoustic_config=sc.acoustic_config(seed))
    try:
        return calibrate_ego_noise(hal.drive, hal.audio, hal.clock)
    finally:
        hal.close()


def suppressor(method: str | None, template: EgoNoiseTemplate) -> EgoNoiseSuppressor | None:
    if method is None:
        return None
    kw = {"spatial": dict(spatial=True, spectral=False), "spectral": dict(spatial=False, exclude_deg=0.0),
          "default": {}, "all": dict(spatial=True)}[method]
    cfg = MotorMount().suppression_config(**kw)
    return EgoNoiseSuppressor(cube8(), cfg, template)


def trial(speed: float, ego: bool, seed: int, methods: dict[str, EgoNoiseSuppressor | None]) -> list[dict]:
    """One drive; the same block localized by each suppression of ``methods`` (label -> suppressor)."""
    sc = load_scenario("paper_lab")
    world = sc.world(seed)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        hal = make_sim_hal(world, sources=sc.sources(world, seed), acoustic_config=sc.acoustic_config(seed),
                           ego_noise=EgoNoiseConfig() if ego else None)
    side = 1.0 if seed % 2 == 0 else -1.0
    hal.robot.set_twist(0.0, side * speed, 0.0)
    hal.audio.read(8000)  # 0.5 s: accelerate
    w0 = hal.drive.odometry().wheel_speeds
    block = hal.audio.read(16000)
    wheels = 0.5 * (w0 + hal.drive.odometry().wheel_speeds)
    poses = hal.audio.last_array_poses
    origin, rot = poses[len(poses) // 2]
    az, el, _ = array_frame_directions(origin, rot, np.asarray(world.victims[0].position)[None])
    moved = float(np.linalg.norm(poses[-1][0] - poses[0][0]))
    hal.close()
    rows = []
    for label, sup in methods.items():
        cfg = replace(sc.localizer, band_hz=BANDS[label]) if label in BANDS else sc.localizer
        res = Localizer(cube8(), cfg, ego_noise=sup).locate(block.samples, block.sample_rate, wheel_speeds=wheels)
        row = {"speed": speed, "mode": label, "seed": seed, "moved_m": moved, "detected": int(bool(res.detections)),
               "az_err_deg": float("nan"), "el_signed_err_deg": float("nan")}
        if res.detections:
            d = res.detections[0]
            row["az_err_deg"] = abs((math.degrees(d.azimuth - az[0]) + 180) % 360 - 180)
            row["el_signed_err_deg"] = math.degrees(d.elevation - el[0])
        rows.append(row)
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=6, help="trials per speed and ego-noise setting")
    ap.add_argument("--out", default=str(RESULTS), help="output directory")
    args = ap.parse_args(argv)
    from tqdm import tqdm

    template = calibrate()
    sups = {audible: {label: suppressor(m, template) for label, e, m in MODES if e == audible}
            for audible in (False, True)}
    rows = []
    for v, s in tqdm([(v, s) for v in SPEEDS for s in range(args.seeds)], desc="listen while driving", unit="trial"):
        rows += trial(v, False, s, sups[False])
        rows += trial(v, True, s, sups[True])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "listen_while_driving.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    header = ["| speed (m/s) | array moved (m) | " + " | ".join(m[0] for m in MODES) + " |",
              "|---|---|" + "---|" * len(MODES)]
    lines = ["# Listening while driving (paper_lab caller, 1 s blocks)", "",
             f"{args.seeds} trials per cell (seeds 0..{args.seeds - 1}, sideways left/right alternating). Suppression: "
             "ssl_core.ego_noise with the template of a simulated calibration run (robot.ego_calibration). The last "
             "three columns are controls on the silent drive's block: weighed as if the motors sounded, and localized "
             "in the lower or the upper part of the voice band only.", "",
             "Median / max azimuth error of the strongest detection (deg), detections / trials:", "", *header]
    elevation = ["", "Signed elevation error of the strongest detection (deg, detection - truth; negative: read low), "
                 "mean / median:", "", *header]
    for v in SPEEDS:
        cells, el_cells = [], []
        for label, _, _ in MODES:
            r = [x for x in rows if x["speed"] == v and x["mode"] == label]
            err = np.array([x["az_err_deg"] for x in r if x["detected"]])
            el = np.array([x["el_signed_err_deg"] for x in r if x["detected"]])
            cells.append((f"{np.median(err):.1f} / {np.max(err):.1f}" if err.size else "-")
                         + f" ({sum(x['detected'] for x in r)}/{len(r)})")
            el_cells.append(f"{np.mean(el):+.1f} / {np.median(el):+.1f}" if el.size else "-")
        moved = np.median([x["moved_m"] for x in rows if x["speed"] == v])
        lines.append(f"| {v:.1f} | {moved:.2f} | " + " | ".join(cells) + " |")
        elevation.append(f"| {v:.1f} | {moved:.2f} | " + " | ".join(el_cells) + " |")
    lines += elevation
    (out / "listen_while_driving.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
