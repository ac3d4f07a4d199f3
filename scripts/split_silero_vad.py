"""Derive the split 8 kHz Silero VAD that ``robot.vad`` runs: its convolutional encoder and the LSTM cell's
input projection as an ONNX model, the cell's recurrent weights and the output layer as arrays.

The shipped model (``src/robot/models/silero_vad_op18_ifless.onnx.gz``, unchanged from the silero-vad 6.2.3
wheel) is per 32 ms frame: STFT and four convolutions (stateless) -> one LSTM cell step (the state) ->
ReLU, a 1x1 convolution and a sigmoid. Only the LSTM carries state between frames, so the encoder of all
frames of a block can go through onnxruntime in one call (batch = frames x streams) and the cheap cell be
stepped frame by frame in numpy (``robot.vad``; tests/test_voice.py checks that both give the model's
probabilities). This script copies the 8 kHz branch's nodes and weights, no retraining; it only rewrites
them into the same arithmetic in forms onnxruntime runs faster (``_as_2d``, ``_pad_bins``).

    pip install 'onnx>=1.16,<2'   # only for this script
    python scripts/split_silero_vad.py

Writes ``src/robot/models/silero_vad_8k_encoder.onnx.gz`` (input ``input`` (batch, 288) float32: 32
samples of context + a 256-sample frame; output ``input_gates`` (batch, 512): the LSTM cell's input
projection W_ih x + b_ih + b_hh, torch's LSTMCell gate order i, f, g, o) and ``silero_vad_8k_lstm.npz``
(``weight_hh`` (512, 128), ``out_weight`` (128,), ``out_bias`` ()).
"""
from __future__ import annotations

import gzip
import sys
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))
from robot.vad import MODEL_PATH, SPLIT_8K_ENCODER_PATH, SPLIT_8K_LSTM_PATH, load_model  # noqa: E402

PREFIX = "model_8k."   # the 8 kHz branch's weights (the 16 kHz one's are "model.")


def _eight_khz_branch(model: onnx.ModelProto) -> onnx.GraphProto:
    """The model branches on ``sr`` (== 16000) in one top-level If node; its else branch is the 8 kHz net."""
    (node,) = [n for n in model.graph.node if n.op_type == "If"]
    (branch,) = [a.g for a in node.attribute if a.name == "else_branch"]
    return branch


def _as_2d(nodes: list[onnx.NodeProto], weights: dict[str, onnx.TensorProto],
           features: str) -> tuple[list[onnx.NodeProto], list[onnx.TensorProto]]:
    """The encoder's 1-D convolutions as 2-D ones of height 1 (the same arithmetic): onnxruntime runs 2-D
    convolutions in its blocked NCHWc layout on x86-64 (AVX2 / AVX-512): the encoder of 12 frames took 200 us
    instead of 355 (onnxruntime 1.32, AVX-512, one thread). The signal is (batch, channels, 1, time) from the
    STFT's input on; the encoder's output at time step 0 is renamed ``features`` (batch, 128)."""
    out, extra = [], [numpy_helper.from_array(np.array([1, 2], np.int64), "axes_channel_height"),
                      numpy_helper.from_array(np.array([2], np.int64), "axis_height")]
    (first,) = [n for n in nodes if n.op_type == "Conv"][:1]
    for n in nodes:
        n = onnx.NodeProto.FromString(n.SerializeToString())   # a copy
        if n.op_type == "Unsqueeze" and first.input[0] in n.output:   # (batch, time) -> (batch, 1, 1, time)
            n.input[1] = "axes_channel_height"
        elif n.op_type == "Conv":
            w = numpy_helper.to_array(weights[n.input[1]])
            extra.append(numpy_helper.from_array(w[:, :, None, :], n.input[1] + ".2d"))
            n.input[1] += ".2d"
            for a in n.attribute:
                if a.name in ("strides", "dilations", "kernel_shape"):
                    a.ints[:] = [1, *a.ints]
                elif a.name == "pads":
                    a.ints[:] = [0, a.ints[0], 0, a.ints[1]]
        elif features in n.output:             # Gather of time step 0 along axis 2 -> axis 3, then drop height
            assert n.op_type == "Gather" and n.attribute[0].name == "axis" and n.attribute[0].i == 2, n
            n.attribute[0].i = 3
            out.append(n)
            n = helper.make_node("Squeeze", [features, "axis_height"], ["features"])
        out.append(n)
    return out, extra


