"""Benchmark: CPU time of ssl_core.tracking.Tracker alone, per second of audio.

Detections are made by hand (no localizer): 128 ms windows, two talkers taking turns (one moving at
20 deg/s), each heard in 85 % of its windows with 2 deg noise, plus false detections uniform on the
sphere in 30 % of windows. Prints figures, then one JSON line.
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from _results import add_check_option, finish, require_stored  # noqa: E402
from ssl_core.grid import direction_from_angles  # noqa: E402
from ssl_core.localizer import Detection  # noqa: E402
from ssl_core.tracking import Tracker  # noqa: E402

WINDOW = 0.128


def detection(u: np.ndarray, power: float) -> Detection:
    return Detection(float(np.arctan2(u[1], u[0])), float(np.arcsin(u[2])), u, power, -30.0)


def scenario(seconds: float, seed: int = 0) -> list[list[Detection]]:
    rng = np.random.default_rng(seed)
    windows = []
    for k in range(int(seconds / WINDOW)):
        t = k * WINDOW
        dets = []
        az = (40.0 + 20.0 * t) if int(t // 2.0) % 2 else -100.0
        if rng.random() < 0.85:
            u = direction_from_angles(np.deg2rad(az + rng.normal(0, 2)), np.deg2rad(rng.normal(10, 2)))
            dets.append(detection(u, 0.1))
        if rng.random() < 0.3:
            v = rng.standard_normal(3)
            dets.append(detection(v / np.linalg.norm(v), float(10 ** rng.normal(np.log10(0.022), 0.2))))
        windows.append(dets)
    return windows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=120.0, help="audio seconds simulated (default 120)")
    add_check_option(ap)
    args = ap.parse_args()
    require_stored("tracking", args.check)
    windows = scenario(args.seconds)
    tracker = Tracker()
    n_tracks = []
    c0 = time.process_time()
    for k, dets in enumerate(windows):
        n_tracks.append(len(tracker.update(dets, k * WINDOW)))
    cpu = time.process_time() - c0
    audio = len(windows) * WINDOW
    ms_per_s = 1000 * cpu / audio
    print(f"tracker: {len(windows)} windows ({audio:.0f} s of audio), mean {np.mean(n_tracks):.2f} confirmed tracks, "
          f"{sum(len(d) for d in windows)} detections")
    print(f"CPU {ms_per_s:.2f} ms per second of audio, {1e6 * cpu / len(windows):.0f} us per window")
    figures = {"audio_s": round(audio, 1), "windows": len(windows), "cpu_ms_per_audio_s": round(ms_per_s, 3),
               "cpu_us_per_window": round(1e6 * cpu / len(windows), 1),
               "mean_confirmed_tracks": round(float(np.mean(n_tracks)), 2)}
    return finish("tracking", figures, check=args.check, better={"cpu_ms_per_audio_s": "lower"})


if __name__ == "__main__":
    raise SystemExit(main())
