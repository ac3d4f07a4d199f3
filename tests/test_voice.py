"""Voice activity detection (robot.vad, Silero VAD via onnxruntime) on REAL recordings (ssl_sim/sounds,
see its PROVENANCE) and on the simulator's procedural victim and machine sounds."""
from __future__ import annotations

import numpy as np
import pytest

from robot.vad import CHUNK_SPEECH_FRACTION, FRAME, SAMPLE_RATE, SileroVad, speech_fraction
from sound_dataset import FS, SPEECH_CATEGORIES, chunk_starts, recordings


@pytest.fixture(scope="module")
def vad():
    return SileroVad()


def _called_speech(vad, x, starts):
    p = vad.probabilities(x)
    per_chunk = FS // FRAME
    return [speech_fraction(p[s // FRAME: s // FRAME + per_chunk]) >= CHUNK_SPEECH_FRACTION for s in starts]


def test_test_part_speech_found_and_noise_rejected_per_category(vad):
    called: dict[str, list[bool]] = {}
    for r in recordings("test"):
        called.setdefault(r.category, []).extend(_called_speech(vad, r.samples, chunk_starts(r)))
    report = {c: (len(v), float(np.mean(v))) for c, v in called.items()}
    print("test part, share of 1 s chunks called speech:", report)
    assert len(called["speech"]) >= 40 and np.mean(called["speech"]) >= 0.95, report
    for cat, v in called.items():
        if cat not in SPEECH_CATEGORIES:
            assert len(v) >= 5 and np.mean(v) <= 0.03, (cat, report)
    # every speaker of the test part (a man, a woman, a male reader) is heard
    for r in recordings("test"):
        if r.category == "speech":
            assert np.mean(_called_speech(vad, r.samples, chunk_starts(r))) >= 0.9, r.name


def test_8k_mode_calls_the_same_test_chunks_speech(vad):
    """robot.hearing hears its beams at 8 kHz: same chunk decisions as at 16 kHz on the test part."""
    vad8 = SileroVad(sample_rate=8000)
    for r in recordings("test"):
        starts = chunk_starts(r)
        p8 = vad8.probabilities(r.samples, FS)
        called8 = [speech_fraction(p8[s // FRAME: s // FRAME + FS // FRAME]) >= CHUNK_SPEECH_FRACTION for s in starts]
        assert called8 == _called_speech(vad, r.samples, starts), r.name


def test_split_8k_net_gives_the_whole_models_probabilities_in_batched_streams():
    """The 8 kHz net run split (encoder of all frames at once, LSTM cell in numpy; scripts/split_silero_vad.py)
    against the unchanged model run frame by frame: three streams fed blocks of unequal, frame-misaligned
    lengths (so streams complete different numbers of frames per call)."""
    split, whole = SileroVad(sample_rate=8000), SileroVad(sample_rate=8000, split=False)
    assert split.split and not whole.split
    from scipy.signal import resample_poly
    rec = recordings("test")
    xs = [resample_poly(r.samples[: 4 * FS], 1, 2) for r in (rec[0], rec[-1], rec[len(rec) // 2])]
    runs = []
    for v in (split, whole):
        streams, out = [v.new_stream() for _ in xs], [[] for _ in xs]
        pos = [0, 0, 0]
        for k in range(60):
            lengths = [(300, 800, 1100)[(k + i) % 3] for i in range(3)]
            probs = v.process(streams, [x[p:p + n] for x, p, n in zip(xs, pos, lengths)])
            pos = [p + n for p, n in zip(pos, lengths)]
            for o, p in zip(out, probs):
                o.append(p)
        runs.append([np.concatenate(o) for o in out])
    for a, b in zip(*runs):
        assert len(a) == len(b) > 50
        np.testing.assert_allclose(a, b, atol=1e-5)
    with pytest.raises(ValueError, match="split"):
        SileroVad(sample_rate=16000, split=True)


def test_data_set_is_speaker_disjoint_16k_mono_and_small():
    dev = {r.name for r in recordings("dev") if r.category in SPEECH_CATEGORIES}
    test = {r.name for r in recordings("test") if r.category in SPEECH_CATEGORIES}
    assert dev and test and not dev & test
    sexes = " ".join(r.sex for r in recordings("test") + recordings("dev") if r.category == "speech")
    assert "female" in sexes and "male (" in sexes
    from sound_dataset import DATA
    assert sum(p.stat().st_size for p in DATA.rglob("*.wav")) < 6.5e6


def test_streaming_in_odd_blocks_and_batching_equal_one_pass(vad):
    x = recordings("test")[0].samples[: 3 * FS]
    whole = vad.probabilities(x)
    streams = [vad.new_stream(), vad.new_stream()]
    parts: list[list[np.ndarray]] = [[], []]
    for a, b in ((0, 700), (700, 4100), (4100, 3 * FS)):   # blocks that do not align with frames
        out = vad.process(streams, [x[a:b], 0.5 * x[a:b]])
        parts[0].append(out[0])
        parts[1].append(out[1])
    np.testing.assert_allclose(np.concatenate(parts[0]), whole, atol=1e-5)
    assert len(np.concatenate(parts[1])) == len(whole)


def test_other_sample_rates_are_resampled_and_bad_input_is_named(vad):
    x = recordings("test")[0].samples[: 2 * FS]
    from scipy.signal import resample_poly
    p8 = vad.probabilities(resample_poly(x, 1, 2), fs=8000)
    assert abs(len(p8) - len(vad.probabilities(x))) <= 1 and speech_fraction(p8) > 0.5
    with pytest.raises(ValueError, match="audio"):
        vad.process([vad.new_stream()], [])
    with pytest.raises(ValueError, match="threads"):
        SileroVad(threads=0)
    with pytest.raises(ValueError, match="sample_rate"):
        SileroVad(sample_rate=44100)
    assert SAMPLE_RATE == 16000


# --- the simulator's procedural sounds --------------------------------------------------------------

def _sounding_chunks(x):
    """1 s chunks (hop 0.5 s) in which the dry signal sounds for >= 50 % of its 32 ms frames."""
    n = len(x) // FRAME
    e = 10 * np.log10((x[: n * FRAME].reshape(n, FRAME) ** 2).mean(1) + 1e-12)
    on = e >= e.max() - 30
    return [s for s in range(0, len(x) - FS + 1, FS // 2) if on[s // FRAME: s // FRAME + FS // FRAME].mean() >= 0.5]


def test_procedural_calls_of_every_speaker_pass_and_machines_and_knocks_do_not(vad):
    from ssl_sim.acoustics.signals import generator_noise, pump_noise
    from ssl_sim.acoustics.voices import SPEAKERS, victim_voice

    calls = []
    for k, spk in enumerate(sorted(SPEAKERS)):
        x = 0.1 * victim_voice("calls", spk, seed=10 + k).render(0, 12 * FS)
        calls += _called_speech(vad, x, _sounding_chunks(x))
    assert len(calls) >= 50 and np.mean(calls) >= 0.95, np.mean(calls)
    # (procedural shouts are not asserted: measured 73 % of male and far fewer of female/child shout
    # chunks are speech to Silero, which hears real recorded cries as non-speech too: docs/design/voice.md)
    for name, sig in (("pump", pump_noise(FS, 1)), ("generator", generator_noise(FS, 2)),
                      ("knocks", victim_voice("knocks", "male", seed=3))):
        x = sig.render(0, 20 * FS)
        x = 0.1 * x / np.sqrt(np.mean(x**2))
        assert not any(_called_speech(vad, x, _sounding_chunks(x) or [0])), name
