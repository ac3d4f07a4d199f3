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
    from robot.hearing import Hearing, HearingConfig
    from ssl_core.tracking import Track
    from ssl_core.geometry import cube8

    geo = cube8()
    rng = np.random.default_rng(1)
    block = FS // 10
    tracks = [Track(i, np.array([np.cos(a), np.sin(a), 0.0]), np.zeros(3), 1.0, 0.0, 0.0, 0.0, 0.0, 0)
              for i, a in enumerate(np.deg2rad([0, 90, 180, 270]))]
    hearing = Hearing(geo.positions, FS, HearingConfig())
    t = time.process_time()
    for k in range(int(seconds * 10)):
        hearing.update(0.01 * rng.standard_normal((8, block)), tracks, (k + 1) * block / FS)
    return {"hearing_4_tracks_ms_per_s": (time.process_time() - t) / seconds * 1e3}


def room_frontends(seconds: int = 16) -> dict:
    """Which signal lets Silero hear the talker beside a machine 6 dB louder (RT60 0.6 s, data/sounds
    ROOM_CASES): per front end, the share of her talking seconds (after 2 s) called speech in the signal
    toward her, and of all seconds called speech in the signal toward the machine (her leak); then the
    robot.hearing classification (hand-made tracks at the true directions)."""
    from robot.hearing import Hearing, VoiceClass, classify
    from sound_dataset import ROOM_CASES, room_case
    from ssl_core.beamform import MpdrBeamformer, OverlapAdd, StftStream, beam_signal
    from ssl_core.geometry import cube8
    from ssl_core.noise import NoiseFloor
    from ssl_core.tracking import Track

    pos = cube8().positions
    vad = SileroVad()
    rows: dict[str, list[list[float]]] = {}

    def chunks_called(y: np.ndarray) -> list[bool]:
        y = y / max(float(np.sqrt(np.mean(y**2))), 1e-12) * 0.1
        p = vad.probabilities(y)
        return [speech_fraction(p[k * 31:(k + 1) * 31]) >= 0.2 for k in range(seconds)]

    def mpdr(x: np.ndarray, u: np.ndarray, denoise: bool) -> np.ndarray:
        st, mp, oa, nf = StftStream(8), MpdrBeamformer(pos, FS), OverlapAdd(), NoiseFloor(30)
        out = []
        for i in range(0, x.shape[1], FS // 10):
            spec = mp.process(st.analyse(x[:, i:i + FS // 10]), u[None])[0]
            if denoise and len(spec):
                spec = spec * np.maximum(nf.weights(np.abs(spec) ** 2), 0.3)
            out.append(oa.synthesise(spec))
        return np.concatenate(out)

    for case in ROOM_CASES:
        x, dirs, talks = room_case(*case, seconds=seconds)
        xf = x.astype(float) / 32768
        fronts = {"microphone 0": lambda u: xf[0], "delay-and-sum beam": lambda u: beam_signal(xf, pos, u, FS),
                  "MPDR beam": lambda u: mpdr(xf, u, False), "MPDR beam + noise suppression": lambda u: mpdr(xf, u, True)}
        for name, f in fronts.items():
            her, machine = chunks_called(f(dirs[0])), chunks_called(f(dirs[1]))
            rows.setdefault(name, []).append([np.mean([c for c, t in zip(her, talks) if t][2:]), np.mean(machine[2:])])
        h = Hearing(pos)
        tracks = [Track(i, d, np.zeros(3), 1.0, 0.0, 0.0, 0.0, 0.0, 0) for i, d in enumerate(dirs)]
        cls = []
        for k in range(seconds * 10):
            ev = h.update(x[:, k * FS // 10:(k + 1) * FS // 10], tracks, (k + 1) / 10)
            if (k + 1) % 10 == 0:
                cls.append([classify(e) for e in ev])
        v = [c[0] is VoiceClass.VOICE for c, t in zip(cls, talks) if t][2:]
        m = [c[1] is not VoiceClass.NON_VOICE for c in cls][2:]
        rows.setdefault("robot.hearing (MPDR + suppression + attribution + filter)", []).append([np.mean(v), np.mean(m)])
    return {k: np.mean(v, axis=0).tolist() for k, v in rows.items()}


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
    room = room_frontends()
    print("room RT60 0.6 s, machine 6 dB louder, 5 cases (data/sounds ROOM_CASES), seconds after the first 2:")
    print("| front end | her talking seconds heard as speech | seconds speech heard toward the machine |")
    print("|---|---|---|")
    for k, (her, mach) in room.items():
        print(f"| {k} | {100 * her:.0f} % | {100 * mach:.0f} % |")
    c = cost()
    print("CPU per second of audio (ms, one core): " + ", ".join(f"{k} {v:.2f}" for k, v in c.items()))
    print(json.dumps({"bench": "voice", "machine": platform.machine(), "thresholds": th, "summary": summary, "room": room,
                      "cost_ms_per_s": c}))


if __name__ == "__main__":
    main()
