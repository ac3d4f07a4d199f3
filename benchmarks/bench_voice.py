"""Voice activity detectors side by side on the real-sound data set's TEST part (ssl_sim/sounds).

Per category: the share of labelled 1 s chunks (hop 0.5 s) called speech (recall for speech,
false-alarm rate for the rest), then precision/recall over all categories; for Silero VAD
(onnxruntime, the chosen one), WebRTC VAD (webrtcvad-wheels, modes 2 and 3) and the old
hand-made score ``benchmarks/_voice_likeness_baseline.py's voice_likeness``. A chunk is called speech when its statistic (the
fraction of speech frames for a frame-wise VAD, the score for the old one) reaches a threshold
chosen per detector on the DEV part (best recall minus false-alarm rate), so each gets its fairest rule.
Then the CPU cost per second of audio (one core, process time, min and median of 5 runs) of Silero
at 16 and 8 kHz for 1 and 4 streams (4 tracks' beams, 100 ms blocks; at 8 kHz the whole model frame by
frame and the split net robot.hearing runs) and under onnxruntime session settings, of WebRTC and of
the old score, and of the whole robot.hearing.Hearing (beams + VAD + filter) for 4 sounding tracks.

    PYTHONPATH=src python benchmarks/bench_voice.py [--cost-only]
"""
from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one core: numpy's BLAS too
    os.environ.setdefault(_var, "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

import numpy as np  # noqa: E402

from robot.vad import SileroVad, speech_fraction  # noqa: E402
from _results import finish, require_stored  # noqa: E402
from _voice_likeness_baseline import voice_likeness  # noqa: E402  (the hand-made score the VAD replaced)
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


def _cpu_ms_per_s(run, seconds: float, repeats: int) -> tuple[float, float]:
    """(min, median) over ``repeats`` of the process time of ``run()`` per second of audio (ms): the
    machine is shared, so the minimum is the best estimate of the code's own cost."""
    out = []
    for _ in range(repeats):
        t = time.process_time()
        run()
        out.append((time.process_time() - t) / seconds * 1e3)
    return float(np.min(out)), float(np.median(out))


def cost(seconds: float = 5.0, repeats: int = 5) -> dict:
    """CPU per second of audio (ms, one core; min and median of ``repeats``)."""
    rng = np.random.default_rng(0)
    x = 0.05 * rng.standard_normal(int(seconds * FS))
    out = {}
    for rate, split in ((16000, False), (8000, False), (8000, True)):
        xr = x[:: FS // rate]
        for n in (1, 4):
            vad = SileroVad(sample_rate=rate, split=split)

            def run() -> None:
                streams = [vad.new_stream() for _ in range(n)]
                for i in range(0, len(xr), rate // 10):
                    vad.process(streams, [xr[i:i + rate // 10]] * n)
            name = f"silero_{rate // 1000}k_{n}_streams" + ("_split" if split else "_per_frame" if rate == 8000 else "")
            out[name] = _cpu_ms_per_s(run, seconds, repeats)
    out["silero_8k_4_streams_session_options"] = _session_options_cost(seconds, repeats)
    out["webrtc_1_stream"] = _cpu_ms_per_s(lambda: _webrtc(3)(x), seconds, repeats)
    out["old_score_1_stream"] = _cpu_ms_per_s(
        lambda: [voice_likeness(x[i:i + FS], FS) for i in range(0, len(x) - FS + 1, FS)], seconds, repeats)
    out.update(_hearing_cost(seconds, repeats))
    return out


def _session_options_cost(seconds: float, repeats: int) -> dict:
    """onnxruntime settings for the 8 kHz model, 4 streams batched, one frame per call (raw session runs)."""
    import onnxruntime as ort

    from robot.vad import load_model
    variants = {"threads 1, sequential, all optimisations": {},
                "no graph optimisation": {"graph_optimization_level": ort.GraphOptimizationLevel.ORT_DISABLE_ALL},
                "basic graph optimisation": {"graph_optimization_level": ort.GraphOptimizationLevel.ORT_ENABLE_BASIC},
                "no memory pattern": {"enable_mem_pattern": False},
                "2 intra-op threads": {"intra_op_num_threads": 2}}
    inp = (0.05 * np.random.default_rng(2).standard_normal((int(seconds / 0.032), 4, 288))).astype(np.float32)
    res = {}
    for name, opts in variants.items():
        so = ort.SessionOptions()
        so.intra_op_num_threads, so.inter_op_num_threads, so.log_severity_level = 1, 1, 3
        so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        for k, v in opts.items():
            setattr(so, k, v)
        sess = ort.InferenceSession(load_model(), so, providers=["CPUExecutionProvider"])

        def run() -> None:
            state, sr = np.zeros((2, 4, 128), np.float32), np.array(8000, np.int64)
            for frame in inp:
                _, state = sess.run(None, {"input": frame, "state": state, "sr": sr})
        res[name] = _cpu_ms_per_s(run, seconds, repeats)
    return res


def _hearing_cost(seconds: float, repeats: int) -> dict:
    """The whole robot.hearing.Hearing for 4 sounding tracks (100 ms blocks of noise): as configured (the
    chain listens 0.5 s in every 1 s), listening all the time, and with tracks that move every block."""
    from robot.hearing import Hearing, HearingConfig
    from ssl_core.geometry import cube8
    from ssl_core.tracking import Track

    pos = cube8().positions
    rng = np.random.default_rng(1)
    block = FS // 10
    blocks = [0.01 * rng.standard_normal((8, block)) for _ in range(int(seconds * 10))]
    az0 = np.deg2rad([0, 90, 180, 270])

    def tracks(k: int, moving: bool) -> list[Track]:
        az = az0 + (np.deg2rad(1.0) * k if moving else 0.0)   # 10 deg/s: the robot turning slowly
        return [Track(i, np.array([np.cos(a), np.sin(a), 0.0]), np.zeros(3), 1.0, 0.0, 0.0, 0.0, 0.0, 0)
                for i, a in enumerate(az)]

    vad = SileroVad(sample_rate=8000)   # the session is made once (a Hearing makes its streams)

    def runner(config: dict, moving: bool = False):
        def run() -> None:
            h = Hearing(pos, FS, HearingConfig(**config), vad=vad)
            for k, b in enumerate(blocks):
                h.update(b, tracks(k, moving), (k + 1) * block / FS)
        return run
    continuous = {"vad_on_s": 1.0, "vad_period_s": 1.0}
    return {"hearing_4_tracks": _cpu_ms_per_s(runner({}), seconds, repeats),
            "hearing_4_tracks_moving": _cpu_ms_per_s(runner({}, True), seconds, repeats),
            "hearing_4_tracks_listening_continuously": _cpu_ms_per_s(runner(continuous), seconds, repeats),
            # the voice scan (HearingConfig.scan_step_deg): 36 / 24 more beams heard in the same bursts
            "hearing_4_tracks_voice_scan_10deg": _cpu_ms_per_s(runner({"scan_step_deg": 10.0}), seconds, repeats),
            "hearing_4_tracks_voice_scan_15deg": _cpu_ms_per_s(runner({"scan_step_deg": 15.0}), seconds, repeats)}


def room_frontends(seconds: int = 16) -> dict:
    """Which signal lets Silero hear the talker beside a machine 6 dB louder (RT60 0.6 s, ssl_sim/sounds
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


def _cost_figures(c: dict) -> dict[str, float]:
    """The minimum of the runs per cost line (the least disturbed by other processes)."""
    out = {}
    for k, v in c.items():
        for name, (lo, _med) in (v.items() if isinstance(v, dict) else [("", v)]):
            out[f"cost_ms_per_audio_s {k}{' ' + name if name else ''}"] = lo
    return out


def main() -> int:
    unknown = [a for a in sys.argv[1:] if a not in ("--cost-only", "--check")]
    if unknown:
        raise SystemExit(f"bench_voice: unknown argument(s) {unknown}; expected [--cost-only] [--check]")
    check = "--check" in sys.argv[1:]
    require_stored("voice_cost" if "--cost-only" in sys.argv[1:] else "voice", check)
    if "--cost-only" in sys.argv[1:]:
        c = cost()
        _print_cost(c)
        figures = _cost_figures(c)
        return finish("voice_cost", figures, check=check, better={k: "lower" for k in figures})
    th = tune(evaluate("dev"))
    table = {m: {c: [int(v >= th[m]) for v in vals] for c, vals in t.items()} for m, t in evaluate("test").items()}
    cats = sorted({c for t in table.values() for c in t}, key=lambda c: (c not in ("speech", "shouts"), c))
    names = list(table)
    print("test part, 1 s chunks called speech (%); chunk thresholds tuned on dev: "
          + ", ".join(f"{m} {th[m]:.2f}" for m in names))
    md = ["| category | n | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for c in cats:
        n = len(table[names[0]][c])
        md.append(f"| {c} | {n} | " + " | ".join(f"{100 * np.mean(table[m][c]):.0f}" for m in names) + " |")
    summary = {}
    for m in names:
        tp = sum(table[m]["speech"])
        fn = len(table[m]["speech"]) - tp
        fp = sum(sum(v) for c, v in table[m].items() if c not in ("speech", "shouts"))
        n_neg = sum(len(v) for c, v in table[m].items() if c not in ("speech", "shouts"))
        summary[m] = {"speech_recall": tp / (tp + fn), "precision": tp / max(tp + fp, 1), "false_alarm_rate": fp / n_neg,
                      "shouts_called_speech": float(np.mean(table[m]["shouts"]))}
    md.append("| overall (speech vs non-speech; shouts apart) | | " + " | ".join(
        f"R {summary[m]['speech_recall']:.2f} P {summary[m]['precision']:.2f} FA {summary[m]['false_alarm_rate']:.3f}"
        for m in names) + " |")
    print("\n".join(md))
    room = room_frontends()
    print("room RT60 0.6 s, machine 6 dB louder, 5 cases (ssl_sim/sounds ROOM_CASES), seconds after the first 2:")
    md_room = ["| front end | her talking seconds heard as speech | seconds speech heard toward the machine |",
               "|---|---|---|"]
    for k, (her, mach) in room.items():
        md_room.append(f"| {k} | {100 * her:.0f} % | {100 * mach:.0f} % |")
    print("\n".join(md_room))
    c = cost()
    _print_cost(c)
    figures = _cost_figures(c)
    for m in names:
        figures.update({f"{k} {m}": v for k, v in summary[m].items()})
        figures.update({f"speech_pct {m} | {cat}": 100 * float(np.mean(table[m][cat])) for cat in cats})
    for k, (her, mach) in room.items():
        figures[f"her_speech_pct {k}"], figures[f"machine_speech_pct {k}"] = 100 * her, 100 * mach
    tables = {"Voice activity on the sound set's test part (% of 1 s chunks called speech)": "\n".join(md) + "\n",
              "A talker beside a machine 6 dB louder (RT60 0.6 s, 5 rooms): which front end lets the VAD hear her":
              "\n".join(md_room) + "\n"}
    return finish("voice", figures, tables, check=check, better={k: "lower" for k in _cost_figures(c)})


def _print_cost(c: dict) -> None:
    print("CPU per second of audio (ms, one core, min / median of 5 runs):")
    for k, v in c.items():
        for name, (lo, med) in (v.items() if isinstance(v, dict) else [("", v)]):
            print(f"  {k}{' ' + name if name else ''}: {lo:.2f} / {med:.2f}")


if __name__ == "__main__":
    raise SystemExit(main())
