"""Microphone array geometry in the array frame (metres).

Array frame: origin at the array (cube) centre, +x forward, +y left, +z up.
"""
from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from itertools import combinations
from pathlib import Path

import numpy as np

#: Edge length of the paper's aluminium cube (m).
CUBE_EDGE = 0.15
#: Distance between the two microphones on one face, along the face diagonal (m).
FACE_PAIR_SPACING = 0.15


@dataclass(frozen=True)
class ArrayGeometry:
    """Microphone positions ``positions[m] = (x, y, z)`` in metres, array frame."""

    positions: np.ndarray
    name: str = "custom"
    min_separation: float = field(default=1e-3, repr=False)

    def __post_init__(self) -> None:
        pos = np.asarray(self.positions, dtype=float)
        if pos.ndim != 2 or pos.shape[1] != 3:
            raise ValueError(f"array '{self.name}': positions must have shape (n_mics, 3), got {pos.shape}")
        if pos.shape[0] < 2:
            raise ValueError(f"array '{self.name}': need at least 2 microphones, got {pos.shape[0]}")
        if not np.all(np.isfinite(pos)):
            bad = np.argwhere(~np.isfinite(pos))[0]
            raise ValueError(f"array '{self.name}': positions[{bad[0]}][{bad[1]}] is not finite")
        d = np.linalg.norm(pos[:, None, :] - pos[None, :, :], axis=-1)
        d[np.diag_indices(len(pos))] = np.inf
        if d.min() < self.min_separation:
            i, j = np.unravel_index(np.argmin(d), d.shape)
            raise ValueError(
                f"array '{self.name}': microphones {i} and {j} are {d[i, j] * 1e3:.2f} mm apart "
                f"(duplicate positions; expected at least {self.min_separation * 1e3:.1f} mm)"
            )
        pos.setflags(write=False)
        object.__setattr__(self, "positions", pos)

    @property
    def n_mics(self) -> int:
        return int(self.positions.shape[0])

    @property
    def pairs(self) -> np.ndarray:
        """All microphone pairs (i, j) with i < j, shape (n_pairs, 2)."""
        return np.array(list(combinations(range(self.n_mics), 2)), dtype=np.intp)

    @property
    def aperture(self) -> float:
        """Largest distance between two microphones (m)."""
        p = self.positions
        return float(np.max(np.linalg.norm(p[:, None] - p[None], axis=-1)))

    def transformed(self, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
        """World positions ``R @ p + t`` of the microphones, shape (n_mics, 3)."""
        return self.positions @ np.asarray(rotation, float).T + np.asarray(translation, float)

    def to_dict(self) -> dict:
        return {"name": self.name, "positions": self.positions.tolist()}


def cube8(edge: float = CUBE_EDGE, spacing: float = FACE_PAIR_SPACING) -> ArrayGeometry:
    """The paper's array: two microphones on each vertical face of a cube.

    On every vertical face the two microphones sit on a face diagonal,
    symmetric about the face centre and ``spacing`` apart (15 cm in the paper),
    i.e. each is offset by ``a = spacing / (2 sqrt 2)`` = 5.30 cm both
    horizontally and vertically from the face centre. The +x face carries mics
    at (e/2, +a, +a) and (e/2, -a, -a); the other faces follow by rotating
    90 degrees about +z, so the array has four-fold symmetry and its mics sit at
    two heights (z = +-a). Two heights give elevation resolution, and the
    diagonal (rather than horizontal) pairs break the up/down mirror symmetry of a
    single ring. Order: +x face (upper, lower), +y face, -x face, -y face.
    """
    h = edge / 2.0
    a = spacing / (2.0 * np.sqrt(2.0))
    face_px = np.array([[h, a, a], [h, -a, -a]])
    pos = []
    for k in range(4):
        c, s = np.cos(k * np.pi / 2), np.sin(k * np.pi / 2)
        rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        pos.append(face_px @ rz.T)
    return ArrayGeometry(np.round(np.vstack(pos), 12), name="cube8")


def cube8_corners(edge: float = CUBE_EDGE) -> ArrayGeometry:
    """Eight microphones on the corners of a cube of the given edge (m)."""
    h = edge / 2.0
    pos = [[sx * h, sy * h, sz * h] for sz in (1, -1) for sy in (1, -1) for sx in (1, -1)]
    return ArrayGeometry(np.array(pos), name="cube8_corners")


PRESETS = {"cube8": cube8, "cube8_corners": cube8_corners}


def load_array(path: str | Path) -> ArrayGeometry:
    """Read a geometry from TOML or JSON: ``positions = [[x, y, z], ...]`` in metres."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"array geometry file not found: {path}")
    text = path.read_text()
    if path.suffix.lower() == ".json":
        data = json.loads(text)
    elif path.suffix.lower() == ".toml":
        data = tomllib.loads(text)
    else:
        raise ValueError(f"array geometry file {path}: expected a .toml or .json file")
    if "positions" not in data:
        raise ValueError(f"array geometry file {path}: missing field 'positions' (list of [x, y, z] in metres)")
    try:
        pos = np.asarray(data["positions"], dtype=float)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"array geometry file {path}: field 'positions' must be a list of [x, y, z] numbers") from exc
    return ArrayGeometry(pos, name=str(data.get("name", path.stem)))


def get_array(spec: str | Path | ArrayGeometry) -> ArrayGeometry:
    """A preset name (``cube8``, ``cube8_corners``), a geometry file, or a geometry."""
    if isinstance(spec, ArrayGeometry):
        return spec
    if str(spec) in PRESETS:
        return PRESETS[str(spec)]()
    p = Path(spec)
    if p.suffix.lower() in (".toml", ".json"):
        return load_array(p)
    raise ValueError(f"unknown array '{spec}': expected one of {sorted(PRESETS)} or a .toml/.json file")
