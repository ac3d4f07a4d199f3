"""Benchmark: ``ssl-locate`` peak memory on a long 8-channel file (target: <= 300 MB for an hour).

Generates a 16-bit 8-channel 16 kHz WAV of the requested length in a temporary folder, block by
block (a talker-like noise burst from a fixed direction every 3 s, plus sensor noise), runs
``ssl-locate`` on it in a child process and reports the child's peak resident memory
(``ru_maxrss``) and CPU time, then one JSON line. The file is deleted afterwards.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from _results import add_check_option, finish, require_stored  # noqa: E402
from ssl_core.geometry import cube8  # noqa: E402
from ssl_core.grid import direction_from_angles  # noqa: E402

FS = 16000
C = 343.0


def write_long_wav(path: Path, seconds: int, seed: int = 0) -> tuple[float, float]:
    """A PCM16 WAV of ``seconds`` s written one second at a time; returns the source (az, el) in degrees."""
    az, el = 70.0, 15.0
    mics = cube8().positions
    delays = -(mics @ direction_from_angles(np.deg2rad(az), np.deg2rad(el))) / C
    f = np.fft.rfftfreq(FS, 1 / FS)
    shift = np.exp(-2j * np.pi * f[None] * delays[:, None])
    rng = np.random.default_rng(seed)
    n_bytes = seconds * FS * 8 * 2
    with open(path, "wb") as out:
        fmt = struct.pack("<HHIIHH", 1, 8, FS, FS * 16, 16, 16)
        out.write(b"RIFF" + struct.pack("<I", 4 + 8 + len(fmt) + 8 + n_bytes) + b"WAVE")
        out.write(b"fmt " + struct.pack("<I", len(fmt)) + fmt + b"data" + struct.pack("<I", n_bytes))
        for k in range(seconds):
            s = rng.standard_normal(FS) * (0.1 if k % 3 == 0 else 0.0)  # a 1 s burst every 3 s
            x = np.fft.irfft(np.fft.rfft(s)[None] * shift, FS) + 0.002 * rng.standard_normal((8, FS))
            out.write(np.round(np.clip(x, -1, 1) * 32767).astype("<i2").T.tobytes())
    return az, el


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--minutes", type=float, default=60.0)
    ap.add_argument("--quick", action="store_true", help="5 minutes instead")
    add_check_option(ap)
    args = ap.parse_args()
    require_stored("locate_memory", args.check)
    minutes = 5.0 if args.quick else args.minutes
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "long.wav"
        t0 = time.perf_counter()
        az, el = write_long_wav(path, int(minutes * 60))
        gen_s = time.perf_counter() - t0
        env = dict(os.environ, PYTHONPATH=str(ROOT / "src"))
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        res = subprocess.run([sys.executable, "-m", "ssl_core.cli", str(path), "--json"], capture_output=True,
                             text=True, env=env)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if res.returncode != 0:
            raise SystemExit(f"ssl-locate failed ({res.returncode}): {res.stderr}")
        det = json.loads(res.stdout.strip().splitlines()[-1])["windows"][0]["detections"][0]
        size_mb = path.stat().st_size / 1e6
    peak_mb = after.ru_maxrss / 1024  # Linux: kB
    cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    print(f"{minutes:g} min 8-channel 16-bit WAV ({size_mb:.0f} MB, generated in {gen_s:.0f} s): ssl-locate peak RSS "
          f"{peak_mb:.0f} MB, CPU {cpu:.1f} s ({1000 * cpu / (minutes * 60):.1f} ms per second of audio); "
          f"found az {det['azimuth_deg']:.1f} el {det['elevation_deg']:.1f} (true {az:g}, {el:g})")
    figures = {"minutes": minutes, "file_mb": round(size_mb, 1), "peak_rss_mb": round(peak_mb, 1),
               "cpu_s": round(cpu, 2), "cpu_ms_per_audio_s": round(1000 * cpu / (minutes * 60), 2),
               "azimuth_deg": det["azimuth_deg"], "elevation_deg": det["elevation_deg"], "true_azimuth_deg": az,
               "true_elevation_deg": el}
    return finish("locate_memory", figures, check=args.check,
                  better={"peak_rss_mb": "lower", "cpu_ms_per_audio_s": "lower"})


if __name__ == "__main__":
    raise SystemExit(main())
