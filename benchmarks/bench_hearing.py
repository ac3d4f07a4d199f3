"""Benchmark: hearing in noise - accuracy per condition and method, and CPU per second of audio.

Recordings from the ssl_sim lab (experiments.common: 7 x 6 x 3.5 m room, image sources plus a
diffuse tail, diffuse hvac noise 35 dB SPL, the sensor model), talkers calling near-continuously
(synthetic calls, 62.5 dB SPL at 1 m). Conditions: one talker at 1.5 m, RT60 0.5 s with white
sensor noise at SNR 20 / 5 / -5 dB; one talker 3 m away at RT60 0.9 s; 2 and 3 talkers 40+ deg
apart at 2 m, RT60 0.4 s; a talker beside a steady pump of equal level (0 dB SIR, both 1.5 m).
Directions are drawn per trial (seeded).

Rows:
- ``engine/window``: ssl_core per 128 ms window (n_sources = number of talkers), significance test;
- ``engine+NS/window``: the same with noise suppression;
- ``engine+track``: confirmed tracks of ssl_core.tracking.Tracker per window, detections at the tracking
  gate (``TRACKING_MIN_SIGNIFICANCE``); ``engine+NS+track`` with noise suppression;
- ``engine+NS+2+track``: as ``engine+NS+track`` with two sources per window at least (the pump, a second
  source, counts as false); ``engine+NS+IR+track`` the same with the interference rescan
  (``LocalizerConfig.interference_rescan``);
- ``whole recording``: ``Localizer.locate`` (what ``ssl-locate REC.wav`` prints), one answer per trial;
  ``+NS`` with noise suppression (``ssl-locate --noise-suppression``);
- ``pra SRP`` / ``pra NormMUSIC``: pyroomacoustics on the first windows of each trial (they are slow),
  same frames (512/256), band and grid size, told the number of sources.
Per-window columns: ``hit %`` windows with an output within 10 deg of a talker, ``false %`` windows with
an output farther than 10 deg from every talker (the pump counts as false), ``err`` median error (deg)
of the hits. Whole recording: ``hit %`` trials with every talker within 10 deg, ``err`` median error.
Then CPU per second of audio (detection, + tracking when available) at the 1.5 deg grid, in child
processes: default environment (BLAS pinned by ssl_core), default environment with the pin disabled,
and OPENBLAS_NUM_THREADS=1; and, pinned, two sources per window without and with the interference rescan
(its cost: a covariance update and an 8x8 solve per bin and window). Prints a markdown table and one JSON line.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "src"), str(ROOT)]

import numpy as np  # noqa: E402

from _results import add_check_option, finish, require_stored  # noqa: E402

FS = 16000
HIT_DEG = 10.0


def _conditions():
    from experiments.common import Truth

    def one(dist, el_range=(-15, 25)):
        return lambda rng: [Truth(float(rng.uniform(-180, 180)), float(rng.uniform(*el_range)), dist)]

    def spread(k):
        def draw(rng):
            while True:
                az = rng.uniform(-180, 180, k)
                gaps = np.abs((az[:, None] - az[None, :] + 180) % 360 - 180) + 1e3 * np.eye(k)
                if gaps.min() >= 40:
                    return [Truth(float(a), float(rng.uniform(-20, 30)), 2.0) for a in az]
        return draw

    return {
        "SNR 20 dB": dict(draw=one(1.5), rt60=0.5, snr=20.0),
        "SNR 5 dB": dict(draw=one(1.5), rt60=0.5, snr=5.0),
        "SNR -5 dB": dict(draw=one(1.5), rt60=0.5, snr=-5.0),
        "3 m, RT60 0.9": dict(draw=one(3.0, (-10, 10)), rt60=0.9, snr=None),
        "2 talkers": dict(draw=spread(2), rt60=0.4, snr=None),
        "3 talkers": dict(draw=spread(3), rt60=0.4, snr=None),
        "pump, 0 dB SIR": dict(draw=one(1.5, (0, 0)), rt60=0.5, snr=None, pump=True),
    }


def _fits(truths, lab, margin=0.3) -> bool:
    from ssl_sim.acoustics import point_at

    for t in truths:
        p = point_at(lab.centre, np.deg2rad(t.azimuth_deg), np.deg2rad(t.elevation_deg), t.distance_m)
        if np.any(p < margin) or np.any(p > np.array(lab.room_size) - margin):
            return False
    return True


def make_trials(cond: dict, n_trials: int, seconds: float, seed: int):
    from experiments.common import Lab, Truth, build_sim, with_sensor_noise

    rng = np.random.default_rng(seed)
    lab = Lab(duration_s=seconds, rt60_s=cond["rt60"])
    out = []
    for k in range(n_trials):
        truths = cond["draw"](rng)
        pump = None
        if cond.get("pump"):  # the pump 90 deg from the talker, level with its calls (test_ssl_core_detection)
            pump = Truth(truths[0].azimuth_deg - 90.0, 0.0, 1.5, level_db_spl=59.5)
        while not _fits(truths + ([pump] if pump else []), lab):
            truths = cond["draw"](rng)
            if pump:
                pump = Truth(truths[0].azimuth_deg - 90.0, 0.0, 1.5, level_db_spl=59.5)
        x = build_sim(lab, truths, seed + k, pump=pump).listen_pose(lab.pose, seconds, mount=lab.mount)
        x = with_sensor_noise(x, cond["snr"], seed + k) if cond["snr"] is not None else x.astype(float) / 32768
        out.append((x.astype(np.float32), truths))
    return out


def _errors(dirs, truths) -> np.ndarray:
    """(outputs, truths) angular errors in degrees."""
    if len(dirs) == 0:
        return np.zeros((0, len(truths)))
    t = np.array([tr.direction for tr in truths])
    return np.rad2deg(np.arccos(np.clip(np.asarray(dirs) @ t.T, -1, 1)))


class _Tally:
    def __init__(self):
        self.windows = self.hits = self.false = 0
        self.err: list[float] = []

    def add(self, dirs, truths):
        e = _errors(dirs, truths)
        self.windows += 1
        if e.size:
            best = e.min(axis=1)
            self.hits += bool((best <= HIT_DEG).any())
            self.false += bool((best > HIT_DEG).any())
            self.err += list(best[best <= HIT_DEG])

    def row(self) -> dict:
        n = max(self.windows, 1)
        return {"hit_pct": 100 * self.hits / n, "false_pct": 100 * self.false / n,
                "err_deg": float(np.median(self.err)) if self.err else float("nan"), "n": self.windows}


def _tracker_class():
    try:
        from ssl_core.tracking import Tracker
        return Tracker
    except ImportError:
        return None


def run_engine(trials, k: int, noise_suppression=False, track=False, rescan=False, two=False) -> dict:
    from ssl_core.localizer import Localizer, LocalizerConfig

    cfg = LocalizerConfig(n_sources=max(k, 2) if rescan or two else k, noise_suppression=noise_suppression,
                          interference_rescan=rescan)
    if track:  # the gate the tracker is tuned for
        from ssl_core.tracking import TRACKING_MIN_SIGNIFICANCE
        cfg = replace(cfg, min_significance=TRACKING_MIN_SIGNIFICANCE)
    loc = Localizer("cube8", cfg)
    tally = _Tally()
    Tracker = _tracker_class()
    for x, truths in trials:
        tracker = Tracker() if track else None
        for r in loc.process_all(x):
            if tracker is not None:
                tally.add([t.direction for t in tracker.update(r.detections, r.time)], truths)
            else:
                tally.add([d.direction for d in r.detections], truths)
    return tally.row()


def run_whole(trials, k: int, noise_suppression=False) -> dict:
    from ssl_core.localizer import Localizer, LocalizerConfig

    loc = Localizer("cube8", LocalizerConfig(n_sources=k, noise_suppression=noise_suppression))
    ok, errs = 0, []
    for x, truths in trials:
        e = _errors([d.direction for d in loc.locate(x).detections], truths)
        if e.shape[0] >= len(truths):
            from scipy.optimize import linear_sum_assignment
            r, c = linear_sum_assignment(e)
            ok += bool((e[r, c] <= HIT_DEG).all())
            errs += list(e[r, c])
    return {"hit_pct": 100 * ok / len(trials), "false_pct": float("nan"),
            "err_deg": float(np.median(errs)) if errs else float("nan"), "n": len(trials)}


def run_pra(name: str, trials, k: int, n_windows: int) -> dict:
    import pyroomacoustics as pra
    from ssl_core.geometry import cube8
    from ssl_core.grid import direction_from_angles, n_points_for_spacing

    n_grid = n_points_for_spacing(np.deg2rad(1.5))
    doa = pra.doa.algorithms[name](cube8().positions.T, FS, 512, c=343.0, num_src=k, dim=3, n_grid=n_grid)
    win = np.hanning(512)
    block = 7 * 256 + 512  # the engine's 128 ms window: 8 frames
    tally = _Tally()
    for x, truths in trials:
        for w in range(n_windows):
            blk = x[:, w * 8 * 256: w * 8 * 256 + block]
            frames = np.lib.stride_tricks.sliding_window_view(blk, 512, axis=1)[:, ::256] * win
            doa.locate_sources(np.fft.rfft(frames, axis=-1).transpose(0, 2, 1), num_src=k, freq_range=[300.0, 6000.0])
            dirs = direction_from_angles(doa.azimuth_recon, np.pi / 2 - doa.colatitude_recon)
            tally.add(np.atleast_2d(dirs), truths)
    return tally.row()


# ----------------------------------------------------------------------------------------- CPU
def cpu_child(seconds: float, pin: bool, n_sources: int = 1, rescan: bool = False) -> dict:
    """CPU (process_time) per second of audio of detection (+ tracking) at the 1.5 deg grid, this process."""
    import ssl_core.blas
    import ssl_core.localizer as L
    from experiments.common import Lab, Truth, build_sim

    if not pin:
        ssl_core.blas.disable()  # no one-thread pin: what numpy's default thread pool costs
    lab = Lab(duration_s=seconds)
    x = build_sim(lab, [Truth(40.0, 10.0, 1.5)], 1).listen_pose(lab.pose, seconds, mount=lab.mount)
    Tracker = _tracker_class()
    tracker = Tracker() if Tracker else None
    cfg = L.LocalizerConfig(n_sources=n_sources, interference_rescan=rescan)
    if tracker is not None:
        from ssl_core.tracking import TRACKING_MIN_SIGNIFICANCE
        cfg = replace(cfg, min_significance=TRACKING_MIN_SIGNIFICANCE)
    loc = L.Localizer("cube8", cfg)
    loc.process(x[:, :FS])  # warm-up
    loc.reset()
    t0 = time.process_time()
    for k in range(0, x.shape[1], 1600):  # 100 ms blocks, as a robot would stream
        for r in loc.process(x[:, k:k + 1600]):
            if tracker is not None:
                tracker.update(r.detections, r.time)
    cpu = time.process_time() - t0
    t0 = time.process_time()
    loc.locate(x)  # the whole-recording answer on the same audio
    cpu_locate = time.process_time() - t0
    return {"cpu_ms_per_s": 1000 * cpu / seconds, "locate_cpu_ms_per_s": 1000 * cpu_locate / seconds,
            "tracking": tracker is not None}


def cpu_table(seconds: float) -> dict:
    modes = {"default env (pinned)": ({}, []), "default env, pin off": ({}, ["--no-pin"]),
             "OPENBLAS_NUM_THREADS=1": ({"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}, []),
             "pinned, 2 sources": ({}, ["--cpu-sources", "2"]),
             "pinned, 2 sources + IR": ({}, ["--cpu-sources", "2", "--cpu-rescan"])}
    out = {}
    for name, (extra, flags) in modes.items():
        env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
        env.update(extra)
        res = subprocess.run([sys.executable, __file__, "--cpu-child", str(seconds)] + flags,
                             capture_output=True, text=True, env=env, check=True)
        out[name] = json.loads(res.stdout.strip().splitlines()[-1])
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="1 trial of 2 s per condition, 2 pra windows")
    ap.add_argument("--trials", type=int, default=4)
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--pra-windows", type=int, default=4)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--methods", default=None, help="comma-separated rows to run (default: all); cpu = the CPU part")
    add_check_option(ap)
    ap.add_argument("--cpu-child", type=float, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--no-pin", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--cpu-sources", type=int, default=1, help=argparse.SUPPRESS)
    ap.add_argument("--cpu-rescan", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.cpu_child is not None:
        print(json.dumps(cpu_child(a.cpu_child, not a.no_pin, a.cpu_sources, a.cpu_rescan)))
        return 0
    require_stored("hearing", a.check)
    if a.quick:
        a.trials, a.seconds, a.pra_windows = 1, 2.0, 2
    tracking = _tracker_class() is not None
    rows = {"engine/window": lambda t, k: run_engine(t, k),
            "engine+NS/window": lambda t, k: run_engine(t, k, noise_suppression=True),
            "engine+track": lambda t, k: run_engine(t, k, track=True),
            "engine+NS+track": lambda t, k: run_engine(t, k, noise_suppression=True, track=True),
            "engine+NS+2+track": lambda t, k: run_engine(t, k, noise_suppression=True, track=True, two=True),
            "engine+NS+IR+track": lambda t, k: run_engine(t, k, noise_suppression=True, track=True, rescan=True),
            "whole recording": lambda t, k: run_whole(t, k),
            "whole recording+NS": lambda t, k: run_whole(t, k, noise_suppression=True),
            "pra SRP": lambda t, k: run_pra("SRP", t, k, a.pra_windows),
            "pra NormMUSIC": lambda t, k: run_pra("NormMUSIC", t, k, a.pra_windows)}
    wanted = a.methods.split(",") if a.methods else [m for m in rows if tracking or "track" not in m] + ["cpu"]
    unknown = [m for m in wanted if m not in rows and m != "cpu"]
    if unknown:
        raise SystemExit(f"--methods: unknown {unknown}; expected some of {list(rows) + ['cpu']}")
    methods = [m for m in wanted if m in rows]
    table: dict[str, dict[str, dict]] = {m: {} for m in methods}
    conds = _conditions()
    for ci, (cname, cond) in enumerate(conds.items()):
        if not methods:
            break
        trials = make_trials(cond, a.trials, a.seconds, a.seed + 100 * ci)
        k = len(trials[0][1])
        for m in methods:
            table[m][cname] = rows[m](trials, k)
        print(f"[{cname} done]", file=sys.stderr, flush=True)
    print(f"{a.trials} trials x {a.seconds:g} s per condition; hit % / false % / median error (deg) "
          f"(whole recording: trials with every talker within {HIT_DEG:g} deg / - / median error)\n")
    md = ["| method | " + " | ".join(conds) + " |", "|---|" + "---|" * len(conds)]
    for m in methods:
        cells = []
        for c in conds:
            r = table[m][c]
            false = "-" if np.isnan(r["false_pct"]) else f"{r['false_pct']:.0f}"
            err = "-" if np.isnan(r["err_deg"]) else f"{r['err_deg']:.1f}"
            cells.append(f"{r['hit_pct']:.0f} / {false} / {err}")
        md.append(f"| {m} | " + " | ".join(cells) + " |")
    print("\n".join(md))
    cpu = cpu_table(a.seconds if a.quick else 20.0) if "cpu" in wanted else {}
    label = "detection + tracking" if tracking else "detection"
    if cpu:
        print(f"\nCPU per second of audio, 1.5 deg grid: {label} streamed in 100 ms blocks; whole-recording locate:")
    for name, r in cpu.items():
        print(f"  {name:26s} {r['cpu_ms_per_s']:6.2f} ms/s   locate {r['locate_cpu_ms_per_s']:6.2f} ms/s")
    print(json.dumps({"bench": "hearing", "trials": a.trials, "seconds": a.seconds, "table": table, "cpu": cpu}))
    figures = {f"cpu_ms_per_audio_s {name}": r["cpu_ms_per_s"] for name, r in cpu.items()}
    figures.update({f"locate_cpu_ms_per_audio_s {name}": r["locate_cpu_ms_per_s"] for name, r in cpu.items()})
    for m in methods:
        for c in conds:
            figures.update({f"{k} {m} | {c}": v for k, v in table[m][c].items() if isinstance(v, (int, float))})
    tables = {f"Hearing in noise ({a.trials} trials x {a.seconds:g} s per condition; hit % / false % / median "
              f"error deg)": "\n".join(md) + "\n"} if methods else {}
    return finish("hearing", figures, tables, check=a.check,
                  better={k: "lower" for k in figures if k.startswith("cpu_ms_per_audio_s") and "pinned" in k})


if __name__ == "__main__":
    raise SystemExit(main())
