"""``ssl-locate REC.wav --array cube8 [--sources 3]``: localize the sources in a multichannel WAV.

Default: one whole-recording answer (every source the 128 ms windows find consistently, most consistent
first). ``--stream``: every window's detections; ``--track``: the confirmed tracks
(``ssl_core.tracking.Tracker``) after every window, fed with detections at the tracking gate
``TRACKING_MIN_SIGNIFICANCE``.
The file is read in blocks, so memory stays bounded whatever its length.

A truncated file (its header declares more samples than it holds) is named on stderr with both lengths, and
the samples present are processed.

Exit codes: 0 done (also when no source was found: stderr says so); 1 no source found and
``--require-source`` given; 2 bad input (file missing, a directory, unreadable, not a WAV, wrong
channel count, bad ``--array`` or option values; one line on stderr naming the file or option).

``--truth REC.json`` scores the per-window detections (or, with ``--track``, the confirmed tracks) against the
truth JSON ``ssl-rescue record`` writes beside its WAV: per source its direction error and detection rate, and
the false-alarm rate (definitions in ``ssl_core.scoring``); prints a table, or one JSON object with ``--json``.

``--stream --json`` / ``--track --json`` print one JSON object per analysis window and line, as the windows
come: ``{"time_s": t, "detections": [...]}`` / ``{"time_s": t, "tracks": [...]}``.

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
import re
import sys
from dataclasses import replace
from typing import TYPE_CHECKING

from ssl_core.broken_pipe import quiet_on_broken_pipe
from ssl_core.version import version

# The localizer's modules import scipy.signal (seconds): they are imported once the arguments are parsed, so that
# --help and usage errors answer at once.
if TYPE_CHECKING:
    from ssl_core.detection import Detection
    from ssl_core.localizer import Localizer
    from ssl_core.tracking import Track

#: Analysis band (Hz) when ``--band`` is not given.
DEFAULT_BAND_HZ = (300.0, 6000.0)
EXIT_OK, EXIT_NO_SOURCE, EXIT_BAD_INPUT = 0, 1, 2
_BLOCK_S = 1.0  # seconds read per block: bounded memory, few Python round trips


class _BadInput(Exception):
    """One-line message for stderr; exit code 2."""


def _unreadable(label: str, exc: OSError, expected: str) -> _BadInput:
    """Why the file ``label`` (the path, or the option and path) could not be opened, in one line."""
    if isinstance(exc, FileNotFoundError):
        return _BadInput(f"{label}: no such file")
    if isinstance(exc, IsADirectoryError):
        return _BadInput(f"{label}: is a directory, expected {expected}")
    if isinstance(exc, PermissionError):
        return _BadInput(f"{label}: permission denied")
    return _BadInput(f"{label}: cannot read: {exc.strerror or exc}")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="ssl-locate", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--version", action="version", version=f"%(prog)s {version()}")
    p.add_argument("wav", help="multichannel WAV file (one channel per microphone)")
    p.add_argument("--array", default="cube8", help="array preset (cube8, cube8_corners) or .toml/.json geometry")
    p.add_argument("--sources", type=int, default=1, help="maximum number of sources to report (>= 1)")
    p.add_argument("--resolution", type=float, default=1.5, help="final grid resolution (degrees)")
    p.add_argument("--band", type=float, nargs=2, default=None, metavar=("LOW", "HIGH"),
                   help="analysis band (Hz) (default: %g %g; the file's sample rate must be at least twice HIGH)"
                        % DEFAULT_BAND_HZ)
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
    p.add_argument("--truth", metavar="REC.json", default=None,
                   help="score the detections per window against this truth (the JSON `ssl-rescue record` writes): "
                        "per-source error and detection rate, false-alarm rate")
    p.add_argument("--truth-tolerance", type=float, default=20.0, metavar="DEG",
                   help="with --truth: a detection within this angle of a sounding source is a hit of it "
                        "(default: %(default)s)")
    return p


def _open(path: str):
    from ssl_core.wav_blocks import wav_info

    try:
        return wav_info(path)
    except OSError as exc:
        raise _unreadable(path, exc, "a WAV file") from None
    except ValueError as exc:
        raise _BadInput(str(exc))


def _localizer(args, fs: int) -> Localizer:
    from ssl_core.geometry import get_array
    from ssl_core.localizer import Localizer, LocalizerConfig
    from ssl_core.tracking import TRACKING_MIN_SIGNIFICANCE

    if args.band is None and fs < 2 * DEFAULT_BAND_HZ[1]:
        raise _BadInput(f"{args.wav}: sample rate {fs} Hz is too low for the default analysis band "
                        f"{DEFAULT_BAND_HZ[0]:g}-{DEFAULT_BAND_HZ[1]:g} Hz (it needs at least "
                        f"{2 * DEFAULT_BAND_HZ[1]:g} Hz): record or resample at 16000 Hz, or give a band below "
                        f"{fs / 2:g} Hz with --band LOW HIGH")
    band = tuple(args.band) if args.band is not None else DEFAULT_BAND_HZ
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
                      band_hz=band, radius_m=args.radius, noise_suppression=args.noise_suppression,
                      min_separation_deg=args.min_separation, window_frames=args.window)
        if args.track:  # the tracker's confirmation is the false-alarm control: the looser gate it is tuned for
            cfg = replace(cfg, min_significance=TRACKING_MIN_SIGNIFICANCE)
        return Localizer(geometry, cfg)
    except ValueError as exc:
        message = _with_option(args, str(exc))
        if message.startswith("--band") and "fs/2" in message:
            message = f"{message} (the file {args.wav} is sampled at {fs} Hz)"
        raise _BadInput(message)


# The option that sets each LocalizerConfig field an error can name.
_OPTION_OF_FIELD = {"resolution_deg": "--resolution", "coarse_resolution_deg": "--resolution", "band_hz": "--band",
                    "window_frames": "--window", "radius_m": "--radius", "min_separation_deg": "--min-separation",
                    "n_sources": "--sources"}


def _with_option(args, message: str) -> str:
    """``message`` prefixed with the command-line option (and its value) behind the field it names."""
    m = re.match(r"LocalizerConfig\.(\w+)=", message)
    field = m.group(1) if m else next((f for f in ("band_hz", "radius") if f in message), None)
    option = _OPTION_OF_FIELD.get("radius_m" if field == "radius" else field)
    if option is None:
        return message
    return f"{option} {_shown(getattr(args, option[2:].replace('-', '_')))}: {message}"


def _shown(value) -> str:
    return " ".join(f"{v:g}" for v in value) if isinstance(value, (tuple, list)) else f"{value:g}"


def _blocks(info, loc: Localizer):
    from ssl_core.wav_blocks import read_blocks

    if info.channels != loc.geometry.n_mics:
        raise _BadInput(f"{info.path}: {info.channels} channels, array '{loc.geometry.name}' expects "
                        f"{loc.geometry.n_mics}")
    if info.n_frames < loc.config.frame_size:
        raise _BadInput(f"{info.path}: too short ({info.n_frames} samples), need at least "
                        f"{loc.config.frame_size}")
    return read_blocks(info, max(loc.config.frame_size, int(_BLOCK_S * info.fs)))


def _run(args) -> int:
    fmt = "json" if args.json else args.format
    if args.truth is not None and fmt == "odas":
        raise _BadInput("--truth prints scores: use it with the table or --json, not --format odas")
    info = _open(args.wav)
    if info.truncated:   # processed, but never silently: the user may hold a copy cut short
        print(f"ssl-locate: warning: {info.truncation()}; processing the {info.duration_s:.3f} s present",
              file=sys.stderr)
    truth, truth_array = _truth(args, info) if args.truth is not None else (None, None)
    loc = _localizer(args, info.fs)
    blocks = _blocks(info, loc)
    if truth is not None:
        if truth_array is not None and truth_array != loc.geometry.name:
            raise _BadInput(f"--truth {args.truth}: directions are in the frame of array '{truth_array}', "
                            f"--array {args.array} is '{loc.geometry.name}'")
        return _score(args, fmt, info, loc, blocks, truth)
    try:
        found = (_per_window if args.stream or args.track else _whole)(args, fmt, info, loc, blocks)
    except ValueError as exc:  # bad samples found while reading (NaN in a float WAV)
        raise _BadInput(f"{info.path}: {exc}")
    if not found:
        print(f"ssl-locate: {args.wav}: no source detected (no peak passed the significance test)", file=sys.stderr)
        return EXIT_NO_SOURCE if args.require_source else EXIT_OK
    return EXIT_OK


def _truth(args, info):
    """The ``--truth`` file as a ``ssl_core.scoring.Scorer`` and the array its directions refer to (None: not
    said); bad input names the file and the field."""
    from ssl_core.scoring import Scorer, Truth

    path = args.truth
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except OSError as exc:
        raise _unreadable(f"--truth {path}", exc, "the truth JSON of a recording") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise _BadInput(f"--truth {path}: not a JSON file ({exc})")
    try:
        truth = Truth.from_dict(data, where=f"--truth {path}")
        scorer = Scorer(truth, args.truth_tolerance)
    except ValueError as exc:
        msg = str(exc)
        raise _BadInput(msg if msg.startswith("--truth") else f"--truth-tolerance {args.truth_tolerance:g}: {msg}")
    if isinstance(data.get("fs"), int) and data["fs"] != info.fs:
        raise _BadInput(f"--truth {path}: is the truth of a recording at {data['fs']} Hz, {args.wav} is at "
                        f"{info.fs} Hz")
    return scorer, (data.get("array") if isinstance(data.get("array"), str) else None)


def _score(args, fmt: str, info, loc: Localizer, blocks, scorer) -> int:
    """Every window's detections (``--track``: confirmed tracks) scored against the truth; prints the scores."""
    import numpy as np

    from ssl_core.tracking import Tracker

    tracker = Tracker() if args.track else None
    cfg = loc.config
    half_window_s = ((cfg.window_frames - 1) * cfg.hop + cfg.frame_size) / (2.0 * info.fs)
    try:
        for block in blocks:
            for r in loc.process(block):
                items = tracker.update(r.detections, r.time) if tracker is not None else r.detections
                dirs = np.array([it.direction for it in items], float).reshape(-1, 3)
                scorer.add(r.time - half_window_s, dirs)
    except ValueError as exc:
        raise _BadInput(f"{info.path}: {exc}")
    result = scorer.to_dict()
    if fmt == "json":
        print(json.dumps({"file": args.wav, "truth": args.truth, "fs": info.fs, "array": loc.geometry.name,
                          "scored": "tracks" if tracker is not None else "detections", **result}))
        return EXIT_OK
    what = "confirmed tracks" if tracker is not None else "detections"
    print(f"{args.wav} against {args.truth}: {result['windows']} windows, {result['detections']} {what}, "
          f"hit = within {result['tolerance_deg']:g} deg of a sounding source")
    print(f"{'source':<16} {'sounding':>8} {'hits':>6} {'det_rate':>8} {'err_med_deg':>11} {'err_p90_deg':>11}")
    for s in result["sources"]:
        print(f"{s['name']:<16} {s['windows_sounding']:8d} {s['hits']:6d} {_cell(s['detection_rate'], 3):>8} "
              f"{_cell(s['error_median_deg'], 1):>11} {_cell(s['error_p90_deg'], 1):>11}")
    print(f"false alarms: {result['false_alarms']} of {result['detections']} {what} "
          f"(rate {_cell(result['false_alarm_rate'], 3)}, {_cell(result['false_alarms_per_window'], 3)} per window)")
    return EXIT_OK


