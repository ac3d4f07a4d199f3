"""Benchmark: CPU cost of the microphone health monitor (ssl_core.health) against the localizer it guards.

A healthy 8-channel talker recording (pyroomacoustics room, RT60 0.4 s, SNR 20 dB) streamed in 100 ms blocks
through ``MicHealth`` (one analysis of 1 s every 0.5 s) and through the default ``Localizer``, one core,
CPU time (``time.process_time``). Then the same with a swapped pair (the monitor's costliest path: the
28 exchange hypotheses are fitted). Prints CPU ms per second of audio, then one JSON line.
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from signals import room_talker  # noqa: E402

from _results import add_check_option, finish, require_stored  # noqa: E402
from ssl_core.geometry import cube8  # noqa: E402
from ssl_core.grid import direction_from_angles  # noqa: E402
from ssl_core.health import MicHealth  # noqa: E402
from ssl_core.localizer import Localizer, LocalizerConfig  # noqa: E402

FS = 16000
BLOCK = FS // 10


def cpu_ms_per_s(feed, x: np.ndarray) -> float:
    t = time.process_time()
    for k in range(0, x.shape[1], BLOCK):
        feed(x[:, k:k + BLOCK])
    return 1e3 * (time.process_time() - t) / (x.shape[1] / FS)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=10.0)
    add_check_option(ap)
    a = ap.parse_args()
    require_stored("health", a.check)
    x = room_talker(cube8().positions, direction_from_angles(0.5, 0.2), a.seconds, FS, seed=1)
    healthy = cpu_ms_per_s(MicHealth(cube8(), devices=[0] * 4 + [1] * 4).update, x)
    swapped = cpu_ms_per_s(MicHealth(cube8(), devices=[0] * 4 + [1] * 4).update, x[[0, 1, 2, 6, 4, 5, 3, 7]])
    loc = cpu_ms_per_s(Localizer(cube8(), LocalizerConfig()).process, x)
    print(f"CPU ms per s of audio ({a.seconds:g} s, one core): health monitor {healthy:.1f} (healthy array), "
          f"{swapped:.1f} (swapped pair); localizer {loc:.1f}")
    figures = {"seconds": a.seconds, "health_cpu_ms_per_s": round(healthy, 2),
               "health_swapped_cpu_ms_per_s": round(swapped, 2), "localizer_cpu_ms_per_s": round(loc, 2)}
    return finish("health", figures, check=a.check,
                  better={"health_cpu_ms_per_s": "lower", "health_swapped_cpu_ms_per_s": "lower"})


if __name__ == "__main__":
    raise SystemExit(main())
