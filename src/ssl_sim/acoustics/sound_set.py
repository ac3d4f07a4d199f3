"""The shipped set of real recordings (``ssl_sim.resources.SOUNDS_DIR``) as a catalogue: its ``PROVENANCE`` table.

Every recording belongs to one part, ``dev`` or ``test``, and one category (``speech``, ``shouts``, ``machinery``,
``engine``, ``alarm``, ``music``, ``knock``, ``rubble``, ``wind_hum``). No speaker, machine or source file is in
both parts: whatever is tuned or trained uses ``dev``; ``test`` is only ever evaluated on.

    sound_files("test", "speech")      # -> [SoundFile(split='test', category='speech', path=..., ...), ...]
"""
from __future__ import annotations

import csv
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from ssl_sim.resources import SOUNDS_DIR

#: The two parts of the sound set.
SOUND_SPLITS = ("dev", "test")
#: Categories of a person's voice (a victim's sound); the others are non-speech sounds.
SPEECH_CATEGORIES = ("speech", "shouts")


@dataclass(frozen=True)
class SoundFile:
    """One recording: ``path`` absolute (16 kHz mono WAV), ``seconds`` its length, provenance as listed."""

    split: str
    category: str
    path: Path
    seconds: float
    source_package: str
    sources: tuple[str, ...]        # paths of the original files inside the source package
    license: str
    speaker_sex: str                # "-" for non-speech
    content: str

    @property
    def name(self) -> str:
        return self.path.stem

    @property
    def is_speech(self) -> bool:
        return self.category in SPEECH_CATEGORIES


@lru_cache(maxsize=4)
def _catalogue(sounds_dir: Path) -> tuple[SoundFile, ...]:
    provenance = sounds_dir / "PROVENANCE"
    out = []
    with open(provenance) as f:
        rows = csv.DictReader((line for line in f if not line.startswith("#")), delimiter="\t")
        for k, r in enumerate(rows):
            if r["split"] not in SOUND_SPLITS:
                raise ValueError(f"{provenance}: row {k + 1}: split: expected one of {SOUND_SPLITS}, "
                                 f"got {r['split']!r}")
            path = (sounds_dir / r["file"]).resolve()
            if not path.is_file():
                raise FileNotFoundError(f"{provenance}: row {k + 1}: file {r['file']} not found under {sounds_dir}")
            out.append(SoundFile(r["split"], r["category"], path, float(r["seconds"]), r["source_package"],
                                 tuple(s.strip() for s in r["paths_in_package"].split(";")), r["license"],
                                 r["speaker_sex"], r["content"]))
    return tuple(out)


def categories(sounds_dir: Path = SOUNDS_DIR) -> tuple[str, ...]:
    """The categories listed in the sound set, in order of first appearance."""
    return tuple(dict.fromkeys(s.category for s in _catalogue(Path(sounds_dir))))


def sound_files(split: str | None = None, category: str | None = None,
                sounds_dir: Path = SOUNDS_DIR) -> list[SoundFile]:
    """The recordings of ``split`` (``dev`` | ``test``; None: both) and ``category`` (None: all), in
    PROVENANCE order."""
    if split is not None and split not in SOUND_SPLITS:
        raise ValueError(f"split: expected one of {SOUND_SPLITS}, got {split!r}")
    files = _catalogue(Path(sounds_dir))
    if category is not None:
        known = categories(sounds_dir)
        if category not in known:
            raise ValueError(f"category: expected one of {known}, got {category!r}")
    return [s for s in files if (split is None or s.split == split) and (category is None or s.category == category)]
