"""The rescue's own listens, heard again: how often a listen detects and voices each nearby victim.

Runs a scenario's seeds (``ssl_sim.runner.RescueRun``, the shipped behaviour), keeps the audio of every
listen with the truth the runner records for it (each source's direction in the array frame, distance,
share of the listen it sounds), and replays the listens within ``--max-distance`` of a victim through the
rescue's ``robot.listening.Listener`` with the voice scan off and on. Per victim listen (the victim within
``--max-distance`` m and sounding in at least ``--min-active`` of the listen): ``det %`` a detection within
10 deg of its azimuth, ``voiced %`` one whose beam had speech (``voice_threshold``). Per listen: ``ghosts``
detections more than 15 deg in azimuth from every source, ``voiced ghosts`` those with speech. The runs'
paths are the shipped behaviour's, so the listens are the poses the robot really listens from.

Run: ``.venv/bin/python tools/listen_replay.py --scenario dense_pump --seeds 0:4``; prints a markdown
table, then one JSON line.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def run_listens(scenario: str, seed: int) -> tuple[list[tuple[np.ndarray, dict]], int]:
    """(audio, truth record) of every listen of one run, and the sample rate."""
    from ssl_sim.runner import RescueRun
    from ssl_sim.scenario import load_scenario
    run = RescueRun(load_scenario(ROOT / "src" / "ssl_sim" / "scenarios" / f"{scenario}.toml").with_overrides(seed=seed))
    captured: list[np.ndarray] = []
    locate = run.localizer.locate

    def keep(samples):
        captured.append(np.array(samples, copy=True))
        return locate(samples)
    run.localizer.locate = keep   # the instance's own locate: the behaviour sees the same results
    run.run()
    if len(captured) != len(run.listens):
        raise RuntimeError(f"{len(captured)} listens captured, {len(run.listens)} recorded")
    return list(zip(captured, run.listens)), run.scenario.localizer.fs


def _az_error_deg(a: float, b_deg: float) -> float:
    return abs(math.degrees(math.remainder(a - math.radians(b_deg), 2 * math.pi)))


def score(listens, fs: int, localizer, scan_deg: float, voice_threshold: float, max_distance: float,
          min_active: float) -> dict:
    """Replays the ``listens`` within ``max_distance`` of a victim through one ``Listener`` (the project's
    ``WavFileSource`` reading them in turn from a temporary WAV) and counts as the module docstring says."""
    from scipy.io import wavfile

    from robot.hal import ManualClock
    from robot.listening import Listener
    from robot.replay import WavFileSource
    from ssl_core.geometry import cube8
    kept = [(x, rec) for x, rec in listens
            if min(s["distance_m"] for s in rec["sources"] if s["kind"] == "victim") <= max_distance]
    victims: dict[str, list[int]] = {}
    ghosts = voiced_ghosts = 0
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "listens.wav"
        wavfile.write(path, fs, np.concatenate([x for x, _ in kept], axis=1).T.astype(np.float32))
        listener = Listener(WavFileSource(path, 8, fs), ManualClock(), localizer, cube8().positions,
                            voice_threshold, voice_scan_deg=scan_deg)
        heard = [listener.listen(x.shape[1] / fs, 0.0, 0.0).evidence for x, _ in kept]
    for ev, (_, rec) in zip(heard, kept):
        for e in ev:
            if all(_az_error_deg(e.azimuth, s["azimuth_deg"]) > 15 for s in rec["sources"]):
                ghosts += 1
                voiced_ghosts += e.speech_fraction >= voice_threshold
        for s in rec["sources"]:
            if s["kind"] != "victim" or s["distance_m"] > max_distance or s["active_fraction"] < min_active:
                continue
            near = [e for e in ev if _az_error_deg(e.azimuth, s["azimuth_deg"]) <= 10]
            row = victims.setdefault(s["name"], [0, 0, 0])
            row[0] += 1
            row[1] += bool(near)
            row[2] += any(e.speech_fraction >= voice_threshold for e in near)
    n = max(len(kept), 1)
    return {"listens": len(kept), "ghosts_per_listen": ghosts / n, "voiced_ghosts_per_listen": voiced_ghosts / n,
            "victims": {k: {"listens": v[0], "det_pct": 100 * v[1] / v[0], "voiced_pct": 100 * v[2] / v[0]}
                        for k, v in victims.items()}}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="dense_pump")
    ap.add_argument("--seeds", default="0:4", help="START:STOP (stop exclusive)")
    ap.add_argument("--max-distance", type=float, default=2.5, help="m: listens this close to a victim")
    ap.add_argument("--min-active", type=float, default=0.5, help="victim sounding in this share of the listen")
    ap.add_argument("--scan-deg", type=float, default=15.0, help="the voice scan's beam spacing when on")
    args = ap.parse_args()
    from ssl_core.geometry import cube8
    from ssl_core.localizer import Localizer
    from ssl_sim.scenario import load_scenario
    sc = load_scenario(ROOT / "src" / "ssl_sim" / "scenarios" / f"{args.scenario}.toml")
    a, b = (int(v) for v in args.seeds.split(":"))
    listens, fs = [], sc.localizer.fs
    for seed in range(a, b):
        got, fs = run_listens(args.scenario, seed)
        listens += got
    localizer = Localizer(cube8(), sc.localizer)
    threshold = sc.behaviour.voice_threshold
    out = {name: score(listens, fs, localizer, deg, threshold, args.max_distance, args.min_active)
           for name, deg in (("scan off", 0.0), (f"scan {args.scan_deg:g} deg", args.scan_deg))}
    names = sorted({v for r in out.values() for v in r["victims"]})
    print(f"{args.scenario}, seeds {a}-{b - 1}: listens within {args.max_distance} m of a victim; per victim "
          f"listen (sounding >= {args.min_active:.0%}): det % / voiced %")
    print("| listener | listens | " + " | ".join(names) + " | ghosts per listen | voiced ghosts per listen |")
    print("|---" * (len(names) + 4) + "|")
    for name, r in out.items():
        cells = [f"{r['victims'][v]['det_pct']:.0f} / {r['victims'][v]['voiced_pct']:.0f} "
                 f"(n {r['victims'][v]['listens']})" if v in r["victims"] else "-" for v in names]
        print(f"| {name} | {r['listens']} | " + " | ".join(cells)
              + f" | {r['ghosts_per_listen']:.2f} | {r['voiced_ghosts_per_listen']:.3f} |")
    print(json.dumps({"bench": "listens", "scenario": args.scenario, "seeds": [a, b], "results": out}))


if __name__ == "__main__":
    main()
