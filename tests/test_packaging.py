"""A wheel built from the tree is the whole testbed: installed outside the tree, its commands find the shipped
scenarios, scenes, models, the VAD model and the sound set, and give real answers.

The wheel is installed with ``--no-deps`` into a fresh virtualenv; the dependencies (numpy, MuJoCo, ...) come
from the test's own interpreter through a ``.pth`` line naming its site-packages. A plain path line adds that
directory to ``sys.path`` without running the ``.pth`` files inside it, so the editable install of this tree
(if any) stays inactive and every ``ssl_*`` module is the wheel's.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import sysconfig
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src"

pytestmark = pytest.mark.slow


def _shipped_data() -> set[str]:
    """Every non-Python file under src/ (package data), as paths inside the wheel."""
    return {p.relative_to(SRC).as_posix() for p in SRC.rglob("*")
            if p.is_file() and p.suffix not in (".py", ".pyc") and "egg-info" not in p.as_posix()
            and "__pycache__" not in p.parts}


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    # build isolation: setuptools >= 77 (pyproject's build requirement) comes from the package index
    r = subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-w", str(out), "-q"],
                       capture_output=True, text=True, timeout=600)
    offline = ("Could not find a version", "No matching distribution", "connection", "Temporary failure in name",
               "Network is unreachable")
    if r.returncode != 0 and any(m.lower() in r.stderr.lower() for m in offline):
        pytest.skip(f"cannot fetch the build backend (setuptools >= 77) from the package index: "
                    f"{r.stderr.strip().splitlines()[-1]}")
    assert r.returncode == 0, r.stderr
    (whl,) = out.glob("ssl_rescue-*.whl")
    return whl


@pytest.fixture(scope="module")
def installed(wheel, tmp_path_factory) -> Path:
    """A fresh virtualenv outside the tree with the wheel installed; returns its bin directory."""
    env_dir = tmp_path_factory.mktemp("venv")
    venv.EnvBuilder(with_pip=True, clear=True).create(env_dir)
    py = env_dir / "bin" / "python"
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True, env=_clean_env()).stdout.strip()
    r = subprocess.run([str(py), "-m", "pip", "install", "--no-deps", "--no-index", "-q", str(wheel)],
                       capture_output=True, text=True, timeout=300, env=_clean_env(), cwd=env_dir)
    assert r.returncode == 0, r.stderr
    # after the install: with the dependencies' directory on the path, pip would see this project's own
    # (editable) metadata there and call the wheel "already satisfied"
    Path(site, "_test_deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    return env_dir / "bin"


def _clean_env() -> dict[str, str]:
    """This process's environment without what would put the source tree on the path."""
    return {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME")}


def _run(bin_dir: Path, cwd: Path, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = _clean_env()
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    return subprocess.run([str(bin_dir / args[0]), *args[1:]], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)


def test_the_wheel_carries_every_data_file(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    missing = _shipped_data() - names
    assert not missing, f"not in the wheel: {sorted(missing)}"
    # the kinds the testbed needs, named so that an empty source tree cannot pass
    for needed in ("ssl_sim/scenarios/paper_lab.toml", "ssl_sim/scenarios/scenes/slab_pair.toml",
                   "ssl_sim/models/omni_robot.xml", "ssl_sim/models/scenes/light_rubble.xml",
                   "robot/models/silero_vad_op18_ifless.onnx.gz", "ssl_sim/sounds/PROVENANCE"):
        assert needed in names
    assert sum(n.startswith("ssl_sim/sounds/") and n.endswith(".wav") for n in names) >= 20


def test_the_installed_wheel_runs_outside_the_tree(installed, tmp_path):
    cwd = tmp_path / "elsewhere"
    cwd.mkdir()
    where = _run(installed, cwd, "python", "-c", "import ssl_sim, robot, ssl_core; "
                 "print(ssl_sim.__file__); print(robot.__file__); print(ssl_core.__file__)")
    assert where.returncode == 0, where.stderr
    for line in where.stdout.split():
        assert not Path(line).is_relative_to(ROOT) and Path(line).is_relative_to(installed.parent), line

    for prog in ("ssl-rescue", "ssl-locate", "ssl-robot"):
        v = _run(installed, cwd, prog, "--version")
        assert v.returncode == 0 and v.stdout.strip().startswith(prog) and v.stdout.split()[-1][0].isdigit(), v

    listed = _run(installed, cwd, "ssl-rescue", "list")
    assert listed.returncode == 0, listed.stderr
    shipped = sorted(p.stem for p in (SRC / "ssl_sim" / "scenarios").glob("*.toml"))
    for name in shipped:
        assert name in listed.stdout

    run = _run(installed, cwd, "ssl-rescue", "run", "paper_lab", "--time-limit", "30", "--out", "run", "-q")
    assert run.returncode == 0, run.stderr
    results = json.loads((cwd / "run" / "results.json").read_text())
    assert results["scenario"] == "paper_lab" and results["n_victims"] == 1
    assert Path(results["scenario_file"]).is_relative_to(installed.parent)
    assert 0 < results["sim_time_s"] <= 30.0 + 1e-6

    rec = _run(installed, cwd, "ssl-rescue", "record", "paper_lab", "--duration", "4", "--out", "rec.wav")
    assert rec.returncode == 0, rec.stderr
    truth = json.loads((cwd / "rec.json").read_text())
    (caller,) = truth["sources"]
    located = _run(installed, cwd, "ssl-locate", "rec.wav", "--json")
    assert located.returncode == 0, located.stderr
    doc = json.loads(located.stdout.strip().splitlines()[-1])
    (det, *_) = doc["windows"][-1]["detections"]
    # the caller's direction from the scene geometry (array frame), constant while the robot stands
    az, el = caller["azimuth_deg"][0], caller["elevation_deg"][0]
    u = [math.cos(math.radians(el)) * math.cos(math.radians(az)),
         math.cos(math.radians(el)) * math.sin(math.radians(az)), math.sin(math.radians(el))]
    d_az, d_el = math.radians(det["azimuth_deg"]), math.radians(det["elevation_deg"])
    v = [math.cos(d_el) * math.cos(d_az), math.cos(d_el) * math.sin(d_az), math.sin(d_el)]
    error_deg = math.degrees(math.acos(max(-1.0, min(1.0, sum(a * b for a, b in zip(u, v))))))
    assert error_deg < 5.0, (det, az, el)
