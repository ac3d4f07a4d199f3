"""Procedural victim sounds: calls for help, moans, shouts (both sexes, several pitches)
and knocking/tapping. License-clean by construction and reproducible from a seed.

Voice = source-filter formant synthesis:

* glottal source: Rosenberg (1971) flow pulses driven by a pitch contour (declination,
  stress accents, final rise for questions, jitter, shimmer, vibrato/tremor), flow
  derivative (lip radiation), aspiration noise;
* vocal tract: cascade of five formant resonators (``scipy.signal`` biquads; F1-F4 per
  phone, F5 fixed) with a higher-pole correction, coarticulated by cross-fading the outputs
  of the phones' tracts;
* consonants: /h/ aspiration through the next vowel's tract, fricatives and plosive
  bursts as band-pass noise, nasals and liquids as low-energy voiced murmurs.

Formant targets are the Peterson & Barney / Hillenbrand adult-male averages, scaled
by the speaker's vocal-tract factor (women ~1.17, children ~1.3).

Knocks = modal synthesis: each hit excites a few exponentially decaying modes of the
struck object (wood, metal pipe, concrete) plus a short contact click.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from scipy import signal as sps

from .signals import EventStream

# ---------------------------------------------------------------------------------------------
# Phones: (F1, F2, F3, F4) Hz for an adult male, relative voicing gain.
_VOWELS: dict[str, tuple[float, float, float, float]] = {
    "i": (270, 2290, 3010, 3700), "I": (390, 1990, 2550, 3600), "e": (460, 2000, 2600, 3600),
    "E": (530, 1840, 2480, 3500), "ae": (660, 1720, 2410, 3500), "a": (730, 1090, 2440, 3400),
    "A": (640, 1190, 2390, 3400), "O": (570, 840, 2410, 3400), "o": (480, 880, 2400, 3400),
    "U": (440, 1020, 2240, 3400), "u": (300, 870, 2240, 3400), "@": (500, 1500, 2500, 3500),
}
_SONORANTS: dict[str, tuple[tuple[float, float, float, float], float]] = {
    "m": ((250, 1100, 2200, 3300), 0.22), "n": ((250, 1450, 2300, 3300), 0.22),
    "l": ((360, 1250, 2700, 3400), 0.45), "r": ((420, 1250, 1650, 3300), 0.5),
    "w": ((300, 700, 2200, 3300), 0.5), "j": ((270, 2200, 3000, 3600), 0.5),
}
# Noise consonants: (band Hz, gain, voiced)
_FRICATIVES: dict[str, tuple[tuple[float, float], float, bool]] = {
    "s": ((4000, 7500), 0.35, False), "S": ((2000, 6000), 0.35, False), "f": ((1500, 7500), 0.1, False),
    "z": ((4000, 7500), 0.2, True), "v": ((1500, 7000), 0.08, True),
}
_PLOSIVES: dict[str, tuple[tuple[float, float], float, bool]] = {
    "p": ((400, 2000), 0.35, False), "t": ((3000, 6500), 0.45, False), "k": ((1500, 3500), 0.45, False),
    "b": ((400, 2000), 0.25, True), "d": ((2500, 6000), 0.3, True), "g": ((1300, 3200), 0.3, True),
}
_BANDWIDTHS = (80.0, 100.0, 150.0, 220.0, 300.0)
_F5_HZ = 4500.0  # fifth formant (adult male), the same for every phone

# Words as phone strings with stress marks ('+' before a stressed vowel).
WORDS: dict[str, list[str]] = {
    "help": ["h", "+E", "l", "p"],
    "me": ["m", "+i"],
    "hello": ["h", "@", "l", "+o", "U"],
    "here": ["h", "+I", "@"],
    "anybody": ["+E", "n", "i", "b", "A", "d", "i"],
    "please": ["p", "l", "+i", "z"],
    "somebody": ["s", "+A", "m", "b", "A", "d", "i"],
    "hey": ["h", "+e", "I"],
    "im": ["+a", "I", "m"],
    "stuck": ["s", "t", "+A", "k"],
}
#: Utterances: (words, intonation) with intonation "call" (fall), "question" (final rise), "shout".
PHRASES: dict[str, tuple[tuple[str, ...], str]] = {
    "help": (("help",), "call"),
    "help_me": (("help", "me"), "call"),
    "hello": (("hello",), "question"),
    "anybody_here": (("anybody", "here"), "question"),
    "please_help": (("please", "help"), "call"),
    "somebody_help": (("somebody", "help"), "call"),
    "im_here": (("im", "here"), "call"),
    "im_stuck": (("im", "stuck"), "call"),
    "hey": (("hey",), "shout"),
}


@dataclass(frozen=True)
class Speaker:
    """A voice: mean pitch ``f0_hz``, vocal-tract scale (formants x ``formant_scale``), vocal
    ``effort`` (0 soft .. 1 shouting: shorter open phase, less spectral tilt, higher pitch),
    ``breathiness`` (aspiration noise share), ``jitter``/``shimmer`` (relative per-period
    perturbation of period/amplitude), ``rate`` (speaking-rate factor)."""

    name: str
    f0_hz: float
    formant_scale: float = 1.0
    effort: float = 0.5
    breathiness: float = 0.1
    jitter: float = 0.01
    shimmer: float = 0.05
    rate: float = 1.0


SPEAKERS: dict[str, Speaker] = {
    s.name: s
    for s in (
        Speaker("male_low", 95.0, 0.97, 0.5, 0.08),
        Speaker("male", 120.0, 1.0, 0.5, 0.08),
        Speaker("male_high", 145.0, 1.03, 0.55, 0.1),
        Speaker("female_low", 180.0, 1.12, 0.5, 0.15),
        Speaker("female", 215.0, 1.17, 0.5, 0.15),
        Speaker("female_high", 250.0, 1.2, 0.55, 0.18),
        Speaker("child", 290.0, 1.3, 0.6, 0.15, rate=0.9),
        Speaker("elderly_male", 110.0, 1.0, 0.35, 0.25, jitter=0.03, shimmer=0.12, rate=0.8),
    )
}


def _rosenberg(frac: np.ndarray, open_quotient: float, speed_quotient: float = 2.0) -> np.ndarray:
    """Rosenberg glottal flow over one period; ``frac`` in [0, 1) is the phase within the period."""
    tp = open_quotient * speed_quotient / (1 + speed_quotient)
    tn = open_quotient / (1 + speed_quotient)
    g = np.zeros_like(frac)
    rise = frac < tp
    g[rise] = 0.5 * (1 - np.cos(np.pi * frac[rise] / tp))
    fall = (frac >= tp) & (frac < tp + tn)
    g[fall] = np.cos(0.5 * np.pi * (frac[fall] - tp) / tn)
    return g


def _formant_sos(formants, fs: int, scale: float, effort: float) -> np.ndarray:
    """Cascade of 2-pole resonators (unity gain at DC) as second-order sections."""
    sos = []
    for f, bw in zip((*formants, _F5_HZ), _BANDWIDTHS):
        f = min(f * scale, 0.45 * fs)
        bw = bw * (1.0 - 0.25 * effort)
        r = np.exp(-np.pi * bw / fs)
        a1, a2 = -2 * r * np.cos(2 * np.pi * f / fs), r * r
        g = 1 + a1 + a2
        sos.append([g, 0.0, 0.0, 1.0, a1, a2])
    return np.array(sos)


def _higher_pole_correction(y: np.ndarray, fs: int, gain: float = 2.0, corner_hz: float = 2500.0) -> np.ndarray:
    """High-shelf lift (+9.5 dB above ``corner_hz`` for gain 2): a short formant cascade lacks the poles
    above F5 that keep real voices' 3-6 kHz level up (Klatt's higher-pole correction). With it the
    long-term spectrum of the phrase library (male + female average, re 500 Hz octave) is -6, -10 and
    -18 dB at 1, 2 and 4 kHz, near the standard long-term speech spectrum (about -6, -13, -16 dB)."""
    sos = _butter_sos(2, min(corner_hz, 0.4 * fs), "highpass", fs)
    return y + gain * sps.sosfilt(sos, y)


def _butter_sos(order: int, band: float | tuple[float, float], btype: str, fs: int) -> np.ndarray:
    """Butterworth second-order sections (a copy of a cached design: a few bands recur in every phrase, and
    designing them took a third of the synthesis time)."""
    return _butter_design(order, band, btype, fs).copy()


@lru_cache(maxsize=64)
def _butter_design(order: int, band: float | tuple[float, float], btype: str, fs: int) -> np.ndarray:
    return sps.butter(order, band, btype=btype, fs=fs, output="sos")


def _smooth(x: np.ndarray, n: int) -> np.ndarray:
    """Hann-window moving average over ``n`` samples along the last axis (same length, zeros outside, as
    ``np.convolve(x, k, "same")``); rows of a 2-D ``x`` are smoothed independently. A piecewise-constant
    signal (phone tracks: a few dozen steps) is the sum of its steps' smoothed edges - the kernel's running
    sum placed at each step - which costs a few kernel lengths instead of a full-length FFT convolution."""
    if n <= 1:
        return x
    k, kc = _hann_kernel(n)
    x = np.asarray(x, float)
    if x.ndim == 2:
        return np.stack([_smooth(row, n) for row in x]) if len(x) else x
    jumps = np.diff(x, prepend=0.0, append=0.0)  # step j (0..N) from x[j-1] to x[j], zeros outside
    steps = np.flatnonzero(jumps)
    if steps.size * n > 4 * x.size:  # not piecewise constant (noise): FFT convolution
        return sps.fftconvolve(x, k, mode="same")
    N, off = x.size, (n - 1) // 2  # "same" keeps full-convolution samples off .. off + N - 1
    sh = n - 1 - off
    out = np.zeros(N)
    out[sh:] = x[: N - sh]  # every step's settled part: x delayed by the kernel length minus the centring
    # each step's transition: the kernel's running sum over the n - 1 samples before it settles, added step
    # after step (np.add.at keeps that order where transitions overlap)
    lag = np.arange(n - 1)
    t = steps[:, None] - off + lag
    inside = (t >= 0) & (t < N)
    np.add.at(out, t[inside], (jumps[steps, None] * kc[lag])[inside])
    return out


@lru_cache(maxsize=16)
def _hann_kernel(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The unit-sum Hann kernel of ``n`` samples and its running sum (read-only: shared between calls)."""
    k = np.hanning(n + 2)[1:-1]
    k /= k.sum()
    kc = np.cumsum(k)
    k.flags.writeable = kc.flags.writeable = False
    return k, kc


