"""Benchmark: ssl_core SRP-PHAT against pyroomacoustics' SRP and MUSIC DOA (3D) on the same signals.

Same 8-channel 16 kHz recordings (pyroomacoustics room, RT60 0.3 s, 20 dB SNR,
noise-burst "syllables" from random directions), same grid resolution (1.5
degrees), same band. Everything runs on one core, streamed in 100 ms blocks.
Prints real-time factor, per-block latency and median azimuth/elevation error,
then one JSON line.
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import pyroomacoustics as pra  # noqa: E402

from _results import add_check_option, finish, require_stored  # noqa: E402
from ssl_core.geometry import cube8  # noqa: E402
from ssl_core.grid import direction_from_angles, n_points_for_spacing  # noqa: E402
from ssl_core.localizer import Localizer, LocalizerConfig  # noqa: E402

FS = 16000
BLOCK = FS // 10  # 100 ms
NFFT = 512
BAND = (300.0, 6000.0)
RES_DEG = 1.5


def bursts(n: int, rng: np.random.Generator) -> np.ndarray:
    """Noise bursts with a syllable-rate envelope (broadband, speech-like on/off structure)."""
    t = np.arange(n) / FS
    env = 0.1 + np.clip(np.sin(2 * np.pi * 3.0 * t + rng.uniform(0, 6)), 0, None)
    return rng.standard_normal(n) * env


def make_trials(n_trials: int, seconds: float, seed: int):
    rng = np.random.default_rng(seed)
    g = cube8()
    room_dim = np.array([7.0, 6.0, 3.0])
    e_abs, order = pra.inverse_sabine(0.3, room_dim)
    centre = np.array([3.3, 2.9, 1.3])
    trials = []
    for _ in range(n_trials):
        az, el = rng.uniform(-np.pi, np.pi), rng.uniform(-0.6, 0.6)
        u = direction_from_angles(az, el)
        room = pra.ShoeBox(room_dim, fs=FS, materials=pra.Material(e_abs), max_order=min(order, 10))
        n = int(seconds * FS)
        room.add_source(centre + 1.5 * u, signal=bursts(n, rng))
        room.add_microphone_array((centre + g.positions).T)
        room.simulate()
        x = room.mic_array.signals[:, :n]
        x = x + rng.standard_normal(x.shape) * np.sqrt(np.mean(x**2)) / 10  # 20 dB SNR
        trials.append((x.astype(np.float32), az, el))
    return trials


def ang_err(az, el, az0, el0):
    return abs(np.rad2deg(np.angle(np.exp(1j * (az - az0))))), abs(np.rad2deg(el - el0))


def run_ours(trials):
    cfg = LocalizerConfig(fs=FS, frame_size=NFFT, hop=NFFT // 2, window_frames=6, band_hz=BAND,
                          resolution_deg=RES_DEG)
    loc = Localizer(cube8(), cfg)
    cpu, audio, blocks, errs = 0.0, 0.0, 0, []
    for x, az0, el0 in trials:
        loc.reset()
        for k in range(0, x.shape[1], BLOCK):
            blk = x[:, k:k + BLOCK]
            t0 = time.process_time()
            out = loc.process(blk)
            cpu += time.process_time() - t0
            blocks += 1
            for r in out:
                if r.detections:
                    errs.append(ang_err(r.detections[0].azimuth, r.detections[0].elevation, az0, el0))
        audio += x.shape[1] / FS
    return cpu, audio, blocks, errs, loc.fine_grid.n_points


def run_pra(name: str, trials, n_grid: int, max_blocks: int):
    L = cube8().positions.T
    doa = pra.doa.algorithms[name](L, FS, NFFT, c=343.0, num_src=1, dim=3, n_grid=n_grid)
    win = np.hanning(NFFT)
    cpu, audio, blocks, errs = 0.0, 0.0, 0, []
    for x, az0, el0 in trials:
        for k in range(0, min(x.shape[1], max_blocks * BLOCK), BLOCK):
            blk = x[:, k:k + BLOCK]
            t0 = time.process_time()
            frames = np.lib.stride_tricks.sliding_window_view(blk, NFFT, axis=1)[:, :: NFFT // 2] * win
            X = np.fft.rfft(frames, axis=-1).transpose(0, 2, 1)  # (M, bins, frames)
            doa.locate_sources(X, num_src=1, freq_range=list(BAND))
            cpu += time.process_time() - t0
            blocks += 1
            audio += blk.shape[1] / FS
            az, col = doa.azimuth_recon[0], doa.colatitude_recon[0]
            errs.append(ang_err(az, np.pi / 2 - col, az0, el0))
    return cpu, audio, blocks, errs


def summary(name, cpu, audio, blocks, errs):
    e = np.array(errs) if errs else np.full((1, 2), np.nan)
    return {"method": name, "rtf": audio / cpu, "cpu_ms_per_s": 1000 * cpu / audio,
            "latency_ms_per_block": 1000 * cpu / blocks, "median_az_err_deg": float(np.median(e[:, 0])),
            "median_el_err_deg": float(np.median(e[:, 1])), "estimates": len(errs)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--trials", type=int, default=8)
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--pra-blocks", type=int, default=3, help="100 ms blocks per trial for the (slow) pyroomacoustics methods")
    ap.add_argument("--seed", type=int, default=0)
    add_check_option(ap)
    args = ap.parse_args()
    require_stored("srp", args.check)
    try:
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    except (AttributeError, OSError):
        pass
    trials = make_trials(args.trials, args.seconds, args.seed)
    cpu, audio, blocks, errs, n_grid = run_ours(trials)
    assert n_grid == n_points_for_spacing(np.deg2rad(RES_DEG))
    rows = [summary("ssl_core SRP-PHAT", cpu, audio, blocks, errs)]
    for name in ("SRP", "MUSIC"):
        rows.append(summary(f"pyroomacoustics {name}", *run_pra(name, trials, n_grid, args.pra_blocks)))
    print(f"{args.trials} trials x {args.seconds:g} s, 8 mics, {FS} Hz, grid {n_grid} points "
          f"({RES_DEG} deg), band {BAND[0]:g}-{BAND[1]:g} Hz, 100 ms blocks, one core")
    print(f"{'method':26s} {'x realtime':>10s} {'cpu ms/s':>9s} {'ms/block':>9s} {'az err':>7s} {'el err':>7s}")
    for r in rows:
        print(f"{r['method']:26s} {r['rtf']:10.1f} {r['cpu_ms_per_s']:9.2f} {r['latency_ms_per_block']:9.2f} "
              f"{r['median_az_err_deg']:7.2f} {r['median_el_err_deg']:7.2f}")
    speedup = rows[1]["cpu_ms_per_s"] / rows[0]["cpu_ms_per_s"]
    print(f"speed-up over pyroomacoustics SRP at the same grid: {speedup:.0f}x")
    ours, pra_srp, pra_music = rows
    figures = {"ssl_core_cpu_ms_per_audio_s": ours["cpu_ms_per_s"], "ssl_core_x_realtime": ours["rtf"],
               "ssl_core_median_az_err_deg": ours["median_az_err_deg"],
               "ssl_core_median_el_err_deg": ours["median_el_err_deg"],
               "pra_srp_cpu_ms_per_audio_s": pra_srp["cpu_ms_per_s"], "pra_music_cpu_ms_per_audio_s":
               pra_music["cpu_ms_per_s"], "speedup_vs_pra_srp": speedup, "grid_points": n_grid}
    table = "| method | x real time | CPU ms per s of audio | median az / el error (deg) |\n|---|---|---|---|\n" + "".join(
        f"| {r['method']} | {r['rtf']:.3g} | {r['cpu_ms_per_s']:.3g} | {r['median_az_err_deg']:.2f} / "
        f"{r['median_el_err_deg']:.2f} |\n" for r in rows)
    return finish("srp", figures, {f"SRP-PHAT against pyroomacoustics ({args.trials} trials x {args.seconds:g} s, "
                                   f"{n_grid}-point grid, one core)": table},
                  check=args.check, better={"ssl_core_cpu_ms_per_audio_s": "lower"})


if __name__ == "__main__":
    raise SystemExit(main())
