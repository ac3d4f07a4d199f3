"""Voice activity detectors side by side on the real-sound data set's TEST part (data/sounds).

Per category: the share of labelled 1 s chunks (hop 0.5 s) called speech (recall for speech,
false-alarm rate for the rest), then precision/recall over all categories; for Silero VAD
(onnxruntime, the chosen one), WebRTC VAD (webrtcvad-wheels, modes 2 and 3) and the old
hand-made score ``robot.voice.voice_likeness``. A chunk is called speech when its statistic (the
fraction of speech frames for a frame-wise VAD, the score for the old one) reaches a threshold
chosen per detector on the DEV part (best recall minus false-alarm rate), so each gets its fairest rule.
Then the CPU cost per second of audio (one core, process time) of Silero for 1 and 4 streams
(4 tracks' beams, 100 ms blocks), of WebRTC and of the old score, and of the whole
robot.hearing.Hearing (beams + VAD + filter) for 4 tracks.

    PYTHONPATH=src python benchmarks/bench_voice.py
"""
from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import numpy as np  # noqa: E402

from robot.vad import SileroVad, speech_fraction  # noqa: E402
from robot.voice import voice_likeness  # noqa: E402
from sound_dataset import FS, chunk_starts, recordings  # noqa: E402

THRESHOLDS = np.round(np.arange(0.05, 1.0, 0.05), 2)


def _webrtc(mode: int):
    import webrtcvad

    def frames(x: np.ndarray) -> tuple[np.ndarray, float]:
        v = webrtcvad.Vad(mode)
        pcm = np.clip(x * 32767, -32768, 32767).astype(np.int16)
        n = 480  # 30 ms
        return np.array([v.is_speech(pcm[i:i + n].tobytes(), FS) for i in range(0, len(pcm) - n + 1, n)], float), 0.03
    return frames


def _silero():
    vad = SileroVad()
    return lambda x: (vad.probabilities(x), vad.frame_s)


def evaluate(split: str = "test") -> dict:
    recs = recordings(split)
    detectors = {"silero (onnxruntime)": _silero(), "webrtc mode 3": _webrtc(3), "webrtc mode 2": _webrtc(2)}
    table: dict[str, dict[str, list[int]]] = {}
    for name, det in detectors.items():
        for r in recs:
            p, frame_s = det(r.samples)
            per_chunk = int(round(1.0 / frame_s))
            for s in chunk_starts(r):
                i0 = int(round(s / FS / frame_s))
                table.setdefault(name, {}).setdefault(r.category, []).append(speech_fraction(p[i0:i0 + per_chunk]))
    for r in recs:
        for s in chunk_starts(r):
            table.setdefault("old voice_likeness", {}).setdefault(r.category, []).append(
                voice_likeness(r.samples[s:s + FS], FS).score)
    return table


def tune(dev: dict) -> dict[str, float]:
    """Per detector: the chunk threshold maximising speech recall minus non-speech false alarms on dev."""
    out = {}
    for m, t in dev.items():
        pos = np.array(t["speech"])
        neg = np.concatenate([v for c, v in t.items() if c not in ("speech", "shouts")])
        j = [(pos >= th).mean() - (neg >= th).mean() for th in THRESHOLDS]
        best = np.flatnonzero(np.isclose(j, max(j)))
        out[m] = float(THRESHOLDS[best[len(best) // 2]])  # middle of the best plateau
    return out


def cost(seconds: float = 10.0) -> dict:
    rng = np.random.default_rng(0)
    x = 0.05 * rng.standard_normal(int(seconds * FS))
    out = {}
    for n in (1, 4):
        vad = SileroVad()
        streams = [vad.new_stream() for _ in range(n)]
        t = time.process_time()
        for i in range(0, len(x), FS // 10):
            vad.process(streams, [x[i:i + FS // 10]] * n)
        out[f"silero_{n}_streams_ms_per_s"] = (time.process_time() - t) / seconds * 1e3
    t = time.process_time()
    _webrtc(3)(x)
    out["webrtc_1_stream_ms_per_s"] = (time.process_time() - t) / seconds * 1e3
    t = time.process_time()
    for i in range(0, len(x) - FS + 1, FS):
        voice_likeness(x[i:i + FS], FS)
    out["old_score_1_stream_ms_per_s"] = (time.process_time() - t) / seconds * 1e3
    try:
        out.update(_hearing_cost(seconds))
    except ImportError:  # robot.hearing not available in this checkout
        pass
    return out


def _hearing_cost(seconds: float) -> dict:
    from types import SimpleNamespace

    from robot.hearing import Hearing, HearingConfig
    from ssl_core.geometry import cube8

    geo = cube8()
    rng = np.random.default_rng(1)
    block = FS // 10
    tracks = [SimpleNamespace(id=i, direction=np.array([np.cos(a), np.sin(a), 0.0]), activity=1.0) for i, a in enumerate(np.deg2rad([0, 90, 180, 270]))]
    hearing = Hearing(geo.positions, FS, HearingConfig())
    t = time.process_time()
    for k in range(int(seconds * 10)):
        hearing.update(0.01 * rng.standard_normal((8, block)), tracks, (k + 1) * block / FS)
    return {"hearing_4_tracks_ms_per_s": (time.process_time() - t) / seconds * 1e3}


def main() -> None:
    th = tune(evaluate("dev"))
    table = {m: {c: [int(v >= th[m]) for v in vals] for c, vals in t.items()} for m, t in evaluate("test").items()}
    cats = sorted({c for t in table.values() for c in t}, key=lambda c: (c not in ("speech", "shouts"), c))
    names = list(table)
    print("test part, 1 s chunks called speech (%); chunk thresholds tuned on dev: "
          + ", ".join(f"{m} {th[m]:.2f}" for m in names))
    print("| category | n | " + " | ".join(names) + " |")
    print("|---|---|" + "---|" * len(names))
    for c in cats:
        n = len(table[names[0]][c])
        print(f"| {c} | {n} | " + " | ".join(f"{100 * np.mean(table[m][c]):.0f}" for m in names) + " |")
    summary = {}
    for m in names:
        tp = sum(table[m]["speech"])
        fn = len(table[m]["speech"]) - tp
        fp = sum(sum(v) for c, v in table[m].items() if c not in ("speech", "shouts"))
        n_neg = sum(len(v) for c, v in table[m].items() if c not in ("speech", "shouts"))
        summary[m] = {"speech_recall": tp / (tp + fn), "precision": tp / max(tp + fp, 1), "false_alarm_rate": fp / n_neg,
                      "shouts_called_speech": float(np.mean(table[m]["shouts"]))}
    print("| overall (speech vs non-speech; shouts apart) | | " + " | ".join(
        f"R {summary[m]['speech_recall']:.2f} P {summary[m]['precision']:.2f} FA {summary[m]['false_alarm_rate']:.3f}"
        for m in names) + " |")
    c = cost()
    print("CPU per second of audio (ms, one core): " + ", ".join(f"{k} {v:.2f}" for k, v in c.items()))
    print(json.dumps({"bench": "voice", "machine": platform.machine(), "thresholds": th, "summary": summary,
                      "cost_ms_per_s": c}))


if __name__ == "__main__":
    main()