def _bandnoise(rng: np.random.Generator, n: int, band: tuple[float, float], fs: int) -> np.ndarray:
    lo, hi = band
    hi = min(hi, 0.45 * fs)
    sos = _butter_sos(4, (float(lo), float(hi)), "bandpass", fs)
    y = sps.sosfilt(sos, rng.standard_normal(n + 256))[256:]
    return y / (np.std(y) + 1e-12)


def synth_phrase(phrase: str | tuple[str, ...], speaker: Speaker, rng: np.random.Generator, fs: int = 16000,
                 intonation: str | None = None) -> np.ndarray:
    """Synthesize a phrase (a key of :data:`PHRASES` or a tuple of :data:`WORDS`); returns float (n,)."""
    if isinstance(phrase, str):
        if phrase not in PHRASES:
            raise ValueError(f"phrase: expected one of {sorted(PHRASES)}, got {phrase!r}")
        words, default_int = PHRASES[phrase]
    else:
        words, default_int = tuple(phrase), "call"
        for w in words:
            if w not in WORDS:
                raise ValueError(f"phrase word: expected one of {sorted(WORDS)}, got {w!r}")
    intonation = intonation or default_int
    shout = intonation == "shout"
    sp = replace(speaker, effort=max(speaker.effort, 0.9)) if shout else speaker

    # --- phone timeline ---------------------------------------------------------------
    phones: list[tuple[str, float, bool]] = []  # (phone, duration s, stressed)
    for wi, w in enumerate(words):
        for p in WORDS[w]:
            stressed = p.startswith("+")
            p = p.lstrip("+")
            if p in _VOWELS:
                d = (0.20 if stressed else 0.09) * (1.5 if shout else 1.0)
            elif p in _SONORANTS:
                d = 0.07
            elif p in _FRICATIVES:
                d = 0.11
            elif p in _PLOSIVES:
                d = 0.085
            elif p == "h":
                d = 0.07
            else:
                raise ValueError(f"unknown phone {p!r} in word {w!r}")
            d *= rng.uniform(0.85, 1.2) / sp.rate
            phones.append((p, d, stressed))
        if wi < len(words) - 1:
            phones.append(("_", rng.uniform(0.03, 0.08), False))
    # Lengthen the final vowel (calls are drawn out), more for shouts.
    for i in range(len(phones) - 1, -1, -1):
        if phones[i][0] in _VOWELS:
            p, d, s = phones[i]
            phones[i] = (p, d * (2.2 if shout else 1.5), s)
            break

    n_ph = len(phones)
    starts = np.concatenate([[0.0], np.cumsum([d for _, d, _ in phones])])
    n = int(np.ceil(starts[-1] * fs)) + int(0.05 * fs)
    idx = np.clip(np.searchsorted(starts, np.arange(n) / fs, side="right") - 1, 0, n_ph - 1)

    # Tract per phone: vowels/sonorants their own; /h/, plosive aspiration: next vowel's; others: previous.
    def next_vowel(i: int) -> str:
        for j in range(i, n_ph):
            if phones[j][0] in _VOWELS:
                return phones[j][0]
        return "@"

    tract_of: list[tuple[float, float, float, float]] = []
    voicing = np.zeros(n_ph)
    aspir = np.zeros(n_ph)
    for i, (p, _, stressed) in enumerate(phones):
        if p in _VOWELS:
            tract_of.append(_VOWELS[p])
            voicing[i] = 1.0 if stressed else 0.8
        elif p in _SONORANTS:
            tract_of.append(_SONORANTS[p][0])
            voicing[i] = _SONORANTS[p][1]
        elif p == "h":
            tract_of.append(_VOWELS[next_vowel(i)])
            aspir[i] = 0.5
        else:
            tract_of.append(_VOWELS[next_vowel(i)])
            if p in _FRICATIVES and _FRICATIVES[p][2]:
                voicing[i] = 0.15
            if p in _PLOSIVES and _PLOSIVES[p][2]:
                voicing[i] = 0.08
    smooth_n = int(0.025 * fs)
    av = _smooth(voicing[idx], smooth_n)
    ah = _smooth(aspir[idx], int(0.015 * fs))

    # --- pitch contour ------------------------------------------------------------------
    t = np.arange(n) / fs
    dur = starts[-1]
    f0 = sp.f0_hz * (1.0 + 0.6 * (sp.effort - 0.5)) * (1.6 if shout else 1.0) * rng.uniform(0.93, 1.07)
    contour = 1.0 - 0.12 * t / max(dur, 1e-3)  # declination
    stress_track = np.array([1.0 if s and p in _VOWELS else 0.0 for p, _, s in phones])[idx]
    contour *= 1.0 + 0.12 * _smooth(stress_track, int(0.08 * fs))
    tail = np.clip((t - (dur - 0.35)) / 0.35, 0.0, 1.0)
    if intonation == "question":
        contour *= 1.0 + 0.35 * tail**1.5
    else:
        contour *= 1.0 - 0.2 * tail**1.2
    drift = _smooth(rng.standard_normal(n), int(0.05 * fs)) * np.sqrt(0.05 * fs) * sp.jitter
    vib_hz = rng.uniform(4.5, 6.5)
    contour *= 1.0 + drift + 0.008 * np.sin(2 * np.pi * vib_hz * t)
    f0_t = f0 * contour

    # --- glottal source -----------------------------------------------------------------
    phase = np.cumsum(f0_t) / fs
    period_idx = np.floor(phase).astype(int)
    frac = phase - period_idx
    n_periods = period_idx[-1] + 1
    oq = 0.75 - 0.35 * sp.effort  # open quotient: pressed/loud voice closes longer
    flow = _rosenberg(frac, oq)
    shimmer = 1.0 + sp.shimmer * rng.standard_normal(n_periods)
    flow = flow * shimmer[period_idx]
    dflow = np.diff(flow, prepend=0.0) * fs / f0  # flow derivative ~ lip radiation; normalised per period
    tilt_pole = max(0.0, 0.6 - 0.9 * sp.effort)  # soft voice: steeper spectral tilt
    dflow = sps.lfilter([1.0 - tilt_pole], [1.0, -tilt_pole], dflow)
    noise = rng.standard_normal(n)
    pulse_mod = 0.5 + 0.5 * (flow > 0.3)
    exc = av * (dflow + sp.breathiness * 0.3 * noise * pulse_mod) + ah * noise * 0.3

    # --- vocal tract: cross-faded cascades ------------------------------------------------
    uniq = sorted(set(tract_of))
    tract_idx = np.array([uniq.index(tr) for tr in tract_of])
    y = np.zeros(n)
    weights = _smooth((tract_idx[idx][None] == np.arange(len(uniq))[:, None]).astype(float), smooth_n)
    for formants, w in zip(uniq, weights):
        if w.max() <= 0:
            continue
        y += w * sps.sosfilt(_formant_sos(formants, fs, sp.formant_scale, sp.effort), exc)

    y = _higher_pole_correction(y, fs)

    # --- noise consonants -----------------------------------------------------------------
    for i, (p, d, _) in enumerate(phones):
        a, b = int(starts[i] * fs), int(starts[i + 1] * fs)
        if p in _FRICATIVES:
            band, g, _v = _FRICATIVES[p]
            seg = _bandnoise(rng, b - a, band, fs) * np.hanning(b - a)
            y[a:b] += g * seg * np.max(np.abs(y)) / 4 if np.any(y) else g * seg
        elif p in _PLOSIVES:
            band, g, voiced = _PLOSIVES[p]
            closure = int(0.6 * (b - a))
            burst_len = max(8, int(0.012 * fs))
            bs = a + closure
            be = min(bs + burst_len, n)
            env = np.exp(-np.arange(be - bs) / (0.004 * fs))
            seg = _bandnoise(rng, be - bs, band, fs) * env
            y[a:bs] *= 0.05 if not voiced else 0.3
            y[bs:be] += g * seg * (np.max(np.abs(y)) / 3 if np.any(y) else 1.0)
    fade = int(0.005 * fs)
    y[:fade] *= np.linspace(0, 1, fade)
    y[-fade:] *= np.linspace(1, 0, fade)
    return y


