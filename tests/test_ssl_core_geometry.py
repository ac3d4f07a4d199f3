"""Array geometry, spherical grids and pairwise GCC-PHAT against geometry and analytic delays."""
from __future__ import annotations

import ast
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from signals import delay_signals
from ssl_core.gcc_phat import gcc_phat
from ssl_core.geometry import ArrayGeometry, cube8, cube8_corners, get_array, load_array
from ssl_core.grid import angular_distance, azimuth_elevation, direction_from_angles, make_grid
from ssl_core.srp import tdoa_table

SRC = Path(__file__).resolve().parents[1] / "src"


def test_cube8_matches_the_paper():
    p = cube8().positions
    assert p.shape == (8, 3)
    # two microphones per vertical face, on the face plane (|x| or |y| = 7.5 cm), none on top/bottom
    on_face = np.isclose(np.abs(p[:, :2]), 0.075).any(axis=1)
    assert on_face.all() and not np.isclose(np.abs(p[:, 2]), 0.075).any()
    for k in range(4):
        a, b = p[2 * k], p[2 * k + 1]
        assert np.linalg.norm(a - b) == pytest.approx(0.15, abs=1e-9)  # 15 cm apart
        face_centre = (a + b) / 2
        assert np.linalg.norm(face_centre) == pytest.approx(0.075, abs=1e-9)  # symmetric about the face centre
        d = np.abs(a - b)
        # along a face diagonal: equal horizontal and vertical extent
        assert np.sort(d)[1] == pytest.approx(d[2], abs=1e-9) and np.sort(d)[0] == pytest.approx(0, abs=1e-12)
    # the array centre is the cube centre, and all mics lie inside the cube
    assert np.allclose(p.mean(axis=0), 0)
    assert np.abs(p).max() <= 0.075 + 1e-12


def test_cube8_corners():
    p = cube8_corners().positions
    assert np.allclose(np.abs(p), 0.075)
    assert len({tuple(np.sign(r)) for r in p}) == 8


def test_geometry_files_roundtrip(tmp_path):
    g = cube8()
    (tmp_path / "a.json").write_text(json.dumps(g.to_dict()))
    rows = ",\n".join(f"  [{x}, {y}, {z}]" for x, y, z in g.positions)
    (tmp_path / "a.toml").write_text(f'name = "mine"\npositions = [\n{rows}\n]\n')
    assert np.allclose(load_array(tmp_path / "a.json").positions, g.positions)
    t = get_array(str(tmp_path / "a.toml"))
    assert t.name == "mine" and np.allclose(t.positions, g.positions)


@pytest.mark.parametrize(
    "positions, match",
    [
        ([[0, 0, 0]], "at least 2"),
        ([[0, 0, 0], [0, 0, 0]], "duplicate"),
        ([[0, 0, 0], [np.nan, 0, 0]], "not finite"),
        ([[0, 0], [1, 1]], "shape"),
    ],
)
def test_geometry_validation(positions, match):
    with pytest.raises(ValueError, match=match):
        ArrayGeometry(np.array(positions, float))


def test_geometry_file_errors(tmp_path):
    (tmp_path / "bad.toml").write_text('name = "x"\n')
    with pytest.raises(ValueError, match="positions"):
        load_array(tmp_path / "bad.toml")
    with pytest.raises(ValueError, match="unknown array"):
        get_array("cube9")
    with pytest.raises(FileNotFoundError):
        get_array(str(tmp_path / "none.json"))


@pytest.mark.parametrize("spacing_deg", [1.5, 4.0, 10.0])
def test_grid_spacing_and_coverage(spacing_deg):
    g = make_grid(np.deg2rad(spacing_deg))
    d, _ = cKDTree(g.directions).query(g.directions, k=2)
    nn = np.rad2deg(2 * np.arcsin(d[:, 1] / 2))
    assert nn.max() <= spacing_deg
    # no direction on the sphere is farther than one spacing from a grid point
    probe = np.random.default_rng(0).standard_normal((20000, 3))
    probe /= np.linalg.norm(probe, axis=1, keepdims=True)
    dc, _ = cKDTree(g.directions).query(probe)
    assert np.rad2deg(2 * np.arcsin(dc / 2)).max() <= spacing_deg
    assert np.allclose(np.linalg.norm(g.directions, axis=1), 1)


def test_angles_roundtrip():
    rng = np.random.default_rng(1)
    az, el = rng.uniform(-np.pi, np.pi, 100), rng.uniform(-1.5, 1.5, 100)
    az2, el2 = azimuth_elevation(direction_from_angles(az, el))
    assert np.allclose(az, az2) and np.allclose(el, el2)
    # azimuth counter-clockwise from +x: +90 degrees is +y
    assert np.allclose(direction_from_angles(np.pi / 2, 0.0), [0, 1, 0], atol=1e-12)
    assert angular_distance([1, 0, 0], [0, 0, 1]) == pytest.approx(np.pi / 2)


def test_tdoa_table_far_and_near_field():
    g = cube8()
    grid = make_grid(np.deg2rad(10))
    far = tdoa_table(g, grid)
    i, j = g.pairs[0]
    expect = -((g.positions[i] - g.positions[j]) @ grid.directions.T) / 343.0
    assert np.allclose(far[0], expect)
    near = tdoa_table(g, type(grid)(grid.directions, grid.spacing, radius=100.0))
    assert np.allclose(near, far, atol=2e-7)  # a far radius tends to the far field
    assert np.abs(far).max() <= g.aperture / 343.0 + 1e-12


@pytest.mark.parametrize("delay_samples", [-7.25, -0.5, 0.0, 3.3, 11.8])
def test_gcc_phat_recovers_fractional_delay(delay_samples):
    fs = 16000
    s = np.random.default_rng(4).standard_normal(8000)
    x = delay_signals(s, np.array([delay_samples / fs, 0.0]), fs)
    tau, lags, cc = gcc_phat(x[0], x[1], fs, max_tau=0.002, upsample=32)
    assert tau * fs == pytest.approx(delay_samples, abs=1 / 32)
    assert cc.max() == pytest.approx(1.0, abs=0.05)  # normalised: a coherent path gives 1


def test_ssl_core_imports_only_numpy_and_scipy():
    # threadpoolctl: optional (pure Python), imported lazily to pin BLAS threads; without it ssl_core runs unpinned
    allowed = {"numpy", "scipy", "ssl_core", "__future__", "threadpoolctl"}
    stdlib = set(sys.stdlib_module_names)
    for path in (SRC / "ssl_core").rglob("*.py"):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            else:
                continue
            for n in names:
                top = n.split(".")[0]
                assert top in allowed | stdlib, f"{path.name} imports {n}"
