"""Acoustic surface materials: World material names -> octave-band absorption.

Absorption and scattering coefficients are *energy* coefficients in the seven
octave bands of :data:`OCTAVE_CENTERS_HZ`. Names resolve, in order, through the
project's own materials (``register_material``, a few built in for rubble worlds),
the aliases below (e.g. ``"concrete"`` -> pyroomacoustics' ``"rough_concrete"``),
and the pyroomacoustics material database (``pyroomacoustics/data/materials.json``,
e.g. ``"brickwork"``, ``"concrete_floor"``, ``"plasterboard"``). Unknown names
raise ``ValueError`` listing what is known.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

#: Octave-band centre frequencies (Hz) of all coefficient vectors.
OCTAVE_CENTERS_HZ = (125.0, 250.0, 500.0, 1000.0, 2000.0, 4000.0, 8000.0)
N_BANDS = len(OCTAVE_CENTERS_HZ)


@dataclass(frozen=True)
class AcousticMaterial:
    """Energy absorption and scattering per octave band (:data:`OCTAVE_CENTERS_HZ`), each in [0, 1]."""

    name: str
    absorption: tuple[float, ...]
    scattering: tuple[float, ...] = (0.0,) * N_BANDS
    description: str = ""

    def __post_init__(self) -> None:
        for field_name in ("absorption", "scattering"):
            v = np.broadcast_to(np.asarray(getattr(self, field_name), float), (N_BANDS,))
            if not np.all(np.isfinite(v)) or v.min() < 0.0 or v.max() > 1.0:
                raise ValueError(
                    f"material '{self.name}': {field_name} must be {N_BANDS} numbers in [0, 1] "
                    f"(octave bands {OCTAVE_CENTERS_HZ} Hz), got {getattr(self, field_name)!r}"
                )
            object.__setattr__(self, field_name, tuple(float(x) for x in v))

    @property
    def reflection_amplitude(self) -> np.ndarray:
        """Pressure reflection factor per band, ``sqrt(1 - absorption)``."""
        return np.sqrt(1.0 - np.asarray(self.absorption))


# Materials the pyroomacoustics database lacks but rubble worlds need. Values are
# engineering estimates from textbook tables (Kuttruff, Vorlaender), stated here so
# they can be argued with: loose rubble/debris behaves like a rough porous layer,
# soil like a packed porous ground, sheet metal like a hard panel with some
# low-frequency panel absorption.
_BUILTIN: dict[str, AcousticMaterial] = {
    m.name: m
    for m in (
        AcousticMaterial("rubble", (0.10, 0.15, 0.20, 0.25, 0.30, 0.35, 0.35), (0.3, 0.4, 0.5, 0.6, 0.7, 0.7, 0.7),
                         "loose masonry/concrete debris (estimate)"),
        AcousticMaterial("soil", (0.15, 0.25, 0.40, 0.55, 0.60, 0.60, 0.60), (0.2,) * N_BANDS,
                         "packed earth/dust (estimate)"),
        AcousticMaterial("metal", (0.10, 0.07, 0.05, 0.04, 0.03, 0.03, 0.03), (0.05,) * N_BANDS,
                         "sheet metal panel (estimate)"),
        AcousticMaterial("anechoic", (1.0,) * N_BANDS, (0.0,) * N_BANDS, "fully absorbing (free field)"),
        AcousticMaterial("rigid", (0.0,) * N_BANDS, (0.0,) * N_BANDS, "perfectly reflecting"),
    )
}

#: Short World names -> pyroomacoustics database names.
ALIASES: dict[str, str] = {
    "concrete": "rough_concrete",
    "brick": "brickwork",
    "plaster": "rough_lime_wash",
    "wood": "wood_16mm",
    "glass": "glass_window",
    "tile": "ceramic_tiles",
    "carpet": "carpet_thin",
    "curtain": "curtains_fabric",
    "gypsum": "plasterboard",
}

_REGISTERED: dict[str, AcousticMaterial] = {}


@lru_cache(maxsize=1)
def _pra_database() -> dict[str, dict]:
    """pyroomacoustics' material database, flattened to ``name -> {coeffs, center_freqs, description}``."""
    import pyroomacoustics as pra

    db = {}
    for group in pra.materials_data["absorption"].values():
        db.update(group)
    return db


