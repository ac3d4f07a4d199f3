"""The whole-recording answer (``ssl-locate REC.wav``, Localizer.locate) against simulated truth.

Recordings come from the ssl_sim lab (experiments.common: image-source room, diffuse noise, sensor
model); truth is the geometry put in. Each recording is generated once per module.
"""
from __future__ import annotations

import json
from functools import lru_cache

import numpy as np
import pytest
from scipy.io import wavfile

from experiments.common import Lab, Truth, build_sim, match, with_sensor_noise
from ssl_core.cli import main

FS = 16000


@lru_cache(maxsize=None)
def _recording(truths: tuple[Truth, ...], seed: int, duration_s: float, rt60_s: float, snr_db: float | None = None,
               p_event: float = 1.0, array_height_m: float = 1.7) -> np.ndarray:
    lab = Lab(duration_s=duration_s, rt60_s=rt60_s, array_height_m=array_height_m)
    x = build_sim(lab, list(truths), seed, p_event=p_event).listen_pose(lab.pose, duration_s, mount=lab.mount)
    return x if snr_db is None else np.clip(with_sensor_noise(x, snr_db, seed), -1, 1)


def _cli(tmp_path, capsys, x: np.ndarray, *args: str) -> list[dict]:
    """``ssl-locate REC.wav --json ARGS`` on ``x`` written as 16-bit WAV; the whole-recording detections."""
    path = tmp_path / "rec.wav"
    wavfile.write(path, FS, (x if x.dtype == np.int16 else np.round(x * 32767).astype(np.int16)).T)
    capsys.readouterr()
    assert main([str(path), "--json", *args]) == 0
    return json.loads(capsys.readouterr().out)["windows"][0]["detections"]


class _Det:  # what experiments.common.match needs: a unit vector
    def __init__(self, d: dict):
        az, el = np.deg2rad(d["azimuth_deg"]), np.deg2rad(d["elevation_deg"])
        self.direction = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def _errors(dets: list[dict], truths) -> list[float]:
    return [e for _, _, e in match([_Det(d) for d in dets], list(truths))]


@pytest.mark.parametrize("case, truths, kwargs", [
    ("SNR 5 dB, 1.5 m, RT60 0.5", (Truth(40.0, 10.0, 1.5),), dict(duration_s=3.0, rt60_s=0.5, snr_db=5.0)),
    ("3 m away, RT60 0.9", (Truth(-20.0, -5.0, 3.0),), dict(duration_s=3.0, rt60_s=0.9)),
    ("10 s intermittent, 2.5 m, RT60 0.6, SNR 15", (Truth(150.0, 20.0, 2.5),),
     dict(duration_s=10.0, rt60_s=0.6, snr_db=15.0, p_event=0.4)),
])
@pytest.mark.parametrize("seed", [7, 8])
def test_one_talker_within_5_degrees(tmp_path, capsys, case, truths, kwargs, seed):
    dets = _cli(tmp_path, capsys, _recording(truths, seed, **kwargs))
    assert dets, f"{case}: no source"
    assert _errors(dets[:1], truths)[0] <= 5.0, (case, dets)


def _spread_truths(k: int, seed: int) -> tuple[Truth, ...]:
    """``k`` talkers 2 m away, azimuths at least 40 deg apart, elevations -20..30 deg (seeded)."""
    rng = np.random.default_rng(seed)
    while True:
        az = rng.uniform(-180, 180, k)
        gaps = np.abs((az[:, None] - az[None, :] + 180) % 360 - 180) + 1e3 * np.eye(k)
        if gaps.min() >= 40:
            return tuple(Truth(float(a), float(rng.uniform(-20, 30)), 2.0) for a in az)


@pytest.mark.parametrize("k", [2, 3])
def test_k_talkers_all_found_within_10_degrees(tmp_path, capsys, k):
    ok = 0
    for trial in range(4):
        truths = _spread_truths(k, 100 * k + trial)
        dets = _cli(tmp_path, capsys, _recording(truths, 20 + trial, duration_s=3.0, rt60_s=0.4), "--sources", str(k))
        ok += len(dets) == k and max(_errors(dets, truths)) <= 10.0
    assert ok >= 3, f"all {k} found in {ok} of 4 trials"


def test_paper_three_sources_within_5_degrees(tmp_path, capsys):
    truths = (Truth(-135.0, 35.0, 2.0), Truth(90.0, 75.0, 2.0), Truth(145.0, 60.0, 2.0))
    x = _recording(truths, 3, duration_s=3.0, rt60_s=0.5, array_height_m=1.2)  # as experiments/exp3
    dets = _cli(tmp_path, capsys, x, "--sources", "3")
    assert len(dets) == 3
    assert max(_errors(dets, truths)) <= 5.0, dets


def test_track_and_odas_formats(tmp_path, capsys):
    truth = Truth(60.0, 10.0, 1.5)
    x = _recording((truth,), 5, duration_s=4.0, rt60_s=0.5)
    path = tmp_path / "rec.wav"
    wavfile.write(path, FS, x.T)
    capsys.readouterr()
    # --track --format odas: ODAS SST lines, one per window, a confirmed track on the talker
    assert main([str(path), "--track", "--format", "odas"]) == 0
    lines = [json.loads(s) for s in capsys.readouterr().out.splitlines()]
    assert [m["timeStamp"] for m in lines] == list(range(len(lines))) and len(lines) >= 25
    last = lines[-1]["src"]
    assert len(last) == 1 and set(last[0]) == {"id", "tag", "x", "y", "z", "activity"}
    u = np.array([last[0]["x"], last[0]["y"], last[0]["z"]])
    assert last[0]["id"] == 1 and last[0]["tag"] == "dynamic" and 0 <= last[0]["activity"] <= 1
    assert np.rad2deg(np.arccos(np.clip(u @ truth.direction / np.linalg.norm(u), -1, 1))) <= 5.0
    # --stream --format odas: ODAS SSL lines with the detections' power as E
    assert main([str(path), "--stream", "--format", "odas"]) == 0
    pots = [json.loads(s) for s in capsys.readouterr().out.splitlines()]
    assert len(pots) == len(lines) and any(p["src"] for p in pots)
    assert all(set(e) == {"x", "y", "z", "E"} for p in pots for e in p["src"])
    # --track as a table and as JSON
    assert main([str(path), "--track"]) == 0
    assert "activity" in capsys.readouterr().out
    assert main([str(path), "--track", "--json"]) == 0
    tracks = [json.loads(s) for s in capsys.readouterr().out.splitlines()][-1]["tracks"]  # one line per window
    assert tracks[0]["id"] == 1 and abs(tracks[0]["azimuth_deg"] - 60.0) <= 5.0