def _cell(v, nd: int) -> str:
    return "-" if v is None else f"{v:.{nd}f}"


def _whole(args, fmt: str, info, loc: Localizer, blocks) -> bool:
    """The whole-recording answer; returns whether it holds a source."""
    result = loc.locate_blocks(blocks)
    if fmt == "json":
        print(json.dumps({"file": args.wav, "fs": info.fs, "array": loc.geometry.name, "windows": [
            {"time_s": round(result.time, 4), "detections": [d.to_dict() for d in result.detections]}]}))
    elif fmt == "odas":
        print(json.dumps({"timeStamp": 0, "src": [_odas_pot(d) for d in result.detections]}))
    else:
        _table_header(args, info, loc)
        _table_rows(result.time, result.detections)
    return bool(result.detections)


def _per_window(args, fmt: str, info, loc: Localizer, blocks) -> bool:
    """Detections (``--stream``) or confirmed tracks (``--track``) after every window, printed as they come
    (JSON: one object per window and line); returns whether any window had one."""
    from ssl_core.tracking import Tracker

    tracker = Tracker() if args.track else None
    found, k = False, 0
    if fmt == "table":
        _table_header(args, info, loc, tracks=tracker is not None)
    for block in blocks:
        for r in loc.process(block):
            items = tracker.update(r.detections, r.time) if tracker is not None else r.detections
            found = found or bool(items)
            if tracker is not None:
                if fmt == "json":
                    _json_line({"time_s": round(r.time, 4), "tracks": [_track_dict(t) for t in items]})
                elif fmt == "odas":
                    _json_line({"timeStamp": k, "src": [_odas_track(t) for t in items]})
                else:
                    _track_rows(r.time, items)
            elif fmt == "json":
                _json_line({"time_s": round(r.time, 4), "detections": [d.to_dict() for d in items]})
            elif fmt == "odas":
                _json_line({"timeStamp": k, "src": [_odas_pot(d) for d in items]})
            else:
                _table_rows(r.time, items)
            k += 1
    return found


