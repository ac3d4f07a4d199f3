"""CPU of the robot's hearing chain per second of audio: what the rescue loop runs on every listen.

The chain is ``robot.listening.Listener.listen``: SRP-PHAT localization (``ssl_core.localizer``, the shipped
scenarios' localizer settings), the voice evidence of every detection (MPDR beams and the Silero VAD), the voice
scan when the strongest detection carries no voice, and the tracker across listens (``ssl_core.tracking``).
Audio: the lab of ``experiments.common`` (7 x 6 x 3.5 m, RT60 0.5 s, diffuse HVAC noise 35 dB SPL), 1, 2 or 4
talkers calling near-continuously 2 m from the array, 90 deg apart, rendered once before timing (the acoustic
simulation is not part of the chain). One-second listens from a standing robot, one BLAS thread.

Prints a table and one JSON line. Run: ``.venv/bin/python benchmarks/bench_listen.py [--listens 20]``.
Target: the chain for 4 talkers <= 25 ms CPU per second of audio on one core (a Raspberry Pi 4, about 4x slower
per core, then keeps real time with margin).
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))   # experiments.common from a checkout
from _results import add_check_option, finish, load_avg, require_stored  # noqa: E402
from experiments.common import Lab, Truth, build_sim  # noqa: E402
from robot.hal import AudioBlock, AudioSource, ManualClock  # noqa: E402
from robot.listening import Listener  # noqa: E402
from ssl_core.geometry import cube8  # noqa: E402
from ssl_core.localizer import Localizer  # noqa: E402
from ssl_sim.scenario import load_scenario  # noqa: E402

TALKERS = (1, 2, 4)


class _Recording(AudioSource):
    """A pre-rendered (8, n) int16 recording read block after block (the clock is the caller's)."""

    def __init__(self, samples: np.ndarray, fs: int) -> None:
        self.samples, self.fs, self.pos = samples, fs, 0

    @property
    def sample_rate(self) -> int:
        return self.fs

    @property
    def n_channels(self) -> int:
        return self.samples.shape[0]

    def read(self, n_samples: int) -> AudioBlock:
        a = self.pos % (self.samples.shape[1] - n_samples)
        self.pos = a + n_samples
        return AudioBlock(self.samples[:, a:a + n_samples], self.fs, a / self.fs)


def measure(n_talkers: int, listens: int, seed: int = 0) -> dict:
    """CPU seconds of ``listens`` one-second listens with ``n_talkers`` talkers, and what the chain heard."""
    sc = load_scenario("light_rubble_three")
    cfg = sc.behaviour
    lab = Lab(duration_s=float(listens) + 1.0)
    truths = [Truth(90.0 * k + 20.0, 0.0, 2.0) for k in range(n_talkers)]
    sim = build_sim(lab, truths, seed)
    x = sim.listen_pose(lab.pose, lab.duration_s, t0=0.0, mount=lab.mount)
    listener = Listener(_Recording(x, sc.localizer.fs), ManualClock(), Localizer(cube8(), sc.localizer), cube8(),
                        cfg.voice_threshold, None, cfg.voice_scan_deg)
    listener.listen(cfg.listen_s, 0.0, cfg.min_power, pose=(0.0, 0.0, 0.0))   # model loading off the clock
    c = time.process_time()
    heard = [listener.listen(cfg.listen_s, 0.0, cfg.min_power, pose=(0.0, 0.0, 0.0)) for _ in range(listens)]
    cpu = time.process_time() - c
    tracks = listener.tracker.tracks()
    return {"talkers": n_talkers, "listens": listens, "audio_s": listens * cfg.listen_s,
            "cpu_ms_per_audio_s": 1e3 * cpu / (listens * cfg.listen_s),
            "detections_per_listen": float(np.mean([len(h.evidence) for h in heard])),
            "voiced_per_listen": float(np.mean([sum(e.speech_fraction >= cfg.voice_threshold for e in h.evidence)
                                                for h in heard])),
            "tracks": len(tracks)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--listens", type=int, default=20, help="one-second listens per talker count")
    add_check_option(ap)
    args = ap.parse_args(argv)
    if args.listens < 1:
        ap.error(f"--listens: expected >= 1, got {args.listens}")
    require_stored("listen", args.check)
    rows = [measure(k, args.listens) for k in TALKERS]
    print(f"bench_listen: the robot's hearing chain (localizer + voice evidence + voice scan + tracker), "
          f"{args.listens} one-second listens per row, load average {load_avg()[0]:.2f} on {os.cpu_count()} cores")
    table = "\n".join(["| talkers | CPU ms per s of audio | detections per listen | voiced per listen | tracks |",
                        "|---|---|---|---|---|"]
                       + [f"| {r['talkers']} | {r['cpu_ms_per_audio_s']:.1f} | {r['detections_per_listen']:.1f} | "
                          f"{r['voiced_per_listen']:.1f} | {r['tracks']} |" for r in rows])
    print(table)
    print(json.dumps({"bench": "listen", "rows": rows}))
    figures = {f"cpu_ms_per_audio_s_{r['talkers']}_talkers": round(r["cpu_ms_per_audio_s"], 2) for r in rows}
    figures.update({f"tracks_{r['talkers']}_talkers": r["tracks"] for r in rows})
    return finish("listen", figures, {"hearing chain per second of audio": table}, check=args.check,
                  better={f"cpu_ms_per_audio_s_{k}_talkers": "lower" for k in TALKERS})


if __name__ == "__main__":
    raise SystemExit(main())