def synth_moan(speaker: Speaker, rng: np.random.Generator, fs: int = 16000) -> np.ndarray:
    """A low, breathy moan ("mmm-ohhh"): nasal onset, slow falling glide, tremor."""
    sp = replace(speaker, effort=0.25, breathiness=max(speaker.breathiness, 0.3), jitter=speaker.jitter * 1.5)
    dur = rng.uniform(0.9, 1.8)
    n = int(dur * fs)
    t = np.arange(n) / fs
    f0 = sp.f0_hz * 0.85 * rng.uniform(0.9, 1.1) * (1.05 - 0.2 * t / dur)
    f0 *= 1.0 + 0.02 * np.sin(2 * np.pi * rng.uniform(3.0, 5.0) * t)
    phase = np.cumsum(f0) / fs
    pidx = np.floor(phase).astype(int)
    flow = _rosenberg(phase - pidx, 0.8) * (1.0 + sp.shimmer * rng.standard_normal(pidx[-1] + 1))[pidx]
    dflow = sps.lfilter([0.2], [1.0, -0.8], np.diff(flow, prepend=0.0) * fs / f0)
    exc = dflow + sp.breathiness * 0.4 * rng.standard_normal(n)
    vowel = rng.choice(["O", "o", "u", "A"])
    m_w = np.clip(1.0 - t / 0.25, 0.0, 1.0)
    y = (m_w * sps.sosfilt(_formant_sos(_SONORANTS["m"][0], fs, sp.formant_scale, 0.2), exc) * 0.4
         + (1 - m_w) * sps.sosfilt(_formant_sos(_VOWELS[str(vowel)], fs, sp.formant_scale, 0.2), exc))
    y = _higher_pole_correction(y, fs)
    env = np.minimum(1.0, t / 0.15) * np.minimum(1.0, (dur - t) / 0.4)
    env *= 1.0 + 0.25 * np.sin(2 * np.pi * rng.uniform(2.0, 4.0) * t)  # sobbing tremor
    return y * env


