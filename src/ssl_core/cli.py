"""``ssl-locate REC.wav --array cube8 [--sources 3]``: localize the sources in a multichannel WAV.

Default: one whole-recording answer (every source the 128 ms windows find consistently, strongest
first). ``--stream``: every window's detections; ``--track``: tracks over the windows.
The file is read in blocks, so memory stays bounded whatever its length.

Exit codes: 0 done (also when no source was found: stderr says so); 1 no source found and
``--require-source`` given; 2 bad input (file missing, a directory, unreadable, not a WAV, wrong
channel count, bad ``--array`` or option values; one line on stderr naming the file or option).

``--format odas`` writes one JSON object per line in the shape of ODAS's sinks (introlab/odas
``snk_pots``/``snk_tracks``): ``{"timeStamp": k, "src": [...]}`` with ``k`` the window index
(ODAS counts hops). Without ``--track`` (SSL shape) each entry is ``{"x", "y", "z", "E"}``: the
detection's unit vector (array frame) and its SRP power; with ``--track`` (SST shape)
``{"id", "tag", "x", "y", "z", "activity"}``: the track id, tag ``"dynamic"``, its unit vector and
activity probability.
"""
from __future__ import annotations

import argparse
import json
import sys
from dataclasses import replace

from ssl_core.geometry import get_array
from ssl_core.localizer import Localizer, LocalizerConfig
from ssl_core.wav_blocks import read_blocks, wav_info

EXIT_OK, EXIT_NO_SOURCE, EXIT_BAD_INPUT = 0, 1, 2
_BLOCK_S = 1.0  # seconds read per block: bounded memory, few Python round trips


class _BadInput(Exception):
    """One-line message for stderr; exit code 2."""


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="ssl-locate", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("wav", help="multichannel WAV file (one channel per microphone)")
    p.add_argument("--array", default="cube8", help="array preset (cube8, cube8_corners) or .toml/.json geometry")
    p.add_argument("--sources", type=int, default=1, help="maximum number of sources to report (>= 1)")
    p.add_argument("--resolution", type=float, default=1.5, help="final grid resolution (degrees)")
    p.add_argument("--band", type=float, nargs=2, default=(300.0, 6000.0), metavar=("LOW", "HIGH"),
                   help="analysis band (Hz)")
    p.add_argument("--radius", type=float, default=None, help="near-field grid radius (m); far field if omitted")
    p.add_argument("--min-separation", type=float, default=20.0, help="minimum angle between sources (degrees)")
    p.add_argument("--noise-suppression", action="store_true",
                   help="weight bins by their power above a noise floor (reveals voices beside steady noise)")
    p.add_argument("--stream", action="store_true", help="print detections per analysis window instead of one summary")
    p.add_argument("--track", action="store_true", help="print tracks (ssl_core.tracking) per analysis window")
    p.add_argument("--window", type=int, default=8, help="STFT frames per analysis window")
    p.add_argument("--format", choices=("table", "json", "odas"), default="table", help="output format")
    p.add_argument("--json", action="store_true", help="same as --format json")
    p.add_argument("--require-source", action="store_true", help="exit with code 1 when no source is found")
    return p


def _open(path: str):
    try:
        return wav_info(path)
    except FileNotFoundError:
        raise _BadInput(f"{path}: no such file")
    except IsADirectoryError:
        raise _BadInput(f"{path}: is a directory, expected a WAV file")
    except PermissionError:
        raise _BadInput(f"{path}: permission denied")
    except OSError as exc:
        raise _BadInput(f"{path}: cannot read: {exc.strerror or exc}")
    except ValueError as exc:
        raise _BadInput(str(exc))


def _localizer(args, fs: int) -> Localizer:
    if args.sources < 1:
        raise _BadInput(f"--sources {args.sources}: expected an integer >= 1")
    try:
        geometry = get_array(args.array)
    except (OSError, ValueError, KeyError) as exc:
        what = exc.strerror if isinstance(exc, OSError) and exc.strerror else exc
        raise _BadInput(f"--array {args.array}: {what}")
    try:
        cfg = replace(LocalizerConfig(), fs=fs, n_sources=args.sources, resolution_deg=args.resolution,
                      coarse_resolution_deg=max(args.resolution, min(4.0, args.min_separation / 2)),
                      band_hz=tuple(args.band), radius_m=args.radius, noise_suppression=args.noise_suppression,
                      min_separation_deg=args.min_separation, window_frames=args.window)
        return Localizer(geometry, cfg)
    except ValueError as exc:
        raise _BadInput(str(exc))


def _blocks(info, loc: Localizer):
    if info.channels != loc.geometry.n_mics:
        raise _BadInput(f"{info.path}: {info.channels} channels, array '{loc.geometry.name}' expects "
                        f"{loc.geometry.n_mics}")
    if info.n_frames < loc.config.frame_size:
        raise _BadInput(f"{info.path}: too short ({info.n_frames} samples), need at least "
                        f"{loc.config.frame_size}")
    return read_blocks(info, max(loc.config.frame_size, int(_BLOCK_S * info.fs)))