def _pad_bins(nodes: list[onnx.NodeProto], weights: dict[str, onnx.TensorProto],
              channels: int = 80) -> tuple[list[onnx.NodeProto], list[onnx.TensorProto]]:
    """The STFT's 65 bins padded to ``channels`` (a multiple of 16) with zero filters, and the first encoder
    convolution's weights for them zero (the same arithmetic): with 65 input channels onnxruntime left that
    convolution, half the encoder's time, out of its NCHWc kernels (12 frames: 200 -> 107 us). Also x ** 2
    as x * x (a cheaper kernel)."""
    stft, first = [n for n in nodes if n.op_type == "Conv"][:2]
    basis = numpy_helper.to_array(weights[stft.input[1]])          # (2 x bins, 1, 1, taps): real, then imaginary
    bins = basis.shape[0] // 2
    padded = np.zeros((2 * channels, *basis.shape[1:]), np.float32)
    padded[:bins], padded[channels:channels + bins] = basis[:bins], basis[bins:]
    w = numpy_helper.to_array(weights[first.input[1]])             # (out, bins, 1, 3)
    w_padded = np.zeros((w.shape[0], channels, *w.shape[2:]), np.float32)
    w_padded[:, :bins] = w
    extra = [numpy_helper.from_array(padded, stft.input[1] + ".padded"),
             numpy_helper.from_array(w_padded, first.input[1] + ".padded"),
             numpy_helper.from_array(np.array([channels], np.int64), "bins_padded")]
    out = []
    for n in nodes:
        if n is stft or n is first:
            n.input[1] += ".padded"
        elif n.op_type == "Slice" and stft.output[0] in n.input:    # real / imaginary halves split at `bins`
            split = [i for i in n.input[1:3] if int(numpy_helper.to_array(weights[i]).ravel()[0]) == bins]
            assert len(split) == 1, n
            n.input[list(n.input).index(split[0])] = "bins_padded"
        elif n.op_type == "Pow":
            assert float(numpy_helper.to_array(weights[n.input[1]])) == 2.0, n
            n = helper.make_node("Mul", [n.input[0], n.input[0]], list(n.output))
        out.append(n)
    return out, extra


def main() -> None:
    model = onnx.load_from_string(load_model(MODEL_PATH))
    branch = _eight_khz_branch(model)
    weights = {t.name: t for t in model.graph.initializer}
    lstm = [n for n in branch.node if n.op_type == "Gemm"]
    (w_ih_gemm,) = [n for n in lstm if n.input[1] == PREFIX + "decoder.rnn.weight_ih"]
    features = w_ih_gemm.input[0]          # the encoder's last output, time step 0: the cell's input
    nodes = []
    for n in branch.node:                  # the nodes up to (and including) the one making `features`
        nodes.append(n)
        if features in n.output:
            break
    nodes, extra = _as_2d(nodes, weights, features)
    weights.update({t.name: t for t in extra})
    nodes, extra = _pad_bins(nodes, weights)
    weights.update({t.name: t for t in extra})
    # the cell's input projection too (stateless): W_ih x + b_ih + b_hh, the original Gemm with both biases
    bias = (numpy_helper.to_array(weights[w_ih_gemm.input[2]])
            + numpy_helper.to_array(weights[PREFIX + "decoder.rnn.bias_hh"]))
    weights["input_bias"] = numpy_helper.from_array(bias, "input_bias")
    projection = onnx.NodeProto.FromString(w_ih_gemm.SerializeToString())
    projection.input[:] = ["features", w_ih_gemm.input[1], "input_bias"]
    projection.output[:] = ["input_gates"]
    nodes.append(projection)
    used = {i for n in nodes for i in n.input}
    graph = helper.make_graph(
        nodes, "silero_vad_8k_encoder",
        [helper.make_tensor_value_info("input", TensorProto.FLOAT, ["batch", 288])],
        [helper.make_tensor_value_info("input_gates", TensorProto.FLOAT, ["batch", 512])],
        initializer=[weights[name] for name in sorted(used & set(weights))])
    encoder = helper.make_model(graph, opset_imports=model.opset_import, ir_version=model.ir_version,
                                producer_name="ssl-rescue scripts/split_silero_vad.py")
    onnx.checker.check_model(encoder)
    SPLIT_8K_ENCODER_PATH.write_bytes(gzip.compress(encoder.SerializeToString(), mtime=0))

    def w(name: str) -> np.ndarray:
        return numpy_helper.to_array(weights[PREFIX + name]).astype(np.float32)
    np.savez_compressed(SPLIT_8K_LSTM_PATH, weight_hh=w("decoder.rnn.weight_hh"),
                        out_weight=w("decoder.decoder.2.weight").reshape(128),
                        out_bias=w("decoder.decoder.2.bias").reshape(()))
    for p in (SPLIT_8K_ENCODER_PATH, SPLIT_8K_LSTM_PATH):
        print(f"{p.relative_to(ROOT)}: {p.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