# ---------------------------------------------------------------------------------------------
# Knocking / tapping: modal synthesis.
_SURFACES: dict[str, tuple[tuple[float, float, float], ...]] = {
    # (mode Hz, decay time constant s, relative amplitude)
    "wood": ((190, 0.030, 1.0), (420, 0.022, 0.7), (780, 0.015, 0.5), (1350, 0.010, 0.3), (2100, 0.006, 0.2)),
    "metal_pipe": ((520, 0.35, 1.0), (1430, 0.25, 0.7), (2780, 0.18, 0.5), (4510, 0.12, 0.3), (6600, 0.08, 0.2)),
    "concrete": ((140, 0.012, 1.0), (310, 0.009, 0.7), (620, 0.006, 0.5), (1200, 0.004, 0.3)),
}


def synth_knock(surface: str, rng: np.random.Generator, fs: int = 16000, n_hits: int | None = None) -> np.ndarray:
    """A pattern of 2-5 knocks (or ``n_hits``) on ``surface`` (wood, metal_pipe, concrete)."""
    if surface not in _SURFACES:
        raise ValueError(f"surface: expected one of {sorted(_SURFACES)}, got {surface!r}")
    modes = _SURFACES[surface]
    hits = int(n_hits or rng.integers(2, 6))
    gap = rng.uniform(0.18, 0.32)
    ring = max(d for _, d, _ in modes) * 5
    n = int((gap * (hits - 1) + ring + 0.05) * fs)
    y = np.zeros(n)
    th = np.arange(int(ring * fs)) / fs
    for h in range(hits):
        onset = int((h * gap + rng.uniform(-0.02, 0.02) + 0.02) * fs)
        force = rng.uniform(0.7, 1.0)
        hit = np.zeros_like(th)
        for f, tau, a in modes:
            f_h = f * rng.uniform(0.97, 1.03)
            hit += a * np.exp(-th / tau) * np.sin(2 * np.pi * f_h * th + rng.uniform(0, 2 * np.pi))
        click = _bandnoise(rng, min(th.size, int(0.003 * fs)), (1000, 6000), fs) * 0.3
        hit[: click.size] += click * np.hanning(click.size)
        end = min(n, onset + th.size)
        y[onset:end] += force * hit[: end - onset]
    return y


