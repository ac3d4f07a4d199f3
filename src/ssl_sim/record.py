"""Recordings a user can take away: what the simulated array hears in a scenario, as an
8-channel 16-bit WAV, plus the ground truth over time as JSON.

    truth = record_scenario(load_scenario("paper_lab"), "rec.wav", seed=0, duration_s=10.0)

The robot stands at the scenario's start (or ``pose``) with its drive stopped; the recording is
the simulated HAL's microphone stream (same physics, acoustics and sensor chain as a scenario
run), channel ``i`` = microphone ``i`` of the ``cube8`` geometry (``ssl-locate --array cube8``).

The truth JSON (``rec.json`` next to ``rec.wav``) holds, per source and per ``frame_s`` frame,
its direction in the ARRAY frame (azimuth CCW from the array's +x, elevation up from the array's
xy-plane, degrees), its distance from the array centre (m), its free-field direct-path level at
the array centre (dB SPL, ``level at 1 m - 20 log10(distance)``, while sounding) and whether it is
sounding (its source signal's RMS in the frame is above -20 dB re its active level: signals are
unit RMS while active, exactly zero in pauses).
"""
from __future__ import annotations

import json
import math
import os
import tempfile
import wave
from dataclasses import replace
from pathlib import Path

import numpy as np

from robot.interrupt import check_interrupt

from ssl_sim.acoustics.materials import OCTAVE_CENTERS_HZ
from ssl_sim.backends import array_frame_directions
from ssl_sim.scenario import Scenario, ScenarioError

#: Frame length (s) of the truth time series.
TRUTH_FRAME_S = 0.1
#: A source counts as sounding in a frame when its signal's RMS is above this (re its active level).
SOUNDING_THRESHOLD_DB = -20.0
_BLOCK_S = 1.0  # audio is read from the HAL in blocks of this length (s)


def parse_pose(text: str) -> tuple[float, float, float]:
    """``"x,y,yaw"`` (world m, m, rad) -> tuple; ValueError naming ``--pose`` otherwise."""
    try:
        vals = tuple(float(v) for v in str(text).split(","))
    except ValueError:
        vals = ()
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise ValueError(f"--pose: expected 'x,y,yaw' (world m, m, rad), got {text!r}")
    return vals  # type: ignore[return-value]


def check_record_paths(out_wav: str | Path, out_json: str | Path | None = None,
                       what: str = "--out") -> tuple[Path, Path]:
    """The WAV and truth JSON paths (JSON default: the WAV's name with ``.json``), checked before recording: a
    file name (not '' nor a directory), the two names distinct, and their folder writable (or creatable: the
    nearest existing ancestor is a writable directory). Nothing is created. ValueError naming ``what``."""
    text = str(out_wav)
    if not text.strip():
        raise ValueError(f"{what}: expected a WAV file name, e.g. rec.wav, got {text!r}")
    wav = Path(text)
    if wav.is_dir() or text.endswith(("/", os.sep)):
        raise ValueError(f"{what} {text}: is a directory; expected a WAV file name, e.g. {wav / 'rec.wav'}")
    truth = Path(out_json) if out_json is not None else wav.with_suffix(".json")
    if truth.absolute() == wav.absolute():
        raise ValueError(f"{what} {text}: the truth JSON is written to the WAV's name with .json, which is this "
                         "name: the JSON would overwrite the recording; give a .wav name, e.g. "
                         f"{wav.with_suffix('.wav')}")
    if truth.is_dir():
        raise ValueError(f"{what} {text}: the truth JSON's name {truth} is a directory")
    folder = wav.absolute().parent
    existing = next(d for d in (folder, *folder.parents) if d.exists())
    if not existing.is_dir():
        raise ValueError(f"{what} {text}: cannot write there: {existing} is a file, not a directory")
    try:
        with tempfile.TemporaryFile(dir=existing, prefix=".write-test-"):
            pass
    except OSError as exc:
        raise ValueError(f"{what} {text}: cannot write in {existing} ({exc.strerror or exc})") from None
    return wav, truth


