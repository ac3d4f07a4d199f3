"""Voice activity detection: Silero VAD v6 (a small CNN + LSTM speech detector) run by onnxruntime.

Chosen by measurement on ``ssl_sim/sounds`` (``benchmarks/bench_voice.py``, docs/design/voice.md "Telling a victim
from a machine") over WebRTC's VAD and the old hand-made ``benchmarks/_voice_likeness_baseline.py's voice_likeness`` score.
The model file ``ssl_sim/models/silero_vad_op18_ifless.onnx`` (stored gzip-compressed, ``.onnx.gz``: 1.9 MB instead of
2.8 MB in the repository) is copied unchanged from the ``silero-vad``
6.2.3 wheel (MIT, ``ssl_sim/models/silero_vad.LICENSE``; sha256 7671cd04...bd28): that package itself
requires torch, which the Raspberry Pi does not need for an ONNX model. It is the wheel's dual-rate
"ifless" export (one ``If`` node only, choosing the 16 or 8 kHz net by ``sr``): at 16 kHz its probabilities
equal those of the 16 kHz-only export (``silero_vad_16k_op15.onnx``, used before) within 5e-7, and it also
runs at 8 kHz.

The 8 kHz net split (``SPLIT_8K_*``, derived from that file by ``scripts/split_silero_vad.py``, MIT like it):
only its LSTM cell carries state from frame to frame; its encoder (STFT as a convolution, four
convolutions) is stateless. So the encoder of every pending frame of every stream goes through
onnxruntime in ONE call (batch = frames x streams), rewritten as 2-D convolutions of height 1 with the STFT's
65 bins padded to 80 channels (zero filters), the same arithmetic, so that onnxruntime runs every
convolution in its blocked NCHWc kernels; the same call makes the cell's input projection. The recurrent
rest of the cell (torch's LSTMCell) and the output layer are stepped in numpy. Probabilities equal the
whole model's within 2e-6 (tests/test_voice.py). 12 frames (3 frames of 4 streams): the whole model frame
by frame 3 calls, ~530 us; the encoder as shipped 355 us, as 2-D convolutions 200 us, padded 107 us; the
cell ~15 us per frame. (x86-64 with AVX-512; on the Pi's ARM cores the padded 2-D form is the same
arithmetic, its speed there not measured.)

Cost (one core, onnxruntime 1.32, x86-64 with AVX-512, process time per second of audio, 100 ms blocks;
benchmarks/bench_voice.py, minimum of 5 runs on a shared machine): 16 kHz, whole model per frame: 3.7 ms
for one stream, 9.2 ms for four batched; 8 kHz per frame 3.0 / 6.2 ms (a call ~50 us plus ~30 us per
stream); 8 kHz split 1.3 / 2.7 ms. On the data set's dev and test parts the 8 kHz model calls the same 1 s
chunks speech as the 16 kHz one (speech 100 %, every non-speech category 0 %; tests/test_voice.py checks
the test part).

Streaming and batched: every stream (one beam per tracked source) keeps its own LSTM state and
its leftover samples; all streams with a whole frame pending go through the network together
(batch = streams; split: batch = frames x streams for the encoder).
"""
from __future__ import annotations

import functools
import gzip
import math
import zipfile
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import signal, special

MODEL_PATH = Path(__file__).resolve().parent / "models" / "silero_vad_op18_ifless.onnx.gz"
# The same model's 8 kHz net split by scripts/split_silero_vad.py: its stateless encoder (STFT + convolutions)
# and its LSTM cell + output layer (the only state), so that all frames of a block share one encoder call.
SPLIT_8K_ENCODER_PATH = MODEL_PATH.with_name("silero_vad_8k_encoder.onnx.gz")
SPLIT_8K_LSTM_PATH = MODEL_PATH.with_name("silero_vad_8k_lstm.npz")


class ModelError(RuntimeError):
    """A model file that cannot be read, loaded or run; the message names the file and what is wrong."""

    def __init__(self, path: Path | str, problem: str) -> None:
        super().__init__(f"model file {path}: {problem}")
        self.path = Path(path)


def _why(exc: BaseException) -> str:
    """One line for an exception of gzip, zipfile, numpy or onnxruntime (their messages can span lines)."""
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 200 else text[:197] + "..."