# ---------------------------------------------------------------------------------------------
VICTIM_SOUNDS = ("calls", "moans", "shouts", "knocks", "mixed")


def victim_event(kind: str, speaker: Speaker, fs: int = 16000):
    """``make_event(rng)`` for :class:`EventStream`: one call/moan/shout/knock pattern per event."""
    calls = [k for k, (_, i) in PHRASES.items() if i != "shout"]
    if kind not in VICTIM_SOUNDS:
        raise ValueError(f"victim sound kind: expected one of {VICTIM_SOUNDS}, got {kind!r}")

    def make(rng: np.random.Generator) -> np.ndarray:
        k = kind
        if k == "mixed":
            k = str(rng.choice(["calls", "calls", "moans", "shouts", "knocks"]))
        if k == "calls":
            return synth_phrase(str(rng.choice(calls)), speaker, rng, fs)
        if k == "shouts":
            return synth_phrase(str(rng.choice(["help", "hey", "hello", "help_me"])), speaker, rng, fs, intonation="shout")
        if k == "moans":
            return synth_moan(speaker, rng, fs)
        return synth_knock(str(rng.choice(list(_SURFACES))), rng, fs)

    return make


def victim_voice(kind: str = "calls", speaker: str | Speaker = "male", seed: int = 0, fs: int = 16000,
                 period_s: float = 2.5, p_event: float = 0.9, stream: int = 0) -> EventStream:
    """A victim's sound stream: one event (call, moan, shout or knock pattern) per ``period_s``
    with probability ``p_event``; unit RMS while sounding. ``speaker``: a :data:`SPEAKERS` key or a Speaker."""
    if isinstance(speaker, str):
        if speaker not in SPEAKERS:
            raise ValueError(f"speaker: expected one of {sorted(SPEAKERS)}, got {speaker!r}")
        speaker = SPEAKERS[speaker]
    return EventStream(victim_event(kind, speaker, fs), fs, period_s, seed, stream=stream, p_event=p_event)


def continuous_voice(speaker: str | Speaker = "male", seed: int = 0, fs: int = 16000, stream: int = 0) -> EventStream:
    """Near-continuous calling (short pauses only), like a loudspeaker replaying speech in a lab test."""
    return victim_voice("calls", speaker, seed, fs, period_s=1.2, p_event=1.0, stream=stream)