def record_scenario(scenario: Scenario, out_wav: str | Path, seed: int | None = None, duration_s: float = 10.0,
                    pose: tuple[float, float, float] | None = None, frame_s: float = TRUTH_FRAME_S,
                    out_json: str | Path | None = None) -> dict:
    """Record ``duration_s`` of the scenario's sound at the robot's microphones, standing at ``pose``
    (x, y, yaw; default the scenario's start). Writes ``out_wav`` (int16, one channel per microphone)
    and ``out_json`` (default: ``out_wav`` with suffix ``.json``); returns the truth dict.

    The paths are checked before anything is simulated (``check_record_paths``). The audio streams to disk
    block by block (memory does not grow with the duration). A Ctrl-C (KeyboardInterrupt, raised at the block
    boundaries under ``robot.interrupt.deferred_sigint``) ends the recording early: the WAV and JSON then hold
    what was recorded, ``truth["interrupted"]`` is True (nothing is written when no block was recorded)."""
    if not (isinstance(duration_s, (int, float)) and math.isfinite(duration_s) and duration_s > 0):
        raise ValueError(f"--duration: expected a duration > 0 s, got {duration_s!r}")
    if not frame_s > 0:
        raise ValueError(f"frame_s: expected > 0 s, got {frame_s}")
    out_wav, out_json = check_record_paths(out_wav, out_json)
    sc = scenario.with_overrides(seed=seed)
    if pose is not None:
        sc = replace(sc, robot_start=tuple(float(v) for v in pose))
    try:
        world = sc.world(sc.seed)
    except ScenarioError as exc:
        raise ScenarioError(str(exc).replace("robot.start", "--pose" if pose is not None else "robot.start")) from None
    hal = sc.hal(sc.seed, world=world)
    fs = hal.audio.sample_rate
    n_ch = hal.audio.n_channels
    n_total = int(round(duration_s * fs))
    poses = []
    hal.drive.stop()
    done = 0
    interrupted = False
    out_wav.parent.mkdir(parents=True, exist_ok=True)
    partial = out_wav.with_name(f".{out_wav.name}.partial")   # the finished file replaces any old one at once
    try:
        with wave.open(str(partial), "wb") as w:
            w.setnchannels(n_ch)
            w.setsampwidth(2)
            w.setframerate(fs)
            try:
                while done < n_total:
                    check_interrupt()
                    n = min(int(round(_BLOCK_S * fs)), n_total - done)
                    block = hal.audio.read(n).samples
                    poses.append((done, n, hal.audio.last_array_poses))
                    if block.dtype != np.int16:
                        block = np.clip(np.round(np.asarray(block, float) * 32768.0), -32768, 32767)
                    w.writeframes(np.ascontiguousarray(block.T, dtype="<i2").tobytes())
                    done += n
            except KeyboardInterrupt:
                if not done:
                    raise
                interrupted = True
    except BaseException:
        partial.unlink(missing_ok=True)
        raise
    finally:
        hal.close()
    os.replace(partial, out_wav)

    truth = _truth(hal, poses, fs, done, frame_s)
    truth["rt60_s"] = {  # Eyring, per octave band: what the simulation used and what the scene's materials give
        "octave_hz": list(OCTAVE_CENTERS_HZ),
        "simulated": np.round(hal.acoustics.rt60_bands, 3).tolist(),
        "scene_materials": np.round(hal.acoustics.scene_materials_rt60(), 3).tolist(),
    }
    truth.update(wav=out_wav.name, fs=fs, n_channels=n_ch, duration_s=done / fs, interrupted=interrupted,
                 scenario=sc.name, seed=sc.seed, robot_start={"x": world.robot_start[0], "y": world.robot_start[1],
                                                             "yaw_rad": world.robot_start[2]})
    tmp = out_json.with_name(f".{out_json.name}.partial")
    tmp.write_text(json.dumps(truth, indent=1))
    os.replace(tmp, out_json)
    return truth


def _truth(hal, poses, fs: int, n_total: int, frame_s: float) -> dict:
    """Per-source truth time series on frames of ``frame_s`` (array pose interpolated between the
    pose samples the HAL recorded during each block)."""
    nf = int(round(frame_s * fs))
    starts = np.arange(0, n_total, nf)
    mids = np.minimum(starts + nf / 2.0, n_total)
    # Array poses at the block chunk boundaries: sample index -> (origin, rotation).
    t_idx, origins, rots = [], [], []
    for n0, n, plist in poses:
        for j, (o, r) in enumerate(plist):
            t_idx.append(n0 + n * j / max(1, len(plist) - 1))
            origins.append(o)
            rots.append(r)
    t_idx = np.asarray(t_idx)
    nearest = np.clip(np.searchsorted(t_idx, mids), 0, len(t_idx) - 1)
    sources = hal.acoustics.sources
    out = []
    for src in sources:
        pos = np.asarray(src.position)
        az, el, dist = np.zeros(len(mids)), np.zeros(len(mids)), np.zeros(len(mids))
        for f, k in enumerate(nearest):
            a, e, d = array_frame_directions(origins[k], rots[k], pos[None])
            az[f], el[f], dist[f] = a[0], e[0], d[0]
        # the source signal's RMS per frame, rendered 10 s at a time (an hour at once: 460 MB per source)
        rms = np.empty(len(starts))
        step = max(1, int(10 * fs) // nf)
        for c in range(0, len(starts), step):
            m = min(step, len(starts) - c)
            rms[c:c + m] = np.sqrt(np.mean(src.signal.render(int(starts[c]), m * nf).reshape(m, nf) ** 2, axis=1))
        sounding = rms > 10 ** (SOUNDING_THRESHOLD_DB / 20)
        level = src.level_db_spl - 20 * np.log10(dist)
        out.append({
            "name": src.name, "kind": src.kind, "position_world_m": list(src.position),
            "level_db_spl_at_1m": src.level_db_spl, "buried": src.buried,
            "sounding_fraction": float(sounding.mean()),
            "azimuth_deg": np.round(np.degrees(az), 3).tolist(),
            "elevation_deg": np.round(np.degrees(el), 3).tolist(),
            "distance_m": np.round(dist, 4).tolist(),
            "level_db_spl_at_array": np.round(np.where(sounding, level, np.nan), 2).tolist(),
            "sounding": sounding.tolist(),
        })
    for s in out:  # JSON has no NaN: silent frames have level null
        s["level_db_spl_at_array"] = [None if v != v else v for v in s["level_db_spl_at_array"]]
    return {
        "frame": "array frame: origin at the cube centre, +x forward, +y left, +z up (the robot's axes); "
                 "azimuth CCW from +x, elevation up from the xy-plane, degrees",
        "array": "cube8", "frame_s": frame_s,
        "time_s": np.round(mids / fs, 4).tolist(),
        "sources": out,
    }