def _from_database(name: str) -> AcousticMaterial:
    entry = _pra_database()[name]
    centers = entry.get("center_freqs") or list(OCTAVE_CENTERS_HZ[: len(entry["coeffs"])])
    coeffs = np.asarray(entry["coeffs"], float)
    # Some database entries stop at 4 kHz: hold the last value up to 8 kHz.
    alpha = np.interp(np.log2(OCTAVE_CENTERS_HZ), np.log2(np.asarray(centers, float)), coeffs)
    return AcousticMaterial(name, tuple(alpha), description=str(entry.get("description", "")))


def known_materials() -> list[str]:
    """All names ``get_material`` accepts."""
    return sorted(set(_REGISTERED) | set(_BUILTIN) | set(ALIASES) | set(_pra_database()))


def get_material(name: str) -> AcousticMaterial:
    """Resolve a World material name; ``ValueError`` naming the known ones if it is unknown."""
    if not isinstance(name, str):
        raise ValueError(f"material: expected a material name (str), got {name!r}")
    if name in _REGISTERED:
        return _REGISTERED[name]
    if name in _BUILTIN:
        return _BUILTIN[name]
    db_name = ALIASES.get(name, name)
    if db_name in _pra_database():
        m = _from_database(db_name)
        return m if db_name == name else AcousticMaterial(name, m.absorption, m.scattering, m.description)
    raise ValueError(
        f"unknown acoustic material {name!r}; expected one of: {', '.join(known_materials())} "
        "(or register it with ssl_sim.acoustics.register_material)"
    )


def register_material(name: str, absorption, scattering=0.0, description: str = "") -> AcousticMaterial:
    """Add (or replace) a project material; ``absorption``/``scattering`` scalar or 7 octave-band values."""
    m = AcousticMaterial(name, tuple(np.broadcast_to(np.asarray(absorption, float), (N_BANDS,))),
                         tuple(np.broadcast_to(np.asarray(scattering, float), (N_BANDS,))), description)
    _REGISTERED[name] = m
    return m


def uniform_material(absorption: float, name: str | None = None) -> AcousticMaterial:
    """A frequency-flat material with the given energy absorption."""
    return AcousticMaterial(name or f"uniform_{absorption:.4f}", (float(absorption),) * N_BANDS)


def eyring_absorption_for_rt60(rt60_s: float, volume_m3: float, area_m2: float, c: float = 343.0) -> float:
    """Uniform energy absorption giving reverberation time ``rt60_s`` by Eyring's formula.

    ``T60 = 24 ln(10) V / (-c S ln(1 - a))``  =>  ``a = 1 - exp(-24 ln(10) V / (c S T60))``.
    ``rt60_s = 0`` gives ``a = 1`` (free field).
    """
    if not np.isfinite(rt60_s) or rt60_s < 0:
        raise ValueError(f"rt60_s: expected a reverberation time >= 0 s, got {rt60_s}")
    if rt60_s == 0:
        return 1.0
    return float(1.0 - np.exp(-24.0 * np.log(10.0) * volume_m3 / (c * area_m2 * rt60_s)))


def eyring_rt60(volume_m3: float, areas_m2: np.ndarray, absorptions: np.ndarray, c: float = 343.0) -> np.ndarray:
    """Eyring reverberation time (s) per octave band.

    ``areas_m2``: (n_surfaces,); ``absorptions``: (n_surfaces, n_bands) energy coefficients.
    Returns (n_bands,); 0 where the mean absorption is 1 (no reverberation).
    """
    areas = np.asarray(areas_m2, float)
    alpha = np.asarray(absorptions, float)
    s_total = areas.sum()
    mean_alpha = (areas[:, None] * alpha).sum(axis=0) / s_total
    with np.errstate(divide="ignore"):
        log_term = -np.log(np.clip(1.0 - mean_alpha, 0.0, 1.0))
    rt = np.where(log_term > 0, 24.0 * np.log(10.0) * volume_m3 / (c * s_total * np.where(log_term > 0, log_term, 1.0)), np.inf)
    return np.where(mean_alpha >= 1.0 - 1e-12, 0.0, rt)
