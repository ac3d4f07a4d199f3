"""Victim sounds and time-keyed signal streams: reproducible, block-invariant, voice-like."""
from __future__ import annotations

import numpy as np
import pytest

from ssl_sim.acoustics import (SPEAKERS, EventStream, LoopedSignal, ShapedNoise, TimeKeyedNoise, generator_noise,
                               pump_noise, synth_knock, synth_moan, synth_phrase, victim_voice)
from ssl_sim.acoustics.voices import PHRASES, _smooth

FS = 16000


def f0_autocorr(x: np.ndarray, fs: int = FS, lo: float = 70.0, hi: float = 400.0) -> float:
    """Median pitch (Hz) over voiced 40 ms frames by autocorrelation (an estimator independent of the synthesiser)."""
    n = int(0.04 * fs)
    est = []
    energies = [np.sum(x[i:i + n] ** 2) for i in range(0, x.size - n, n // 2)]
    thr = 0.1 * max(energies)
    for i, e in zip(range(0, x.size - n, n // 2), energies):
        if e < thr:
            continue
        f = x[i:i + n] - np.mean(x[i:i + n])
        ac = np.correlate(f, f, "full")[n - 1:]
        lags = np.arange(int(fs / hi), int(fs / lo))
        est.append(fs / lags[np.argmax(ac[lags])])
    return float(np.median(est))


@pytest.mark.parametrize("speaker,lo,hi", [("male", 85, 150), ("female", 170, 270), ("child", 230, 380)])
def test_phrase_pitch_matches_speaker(speaker, lo, hi):
    x = synth_phrase("help_me", SPEAKERS[speaker], np.random.default_rng(1))
    assert np.all(np.isfinite(x)) and 0.3 < x.size / FS < 2.0
    assert lo < f0_autocorr(x) < hi


def test_question_rises_and_call_falls():
    rng = np.random.default_rng(2)
    q = synth_phrase("hello", SPEAKERS["male"], rng)
    c = synth_phrase("help", SPEAKERS["male"], rng)

    def end_vs_mid(x):
        n = x.size
        return f0_autocorr(x[int(0.75 * n):int(0.95 * n)]) / f0_autocorr(x[int(0.3 * n):int(0.55 * n)])

    assert end_vs_mid(q) > 1.05 and end_vs_mid(c) < 0.97


def test_sounds_are_reproducible_and_vary_with_seed():
    for make in (lambda r: synth_phrase("anybody_here", SPEAKERS["female"], r), lambda r: synth_moan(SPEAKERS["male"], r),
                 lambda r: synth_knock("wood", r)):
        a, b, c = make(np.random.default_rng(5)), make(np.random.default_rng(5)), make(np.random.default_rng(6))
        np.testing.assert_array_equal(a, b)
        assert a.shape != c.shape or not np.allclose(a, c)
    with pytest.raises(ValueError, match="phrase"):
        synth_phrase("hullo", SPEAKERS["male"], np.random.default_rng(0))
    with pytest.raises(ValueError, match="surface"):
        synth_knock("glass", np.random.default_rng(0))
    assert len(PHRASES) >= 8


def test_knocks_are_impulsive_and_decay():
    x = synth_knock("concrete", np.random.default_rng(3), n_hits=3)
    env = np.abs(x)
    peaks = np.flatnonzero((env > 0.5 * env.max()))
    groups = np.split(peaks, np.flatnonzero(np.diff(peaks) > 0.1 * FS) + 1)
    assert len(groups) == 3  # three separate hits
    hit = x[groups[0][0]: groups[0][0] + int(0.05 * FS)]
    assert np.max(np.abs(hit[-160:])) < 0.05 * np.max(np.abs(hit[:160]))


@pytest.mark.parametrize("stream", [
    victim_voice("mixed", "female", seed=3),
    ShapedNoise(FS, 4, "pink"),
    generator_noise(FS, 1),
    pump_noise(FS, 2),
    LoopedSignal(np.sin(np.arange(1000) * 0.3), FS),
])
def test_streams_are_block_invariant(stream):
    n0, n = -3000, 3 * FS
    whole = stream.render(n0, n)
    cuts = [0, 1234, 17000, 17001, 40000, n]
    parts = np.concatenate([stream.render(n0 + a, b - a) for a, b in zip(cuts[:-1], cuts[1:])])
    np.testing.assert_allclose(parts, whole, rtol=0, atol=1e-12 * max(1.0, np.abs(whole).max()))


def test_stream_levels_are_unit_rms_while_active():
    v = victim_voice("calls", "male", seed=1, period_s=2.0, p_event=1.0)
    x = v.render(0, 20 * FS)
    frames = x[: x.size // 160 * 160].reshape(-1, 160)
    e = np.mean(frames**2, axis=1)
    assert np.sqrt(np.mean(e[e > e.max() * 1e-5])) == pytest.approx(1.0, rel=0.15)
    for s in (ShapedNoise(FS, 4, "pink"), generator_noise(FS, 1), pump_noise(FS, 2)):
        assert np.std(s.render(0, 10 * FS)) == pytest.approx(1.0, rel=0.1)


def test_event_stream_silent_periods_and_noise_chunks():
    ev = EventStream(lambda r: np.ones(100), FS, period_s=0.5, seed=1, p_event=0.0)
    assert not np.any(ev.render(0, FS))
    with pytest.raises(ValueError, match="p_event"):
        EventStream(lambda r: np.ones(10), FS, 1.0, 0, p_event=1.5)
    nz = TimeKeyedNoise(9, channels=2, chunk=1000)
    np.testing.assert_array_equal(nz.samples(-1500, 4000)[:, 1500:], nz.samples(0, 2500))


def test_phone_track_smoothing_is_the_hann_moving_average():
    """The voices' track smoothing (a step's transition added per step) equals the direct convolution with the
    unit-sum Hann kernel, "same" alignment, for piecewise-constant tracks (one step or many, overlapping
    transitions, steps at the ends) and rows of a 2-D track, and for noise (the FFT path)."""
    rng = np.random.default_rng(5)
    for n_len, kernel, n_steps in [(4000, 400, 1), (4000, 400, 30), (3000, 801, 12), (500, 64, 60), (900, 2, 5)]:
        x = np.zeros(n_len)
        for at in np.sort(rng.integers(0, n_len, n_steps)):
            x[at:] += rng.normal()
        k = np.hanning(kernel + 2)[1:-1]
        k /= k.sum()
        np.testing.assert_allclose(_smooth(x, kernel), np.convolve(x, k, "same"), atol=1e-12)
        rows = np.stack([x, x[::-1], np.zeros(n_len)])
        np.testing.assert_allclose(_smooth(rows, kernel), [np.convolve(r, k, "same") for r in rows], atol=1e-12)
    noise = rng.standard_normal(5000)
    k = np.hanning(802)[1:-1]
    np.testing.assert_allclose(_smooth(noise, 800), np.convolve(noise, k / k.sum(), "same"), atol=1e-12)
