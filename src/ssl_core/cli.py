"""``ssl-locate REC.wav --array cube8 [--sources 3]``: localize the sources in a multichannel WAV."""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace

import numpy as np
from scipy.io import wavfile

from ssl_core.geometry import get_array
from ssl_core.localizer import Localizer, LocalizerConfig


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="ssl-locate", description=__doc__)
    p.add_argument("wav", help="multichannel WAV file (one channel per microphone)")
    p.add_argument("--array", default="cube8", help="array preset (cube8, cube8_corners) or .toml/.json geometry")
    p.add_argument("--sources", type=int, default=1, help="maximum number of sources to report")
    p.add_argument("--resolution", type=float, default=1.5, help="final grid resolution (degrees)")
    p.add_argument("--band", type=float, nargs=2, default=(300.0, 6000.0), metavar=("LOW", "HIGH"),
                   help="analysis band (Hz)")
    p.add_argument("--radius", type=float, default=None, help="near-field grid radius (m); far field if omitted")
    p.add_argument("--min-separation", type=float, default=20.0, help="minimum angle between sources (degrees)")
    p.add_argument("--stream", action="store_true", help="print detections per analysis window instead of one summary")
    p.add_argument("--window", type=int, default=8, help="STFT frames per analysis window with --stream")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    return p


def _read_wav(path: str) -> tuple[int, np.ndarray]:
    try:
        fs, data = wavfile.read(path)
    except FileNotFoundError:
        raise SystemExit(f"ssl-locate: no such file: {path}")
    except ValueError as exc:
        raise SystemExit(f"ssl-locate: cannot read {path} as WAV: {exc}")
    if data.ndim == 1:
        data = data[:, None]
    if data.dtype == np.uint8:  # 8-bit WAV is unsigned
        data = (data.astype(np.float32) - 128.0) / 128.0
    return int(fs), np.ascontiguousarray(data.T)


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    fs, audio = _read_wav(args.wav)
    try:
        geometry = get_array(args.array)
        cfg = replace(LocalizerConfig(), fs=fs, n_sources=args.sources, resolution_deg=args.resolution,
                      coarse_resolution_deg=max(args.resolution, min(4.0, args.min_separation / 2)),
                      band_hz=tuple(args.band), radius_m=args.radius,
                      min_separation_deg=args.min_separation, window_frames=args.window)
        loc = Localizer(geometry, cfg)
        results = loc.process_all(audio, fs) if args.stream else [loc.locate(audio, fs)]
    except (ValueError, FileNotFoundError) as exc:
        print(f"ssl-locate: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps({"file": args.wav, "fs": fs, "array": geometry.name, "windows": [
            {"time_s": round(r.time, 4), "detections": [d.to_dict() for d in r.detections]} for r in results]}))
        return 0
    print(f"{args.wav}: {audio.shape[0]} channels, {audio.shape[1] / fs:.2f} s at {fs} Hz, array {geometry.name}")
    print(f"{'time_s':>8} {'#':>2} {'azimuth_deg':>12} {'elevation_deg':>14} {'power':>7} {'level_dB':>9}")
    for r in results:
        if not r.detections:
            print(f"{r.time:8.3f}  -  (no source)")
        for k, d in enumerate(r.detections):
            print(f"{r.time:8.3f} {k + 1:2d} {d.azimuth_deg:12.1f} {d.elevation_deg:14.1f} {d.power:7.3f} {d.level_db:9.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