def _json_line(obj: dict) -> None:
    """One JSON line, flushed: a reader of the pipe gets each window when it is done."""
    print(json.dumps(obj), flush=True)


def _odas_pot(d: Detection) -> dict:
    """ODAS SSL (``snk_pots``) entry: unit vector, array frame, and the SRP power as the energy ``E``."""
    u = d.direction
    return {"x": round(float(u[0]), 4), "y": round(float(u[1]), 4), "z": round(float(u[2]), 4), "E": round(d.power, 4)}


def _odas_track(t: Track) -> dict:
    """ODAS SST (``snk_tracks``) entry: id, tag, unit vector (array frame), activity probability."""
    u = t.direction
    return {"id": t.id, "tag": "dynamic", "x": round(float(u[0]), 4), "y": round(float(u[1]), 4),
            "z": round(float(u[2]), 4), "activity": round(t.activity, 3)}


def _track_dict(t: Track) -> dict:
    return {"id": t.id, "azimuth_deg": round(t.azimuth_deg, 3), "elevation_deg": round(t.elevation_deg, 3),
            "activity": round(t.activity, 3), "power": round(t.power, 5), "level_db": round(t.level_db, 2)}


def _table_header(args, info, loc, tracks: bool = False) -> None:
    print(f"{args.wav}: {info.channels} channels, {info.duration_s:.2f} s at {info.fs} Hz, array {loc.geometry.name}")
    if tracks:
        print(f"{'time_s':>8} {'id':>4} {'azimuth_deg':>12} {'elevation_deg':>14} {'activity':>9} {'level_dB':>9}")
    else:
        print(f"{'time_s':>8} {'#':>2} {'azimuth_deg':>12} {'elevation_deg':>14} {'power':>7} {'signif':>7} "
              f"{'level_dB':>9}")


def _table_rows(time: float, detections) -> None:
    if not detections:
        print(f"{time:8.3f}  -  (no source)", flush=True)
    for k, d in enumerate(detections):
        print(f"{time:8.3f} {k + 1:2d} {d.azimuth_deg:12.1f} {d.elevation_deg:14.1f} {d.power:7.3f} "
              f"{d.significance:7.1f} {d.level_db:9.1f}")


def _track_rows(time: float, tracks) -> None:
    if not tracks:
        print(f"{time:8.3f}    -  (no track)", flush=True)
    for t in tracks:
        print(f"{time:8.3f} {t.id:4d} {t.azimuth_deg:12.1f} {t.elevation_deg:14.1f} {t.activity:9.2f} "
              f"{t.level_db:9.1f}")


@quiet_on_broken_pipe
def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)  # argparse exits with 2 on a usage error, as documented
    try:
        return _run(args)
    except _BadInput as exc:
        print(f"ssl-locate: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    sys.exit(main())