def _vec(u) -> dict:
    return {"x": round(float(u[0]), 4), "y": round(float(u[1]), 4), "z": round(float(u[2]), 4)}


def _run(args) -> int:
    fmt = "json" if args.json else args.format
    info = _open(args.wav)
    loc = _localizer(args, info.fs)
    blocks = _blocks(info, loc)
    out = sys.stdout
    found = False
    if not (args.stream or args.track):
        try:
            result = loc.locate_blocks(blocks)
        except ValueError as exc:
            raise _BadInput(f"{info.path}: {exc}")
        found = bool(result.detections)
        if fmt == "json":
            print(json.dumps({"file": args.wav, "fs": info.fs, "array": loc.geometry.name, "windows": [
                {"time_s": round(result.time, 4), "detections": [d.to_dict() for d in result.detections]}]}), file=out)
        elif fmt == "odas":
            print(json.dumps({"timeStamp": 0, "src": [{**_vec(d.direction), "E": round(d.power, 4)}
                                                      for d in result.detections]}), file=out)
        else:
            _table_header(args, info, loc)
            _table_rows(result.time, result.detections)
    else:
        tracker = _tracker() if args.track else None
        windows = []
        if fmt == "table":
            _table_header(args, info, loc, tracks=tracker is not None)
        k = 0
        for block in blocks:
            try:
                results = loc.process(block)
            except ValueError as exc:
                raise _BadInput(f"{info.path}: {exc}")
            for r in results:
                if tracker is not None:
                    items = tracker.update(r.detections, r.time)
                else:
                    items = r.detections
                found = found or bool(items)
                if fmt == "json":
                    key = "tracks" if tracker is not None else "detections"
                    windows.append({"time_s": round(r.time, 4), key: [_item_dict(i) for i in items]})
                elif fmt == "odas":
                    src = ([{"id": t.id, "tag": "dynamic", **_vec(t.direction), "activity": round(t.activity, 3)}
                            for t in items] if tracker is not None else
                           [{**_vec(d.direction), "E": round(d.power, 4)} for d in items])
                    print(json.dumps({"timeStamp": k, "src": src}), file=out)
                elif tracker is not None:
                    _track_rows(r.time, items)
                else:
                    _table_rows(r.time, items)
                k += 1
        if fmt == "json":
            print(json.dumps({"file": args.wav, "fs": info.fs, "array": loc.geometry.name, "windows": windows}),
                  file=out)
    if not found:
        print(f"ssl-locate: {args.wav}: no source detected (no peak passed the significance test)", file=sys.stderr)
        return EXIT_NO_SOURCE if args.require_source else EXIT_OK
    return EXIT_OK


def _tracker():
    try:
        from ssl_core.tracking import Tracker
    except ImportError as exc:  # the tracker is a separate module of ssl_core
        raise _BadInput(f"--track: tracking is not available ({exc})")
    return Tracker()


def _item_dict(item) -> dict:
    if hasattr(item, "to_dict"):
        return item.to_dict()
    return {"id": item.id, "azimuth_deg": round(item.azimuth_deg, 3), "elevation_deg": round(item.elevation_deg, 3),
            "activity": round(item.activity, 3), "power": round(item.power, 5), "level_db": round(item.level_db, 2)}


def _table_header(args, info, loc, tracks: bool = False) -> None:
    print(f"{args.wav}: {info.channels} channels, {info.duration_s:.2f} s at {info.fs} Hz, array {loc.geometry.name}")
    if tracks:
        print(f"{'time_s':>8} {'id':>4} {'azimuth_deg':>12} {'elevation_deg':>14} {'activity':>9} {'level_dB':>9}")
    else:
        print(f"{'time_s':>8} {'#':>2} {'azimuth_deg':>12} {'elevation_deg':>14} {'power':>7} {'signif':>7} "
              f"{'level_dB':>9}")


def _table_rows(time: float, detections) -> None:
    if not detections:
        print(f"{time:8.3f}  -  (no source)")
    for k, d in enumerate(detections):
        print(f"{time:8.3f} {k + 1:2d} {d.azimuth_deg:12.1f} {d.elevation_deg:14.1f} {d.power:7.3f} "
              f"{d.significance:7.1f} {d.level_db:9.1f}")


def _track_rows(time: float, tracks) -> None:
    if not tracks:
        print(f"{time:8.3f}    -  (no track)")
    for t in tracks:
        print(f"{time:8.3f} {t.id:4d} {t.azimuth_deg:12.1f} {t.elevation_deg:14.1f} {t.activity:9.2f} "
              f"{t.level_db:9.1f}")


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)  # argparse exits with 2 on a usage error, as documented
    try:
        return _run(args)
    except _BadInput as exc:
        print(f"ssl-locate: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
