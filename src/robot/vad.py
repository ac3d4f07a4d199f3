"""Voice activity detection: Silero VAD v6 (a small CNN + LSTM speech detector) run by onnxruntime.

Chosen by measurement on ``data/sounds`` (``benchmarks/bench_voice.py``, README "Telling a victim
from a machine") over WebRTC's VAD and the old hand-made ``robot.voice.voice_likeness`` score.
The model file ``models/silero_vad_16k_op15.onnx`` is copied unchanged from the ``silero-vad``
6.2.3 wheel (MIT, ``models/silero_vad.LICENSE``; sha256 7ed98ddb...c49): that package itself
requires torch, which the Raspberry Pi does not need for an ONNX model.

Streaming and batched: every stream (one beam per tracked source) keeps its own LSTM state and
its leftover samples; all streams with a whole frame pending go through the network in ONE call
(batch = streams): four streams cost about twice one, not four times (benchmarks/bench_voice.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import signal

MODEL_PATH = Path(__file__).resolve().parent / "models" / "silero_vad_16k_op15.onnx"
SAMPLE_RATE = 16000  # Hz; the 16 kHz-only export: the dual-rate model at 8 kHz measured no cheaper
FRAME = 512          # samples (32 ms) per model call and stream
_CONTEXT = 64        # samples of the previous frame the model sees in front of each frame
SPEECH_THRESHOLD = 0.5  # frame probability counted as speech (Silero's own default)


@dataclass
class VadStream:
    """Per-stream state: the LSTM state, the model's audio context and samples waiting for a whole frame."""

    state: np.ndarray
    context: np.ndarray
    pending: np.ndarray
    n_frames: int = 0


class SileroVad:
    """Silero VAD on 16 kHz mono streams. One frame = 32 ms; ``process`` returns the speech
    probability (0..1) of each whole frame completed by the new samples."""

    frame_s = FRAME / SAMPLE_RATE

    def __init__(self, threads: int = 1, model_path: Path | str = MODEL_PATH) -> None:
        import onnxruntime as ort  # robot's dependency; imported here so ssl_core users never pay for it

        if threads < 1:
            raise ValueError(f"threads: expected >= 1, got {threads}")
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads  # its matrices are tiny: more threads cost CPU, gain nothing
        opts.inter_op_num_threads = 1
        opts.log_severity_level = 3
        self._session = ort.InferenceSession(str(model_path), opts, providers=["CPUExecutionProvider"])
        self._sr = np.array(SAMPLE_RATE, dtype=np.int64)

    def new_stream(self) -> VadStream:
        return VadStream(np.zeros((2, 1, 128), np.float32), np.zeros(_CONTEXT, np.float32), np.zeros(0, np.float32))

    def process(self, streams: list[VadStream], audio: list[np.ndarray]) -> list[np.ndarray]:
        """Feed each stream its new samples (float, full scale 1, 16 kHz); returns per stream the
        probabilities of the frames completed now (possibly none)."""
        if len(streams) != len(audio):
            raise ValueError(f"audio: expected one array per stream ({len(streams)}), got {len(audio)}")
        for s, x in zip(streams, audio):
            x = np.asarray(x, np.float32).ravel()
            s.pending = np.concatenate([s.pending, x])
        counts = [len(s.pending) // FRAME for s in streams]
        out: list[list[float]] = [[] for _ in streams]
        for k in range(max(counts, default=0)):
            idx = [i for i, c in enumerate(counts) if c > k]
            frames = np.stack([streams[i].pending[k * FRAME:(k + 1) * FRAME] for i in idx])
            inp = np.concatenate([np.stack([streams[i].context for i in idx]), frames], axis=1)
            state = np.concatenate([streams[i].state for i in idx], axis=1)
            prob, state = self._session.run(None, {"input": inp, "state": state, "sr": self._sr})
            for j, i in enumerate(idx):
                streams[i].state = state[:, j:j + 1].copy()
                streams[i].context = inp[j, -_CONTEXT:].copy()
                out[i].append(float(prob[j, 0]))
        for s, c, o in zip(streams, counts, out):
            s.pending = s.pending[c * FRAME:]
            s.n_frames += c
        return [np.asarray(o) for o in out]

    def probabilities(self, x: np.ndarray, fs: int = SAMPLE_RATE) -> np.ndarray:
        """Speech probability per 32 ms frame of one whole mono float signal at ``fs`` Hz (resampled to
        16 kHz if needed; fresh state)."""
        if fs != SAMPLE_RATE:
            g = math.gcd(int(fs), SAMPLE_RATE)
            x = signal.resample_poly(np.asarray(x, float), SAMPLE_RATE // g, int(fs) // g)
        return self.process([self.new_stream()], [x])[0]


def speech_fraction(probs: np.ndarray) -> float:
    """Fraction of frames called speech (probability >= SPEECH_THRESHOLD); 0 for no frames."""
    p = np.asarray(probs)
    return float((p >= SPEECH_THRESHOLD).mean()) if p.size else 0.0
