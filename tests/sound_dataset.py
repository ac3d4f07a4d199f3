"""The real-sound data set (data/sounds, see its PROVENANCE) cut into labelled 1 s chunks.

Truth is independent of any detector: the chunk's file category (speech/shouts vs the
non-speech categories) plus an energy test for the speech files, so that a 1 s chunk that is
mostly the silence between two prompts is not asked to count as speech.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.io import wavfile

DATA = Path(__file__).resolve().parents[1] / "data" / "sounds"
SPEECH_CATEGORIES = ("speech", "shouts")
FS = 16000
CHUNK_S, HOP_S = 1.0, 0.5
_FRAME = 512          # 32 ms energy frames for the truth labels
_ACTIVE_DB = 30.0     # a frame is "sounding" within 30 dB of the file's loudest frame
_SPEECH_ACTIVE = 0.5  # a speech chunk needs >= 50 % sounding frames (else it is a pause: unlabelled)


@dataclass(frozen=True)
class Recording:
    split: str
    category: str
    name: str
    samples: np.ndarray   # float, full scale 1, 16 kHz mono
    sex: str

    @property
    def is_speech(self) -> bool:
        return self.category in SPEECH_CATEGORIES


def recordings(split: str) -> list[Recording]:
    """All recordings of ``split`` ('dev' or 'test') listed in PROVENANCE."""
    if split not in ("dev", "test"):
        raise ValueError(f"split: expected 'dev' or 'test', got {split!r}")
    out = []
    with open(DATA / "PROVENANCE") as f:
        rows = csv.DictReader((line for line in f if not line.startswith("#")), delimiter="\t")
        for r in rows:
            if r["split"] != split:
                continue
            fs, x = wavfile.read(DATA / r["file"])
            if fs != FS or x.ndim != 1:
                raise ValueError(f"{r['file']}: expected 16 kHz mono, got {fs} Hz shape {x.shape}")
            out.append(Recording(split, r["category"], Path(r["file"]).stem, x.astype(np.float64) / 32768.0,
                                 r["speaker_sex"]))
    return out


def chunk_starts(rec: Recording) -> list[int]:
    """Start samples of the labelled 1 s chunks (hop 0.5 s): sounding chunks; for speech, talking ones."""
    x = rec.samples
    n_fr = len(x) // _FRAME
    e = 10 * np.log10((x[: n_fr * _FRAME].reshape(n_fr, _FRAME) ** 2).mean(1) + 1e-12)
    sounding = e >= e.max() - _ACTIVE_DB
    per_chunk = int(CHUNK_S * FS) // _FRAME
    starts = []
    for s in range(0, len(x) - int(CHUNK_S * FS) + 1, int(HOP_S * FS)):
        f0 = s // _FRAME
        frac = sounding[f0: f0 + per_chunk].mean()
        if (frac >= _SPEECH_ACTIVE) if rec.is_speech else (frac > 0):
            starts.append(s)
    return starts
