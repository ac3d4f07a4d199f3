"""Benchmark: CPU cost of the ego-noise suppression and of tracking with motion compensation, per second of
audio heard while driving.

Audio: the simulated robot drives sideways at 0.2 m/s past the paper_lab caller with its motors audible
(``ssl_sim`` defaults), 10 s recorded once with the wheel speeds and array poses of every 128 ms block. Timed
(CPU, ``time.process_time``, ``--repeats`` interleaved runs; costs as the median of paired differences): the streaming localizer (the scenario's settings, tracking
gate) without and with :class:`ssl_core.ego_noise.EgoNoiseSuppressor` (the template from a simulated
calibration run), and the tracker fed with rotation and translation between windows. Prints figures, then
one JSON line; writes ``benchmarks/results/bench_ego_noise.json``.
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from dataclasses import replace  # noqa: E402

import numpy as np  # noqa: E402

from _results import write_result  # noqa: E402
from robot.ego_calibration import MotorMount, calibrate_ego_noise  # noqa: E402
from ssl_core.ego_noise import EgoNoiseSuppressor  # noqa: E402
from ssl_core.geometry import cube8  # noqa: E402
from ssl_core.localizer import Localizer  # noqa: E402
from ssl_core.tracking import TRACKING_MIN_SIGNIFICANCE, Tracker  # noqa: E402
from ssl_sim.backends import make_sim_hal  # noqa: E402
from ssl_sim.scenario import load_scenario  # noqa: E402

BLOCK = 2048


def record(seconds: float):
    sc = load_scenario("paper_lab")
    world = replace(sc.world(1), robot_start=(3.0, 4.0, 0.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cal = make_sim_hal(sc.world(1), sources=[], acoustic_config=sc.acoustic_config(100))
        template = calibrate_ego_noise(cal.drive, cal.audio, cal.clock, record_s=1.0, settle_s=0.4)
        cal.close()
        hal = make_sim_hal(world, sources=sc.sources(world, 1), acoustic_config=sc.acoustic_config(1))
    hal.drive.set_twist(0.0, -0.2, 0.0)
    hal.audio.read(8000)
    blocks = []
    for _ in range(int(seconds * 16000 / BLOCK)):
        w = hal.drive.odometry().wheel_speeds
        b = hal.audio.read(BLOCK)
        blocks.append((b.samples.astype(np.float32), w, hal.audio.last_array_poses[-1]))
    hal.close()
    return sc, template, blocks


def run(sc, sup, blocks, track: bool) -> float:
    loc = Localizer(cube8(), replace(sc.localizer, min_significance=TRACKING_MIN_SIGNIFICANCE), ego_noise=sup)
    tracker = Tracker()
    prev = blocks[0][2]
    t0 = time.process_time()
    for x, w, (o, r) in blocks:
        for res in loc.process(x, 16000, wheel_speeds=w):
            if track:
                tracker.update(res.detections, res.time, rotation=r.T @ prev[1], translation=r.T @ (o - prev[0]))
            prev = (o, r)
    return time.process_time() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    sc, template, blocks = record(args.seconds)
    audio_s = len(blocks) * BLOCK / 16000
    sup = EgoNoiseSuppressor(cube8(), MotorMount().suppression_config(), template)
    runs = {"localizer": [], "localizer_suppressed": [], "localizer_suppressed_tracked": []}
    for _ in range(args.repeats):  # interleaved, so a change of the machine's load hits all three alike
        for name, s, track in (("localizer", None, False), ("localizer_suppressed", sup, False),
                               ("localizer_suppressed_tracked", sup, True)):
            runs[name].append(run(sc, s, blocks, track) / audio_s * 1e3)
    r = {k: np.array(v) for k, v in runs.items()}
    # paired differences of the same repeat, their median (the load of a shared machine drifts between repeats)
    figures = {"localizer_ms_cpu_per_s": round(float(r["localizer"].min()), 2),
               "localizer_suppressed_tracked_ms_cpu_per_s": round(float(r["localizer_suppressed_tracked"].min()), 2),
               "suppression_ms_cpu_per_s": round(float(np.median(r["localizer_suppressed"] - r["localizer"])), 2),
               "tracking_ms_cpu_per_s": round(float(np.median(r["localizer_suppressed_tracked"]
                                                              - r["localizer_suppressed"])), 2),
               "suppression_plus_tracking_ms_cpu_per_s": round(float(np.median(r["localizer_suppressed_tracked"]
                                                                               - r["localizer"])), 2)}
    for k, v in figures.items():
        print(f"{k}: {v}")
    write_result("bench_ego_noise", figures)
    print(json.dumps({"benchmark": "bench_ego_noise", **figures}))


if __name__ == "__main__":
    main()
