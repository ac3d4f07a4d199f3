"""Layering rules, checked on the sources (ast) and on a fresh interpreter's imports.

- robot never imports ssl_sim (the same code must run on the robot without the simulator);
- robot's third-party imports are numpy/scipy (+ pyserial and sounddevice only in robot.hardware);
  sounddevice is imported lazily (inside functions), so importing robot never needs it;
- ssl_core imports neither robot nor ssl_sim.
"""
import ast
import subprocess
import sys
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
STDLIB = set(sys.stdlib_module_names)


def _imports(path: Path):
    """(top-level module name, imported at module level?) for every import in the file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    top_level = {id(n) for n in tree.body}
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield a.name.split(".")[0], id(node) in top_level
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module.split(".")[0], id(node) in top_level


def _files(pkg):
    files = sorted((SRC / pkg).rglob("*.py"))
    assert files, f"no sources found under {SRC / pkg}"
    return files


def test_robot_never_imports_the_simulator():
    bad = [f"{p.relative_to(SRC)} imports {m}" for p in _files("robot") for m, _ in _imports(p) if m == "ssl_sim"]
    assert not bad, bad


def test_robot_third_party_imports_are_minimal_and_hardware_ones_lazy():
    allowed_core = {"numpy", "scipy", "robot", "ssl_core", "__future__"}
    problems = []
    for p in _files("robot"):
        hardware = "hardware" in p.relative_to(SRC).parts
        for mod, at_top in _imports(p):
            if mod in STDLIB or mod in allowed_core:
                continue
            if hardware and mod == "serial":
                continue  # pyserial: a core dependency, only the serial backend uses it
            if hardware and mod == "sounddevice" and not at_top:
                continue  # optional 'hardware' extra, imported lazily
            if p.name == "vad.py" and mod == "onnxruntime" and not at_top:
                continue  # the voice activity detector's runtime (a core dependency), loaded when a VAD is made
            problems.append(f"{p.relative_to(SRC)}: {mod} ({'module level' if at_top else 'lazy'})")
    assert not problems, problems


def test_ssl_core_depends_on_neither_robot_nor_simulator():
    bad = [f"{p.relative_to(SRC)} imports {m}" for p in _files("ssl_core") for m, _ in _imports(p)
           if m in ("robot", "ssl_sim")]
    assert not bad, bad


def test_importing_every_robot_module_pulls_in_no_simulator_and_no_sounddevice():
    mods = sorted(".".join(p.relative_to(SRC).with_suffix("").parts).removesuffix(".__init__")
                  for p in _files("robot"))
    code = (f"import importlib, sys\nfor m in {mods!r}: importlib.import_module(m)\n"
            "bad = [m for m in sys.modules if m.split('.')[0] in ('ssl_sim', 'sounddevice', 'mujoco', "
            "'pyroomacoustics', 'gymnasium', 'rerun', 'matplotlib')]\nprint(','.join(bad))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip() == "", f"importing robot loaded: {res.stdout.strip()}"