def load_model(path: Path | str | None = None) -> bytes:
    """The ONNX model's bytes, from a plain ``.onnx`` file or a gzip-compressed ``.onnx.gz``; ``ModelError``
    naming the file when it cannot be read, is empty or is not whole gzip (truncated, bit-flipped: gzip's CRC)."""
    path = Path(MODEL_PATH if path is None else path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ModelError(path, f"cannot read it ({exc.strerror or exc})") from None
    if not data:
        raise ModelError(path, "empty (0 bytes)")
    if path.suffix != ".gz":
        return data
    try:
        return gzip.decompress(data)
    except EOFError:
        raise ModelError(path, f"truncated: the gzip stream ends early ({len(data)} bytes)") from None
    except (OSError, ValueError, zlib.error) as exc:   # gzip.BadGzipFile is an OSError; CRC mismatches too
        raise ModelError(path, f"damaged gzip data ({_why(exc)})") from None


def _load_lstm(path: Path) -> dict[str, np.ndarray]:
    """The split net's LSTM cell + output layer weights (``.npz``), checked for the shapes the cell needs."""
    want = {"weight_hh": (4 * _HIDDEN, _HIDDEN), "out_weight": (_HIDDEN,), "out_bias": ()}
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise ModelError(path, f"cannot read it ({exc.strerror or exc})") from None
    if size == 0:
        raise ModelError(path, "empty (0 bytes)")
    with open(path, "rb") as f:
        if f.read(4) != b"PK\x03\x04":
            raise ModelError(path, "not an .npz archive (no zip header)")
    try:
        with np.load(path, allow_pickle=False) as w:
            arrays = {k: np.asarray(w[k]) for k in want if k in w.files}
    except (EOFError, OSError, ValueError, KeyError, zipfile.BadZipFile, zlib.error) as exc:  # zip CRC: BadZipFile
        raise ModelError(path, f"truncated or damaged .npz archive ({_why(exc)})") from None
    for k, shape in want.items():
        if k not in arrays:
            raise ModelError(path, f"no array {k!r} (expected {sorted(want)})")
        if np.shape(arrays[k]) != shape and not (shape == () and np.size(arrays[k]) == 1):
            raise ModelError(path, f"{k}: expected shape {shape}, got {np.shape(arrays[k])}")
        if not np.all(np.isfinite(arrays[k])):
            raise ModelError(path, f"{k}: holds non-finite values")
    return arrays


SAMPLE_RATE = 16000  # Hz, the default rate (the data set's); 8000 is the other one the model knows
FRAME = 512          # samples (32 ms) per model call and stream at 16 kHz
# per rate: samples per frame (32 ms) and samples of the previous frame the model sees in front of it
_FRAMING = {16000: (FRAME, 64), 8000: (256, 32)}
SPEECH_THRESHOLD = 0.5  # frame probability counted as speech (Silero's own default)
# A 1 s chunk is speech when >= 20 % of its frames are: on the ssl_sim/sounds dev part every value tried
# from 0.05 to 0.3 separated speech from non-speech perfectly; 0.2 lies inside that range.
CHUNK_SPEECH_FRACTION = 0.2
_HIDDEN = 128        # the LSTM's state size (h and c per stream)


@dataclass
class VadStream:
    """Per-stream state: the LSTM state, the model's audio context and samples waiting for a whole frame."""

    state: np.ndarray
    context: np.ndarray
    pending: np.ndarray
    n_frames: int = 0


class SileroVad:
    """Silero VAD on 16 kHz mono streams. One frame = 32 ms; ``process`` returns the speech
    probability (0..1) of each whole frame completed by the new samples.

    ``split`` (8 kHz with the shipped model only; default there): the net split at its one state, the
    encoder of every pending frame of every stream in one onnxruntime call and the LSTM cell stepped in
    numpy (``SPLIT_8K_*``; the same probabilities within 2e-6). Otherwise one model call per frame."""

    frame_s = FRAME / SAMPLE_RATE  # 32 ms at either rate

    def __init__(self, threads: int = 1, model_path: Path | str | None = None, sample_rate: int = SAMPLE_RATE,
                 split: bool | None = None) -> None:
        import onnxruntime as ort  # robot's dependency; imported here so ssl_core users never pay for it

        model_path = MODEL_PATH if model_path is None else model_path
        if threads < 1:
            raise ValueError(f"threads: expected >= 1, got {threads}")
        if sample_rate not in _FRAMING:
            raise ValueError(f"sample_rate: expected one of {sorted(_FRAMING)} Hz, got {sample_rate}")
        splittable = sample_rate == 8000 and Path(model_path) == MODEL_PATH
        if split and not splittable:
            raise ValueError(f"split: only the shipped model ({MODEL_PATH.name}) at 8000 Hz is split, "
                             f"got {Path(model_path).name} at {sample_rate} Hz")
        self.split = splittable if split is None else split
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = threads  # its matrices are tiny: more threads cost CPU, gain nothing
        opts.inter_op_num_threads = 1
        opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        # (no / basic / all graph optimisations, memory pattern on or off, thread spinning on or off:
        # the same cost within 3 %; 2 intra-op threads double it: benchmarks/bench_voice.py)
        opts.log_severity_level = 3
        self.model_path = Path(SPLIT_8K_ENCODER_PATH if self.split else model_path)
        self.lstm_path = Path(SPLIT_8K_LSTM_PATH) if self.split else None
        model = load_model(self.model_path)
        try:
            self._session = ort.InferenceSession(model, opts, providers=["CPUExecutionProvider"])
        except Exception as exc:   # onnxruntime's own exception types: not an ONNX graph it can run
            raise ModelError(self.model_path, f"not a loadable ONNX model ({_why(exc)})") from None
        if self.split:
            # sigmoid(x) = (1 + tanh(x / 2)) / 2: the i, f and o gates' pre-activations halved, so that one
            # tanh serves all four gates
            self._half = np.repeat(np.array([0.5, 0.5, 1.0, 0.5], np.float32), _HIDDEN)
            w = _load_lstm(self.lstm_path)
            self._w_hh_t = np.ascontiguousarray((w["weight_hh"] * self._half[:, None]).T,  # (state 128, 4 gates x 128)
                                                dtype=np.float32)
            self._out_w = w["out_weight"].astype(np.float32)
            self._out_b = float(np.ravel(w["out_bias"])[0])
        self.sample_rate = sample_rate
        self.frame, self._context = _FRAMING[sample_rate]
        self._sr = np.array(sample_rate, dtype=np.int64)

    def new_stream(self) -> VadStream:
        return VadStream(np.zeros((2, 1, _HIDDEN), np.float32), np.zeros(self._context, np.float32),
                         np.zeros(0, np.float32))

    def process(self, streams: list[VadStream], audio: list[np.ndarray]) -> list[np.ndarray]:
        """Feed each stream its new samples (float, full scale 1, at ``sample_rate``); returns per stream the
        probabilities of the frames completed now (possibly none)."""
        if len(streams) != len(audio):
            raise ValueError(f"audio: expected one array per stream ({len(streams)}), got {len(audio)}")
        for s, x in zip(streams, audio):
            x = np.asarray(x, np.float32).ravel()
            s.pending = np.concatenate([s.pending, x]) if len(s.pending) else x
        frame, ctx = self.frame, self._context
        counts = [len(s.pending) // frame for s in streams]
        n = max(counts, default=0)
        out = []
        if n:
            # Model inputs of every frame at once, (frames, streams, context + frame): each frame preceded by
            # the last samples of the one before. A stream with fewer frames is padded; its padded frames'
            # outputs and states are discarded.
            pending = np.zeros((len(streams), n * frame), np.float32)
            for i, (s, c) in enumerate(zip(streams, counts)):
                pending[i, :c * frame] = s.pending[:c * frame]
            frames = pending.reshape(len(streams), n, frame)
            contexts = np.concatenate([np.stack([s.context for s in streams])[:, None], frames[:, :-1, -ctx:]], axis=1)
            inputs = np.concatenate([contexts, frames], axis=2).transpose(1, 0, 2)
            state = np.concatenate([s.state for s in streams], axis=1)
            try:
                probs, states = self._run_split(inputs, state) if self.split else self._run(inputs, state)
            except Exception as exc:   # a model failing at run time fails the run: never mistaken for an end of audio
                raise ModelError(self.model_path, f"failed at run time ({type(exc).__name__}: {_why(exc)})") from exc
            for i, (s, c) in enumerate(zip(streams, counts)):
                if c:   # the state and context after this stream's last whole frame
                    s.state, s.context = states[c - 1, :, i:i + 1].copy(), inputs[c - 1, i, -ctx:].copy()
                out.append(probs[:c, i].astype(float))
        else:
            out = [np.zeros(0) for _ in streams]
        for s, c in zip(streams, counts):
            s.pending = s.pending[c * frame:]
            s.n_frames += c
        return out

    def _run(self, inputs: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The whole model frame by frame: ``inputs`` (frames, streams, samples), ``state`` (2, streams, 128)
        -> probabilities (frames, streams) and the state after each frame (frames, 2, streams, 128)."""
        probs = np.empty(inputs.shape[:2], np.float32)
        states = np.empty((len(inputs), *state.shape), np.float32)
        for k, x in enumerate(inputs):
            prob, state = self._session.run(None, {"input": np.ascontiguousarray(x), "state": state, "sr": self._sr})
            probs[k], states[k] = prob[:, 0], state
        return probs, states

    def _run_split(self, inputs: np.ndarray, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``_run`` with the encoder of all frames in one call and the LSTM cell (torch's LSTMCell: gates i, f,
        g, o) stepped in numpy."""
        n, k = inputs.shape[:2]
        # the encoder and the cell's input projection (in the graph: a numpy product of this size woke
        # OpenBLAS's thread pool: 2-3x the CPU of the whole hearing listening all the time)
        (gates,) = self._session.run(None, {"input": inputs.reshape(n * k, -1)})
        gates_in = (gates * self._half).reshape(n, k, -1)                        # (frames, streams, 4 x 128)
        h, c = state
        m = _HIDDEN
        states = np.empty((n, 2, k, m), np.float32)
        for t in range(n):
            z = np.tanh(gates_in[t] + h @ self._w_hh_t)   # tanh of: i / 2, f / 2, g, o / 2
            sig = 0.5 * z + 0.5                            # sigmoid(i), sigmoid(f), -, sigmoid(o)
            c = sig[:, m:2 * m] * c + sig[:, :m] * z[:, 2 * m:3 * m]
            h = sig[:, 3 * m:] * np.tanh(c)
            states[t, 0], states[t, 1] = h, c
        return special.expit(np.maximum(states[:, 0], 0) @ self._out_w + self._out_b), states

    def probabilities(self, x: np.ndarray, fs: int = SAMPLE_RATE) -> np.ndarray:
        """Speech probability per 32 ms frame of one whole mono float signal at ``fs`` Hz (resampled to
        ``sample_rate`` if needed; fresh state)."""
        if fs != self.sample_rate:
            g = math.gcd(int(fs), self.sample_rate)
            x = signal.resample_poly(np.asarray(x, float), self.sample_rate // g, int(fs) // g)
        return self.process([self.new_stream()], [x])[0]


def speech_fraction(probs: np.ndarray) -> float:
    """Fraction of frames called speech (probability >= SPEECH_THRESHOLD); 0 for no frames."""
    p = np.asarray(probs)
    return float((p >= SPEECH_THRESHOLD).mean()) if p.size else 0.0


def check_model(sample_rate: int = SAMPLE_RATE) -> SileroVad:
    """Load the shipped model for ``sample_rate`` (8 kHz: its split net, encoder and LSTM weights) and run it on
    0.3 s of silence in 4 streams; ``ModelError`` naming the file when it cannot be loaded or gives anything but
    one probability in [0, 1] per frame. Called where a program starts, before devices open, so that a damaged
    file stops it at once instead of at its first listen. Cached per file state (path, size, mtime)."""
    vad_paths = [SPLIT_8K_ENCODER_PATH, SPLIT_8K_LSTM_PATH] if sample_rate == 8000 else [MODEL_PATH]
    return _checked(sample_rate, tuple((str(p), *_stat(p)) for p in map(Path, vad_paths)))


def _stat(path: Path) -> tuple[int, int]:
    try:
        st = path.stat()
    except OSError:
        return (-1, -1)
    return (st.st_size, st.st_mtime_ns)


@functools.lru_cache(maxsize=8)
def _checked(sample_rate: int, files: tuple) -> SileroVad:
    vad = SileroVad(sample_rate=sample_rate)
    streams = [vad.new_stream() for _ in range(4)]
    block = np.zeros(int(0.1 * sample_rate), np.float32)
    probs = [np.concatenate(p) for p in zip(*(vad.process(streams, [block] * 4) for _ in range(3)))]
    expected = 3 * len(block) // vad.frame
    for p in probs:
        if len(p) != expected or not np.all((p >= 0) & (p <= 1)):
            raise ModelError(vad.model_path, f"gives {p[:4]!r}... on silence: expected {expected} probabilities "
                                             "in [0, 1] per stream")
    return vad
