"""Every config value out of range is refused at validation with its section and field named, from
``ssl-robot --set`` and from a scenario file alike; tables whose size the values set are refused with their
memory estimate before anything is built."""
from __future__ import annotations

import dataclasses
import re
import types
import typing
from argparse import Namespace

import pytest

from robot.cli import _SECTIONS as _SECTION_NAMES, _rescue_config, section_config
from robot.rescue import RescueConfig
from robot.sound_map import SoundMapConfig, triangulate
from ssl_sim.scenario import ScenarioError, load_scenario

BASE = """
name = "bounds"
description = "config bounds"
[scene]
name = "empty_lab"
[robot]
start = [3.0, 3.0, 0.0]
[[victims]]
position = [4.6, 3.9, 0.1]
sound = "continuous"
"""
_SECTIONS = {sec: section_config(sec) for sec in _SECTION_NAMES}
#: scenario sections that are robot configs (the rest of _SECTIONS are ssl-robot only)
SCENARIO_SECTIONS = ("motion", "sound_map", "planner", "occupancy", "coverage")


def _numeric_fields(cls) -> list[tuple[str, type]]:
    out = []
    for f, hint in typing.get_type_hints(cls).items():
        if f not in {x.name for x in dataclasses.fields(cls) if x.init}:
            continue
        if typing.get_origin(hint) in (typing.Union, types.UnionType):
            inner = [a for a in typing.get_args(hint) if a is not type(None)]
            hint = inner[0] if len(inner) == 1 else None
        if hint in (int, float):
            out.append((f, hint))
    return out


CASES = [(sec, f, v) for sec, cls in sorted(_SECTIONS.items()) for f, typ in _numeric_fields(cls)
         for v in ((-1, 0, 10**12) if typ is int else (-1.0, 0.0, 1e12))]
FIELDS = {sec: {x.name for x in dataclasses.fields(cls)} for sec, cls in _SECTIONS.items()}


def _named(message: str, prefix: str, sec: str) -> None:
    """``message`` starts with ``prefix`` + ``sec.FIELD`` of a real field of that section."""
    m = re.match(re.escape(prefix) + re.escape(sec) + r"\.(\w+)", message)
    assert m and m.group(1) in FIELDS[sec], message


@pytest.mark.parametrize("sec,field,value", CASES, ids=[f"{s}.{f}={v:g}" for s, f, v in CASES])
def test_cli_range_errors_name_the_section_and_field(sec, field, value):
    args = Namespace(set=[f"{sec}.{field}={value}"], max_victims=None)
    try:
        _rescue_config(args)
    except ValueError as exc:
        _named(str(exc), "--set ", sec)


@pytest.mark.parametrize("sec,field,value", [c for c in CASES if c[0] in SCENARIO_SECTIONS],
                         ids=[f"{s}.{f}={v:g}" for s, f, v in CASES if s in SCENARIO_SECTIONS])
def test_scenario_range_errors_name_the_section_and_field(tmp_path, sec, field, value):
    p = tmp_path / "s.toml"
    p.write_text(BASE + f"[{sec}]\n{field} = {value!r}\n".replace("e+12", "e12"))
    try:
        load_scenario(p)
    except ScenarioError as exc:
        _named(str(exc), "s.toml: ", sec)


def test_sound_map_seed_is_bounded_from_the_cli_and_a_scenario(tmp_path, capsys):
    from robot.cli import main

    with pytest.raises(ValueError, match=r"^--set sound_map\.seed=-1: expected an integer >= 0"):
        _rescue_config(Namespace(set=["sound_map.seed=-1"], max_victims=None))
    p = tmp_path / "s.toml"
    p.write_text(BASE + "[sound_map]\nseed = -1\n")
    with pytest.raises(ScenarioError, match=r"^s\.toml: sound_map\.seed=-1: expected an integer >= 0"):
        load_scenario(p)
    assert main(["--dry-run", "--replay", str(tmp_path / "none.wav"), "--set", "sound_map.seed=-1"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ssl-robot: error: --set sound_map.seed=-1") and "Traceback" not in err


def test_plain_behaviour_fields_are_named_as_given():
    with pytest.raises(ValueError, match=r"^--set listen_s: expected > 0"):
        _rescue_config(Namespace(set=["listen_s=0"], max_victims=None))


def test_ransac_table_refused_with_its_memory_estimate_which_bounds_the_measured_peak():
    """The estimate is checked against tracemalloc's peak of a real refit at a size that fits (40 MB), and a
    size that does not is refused at validation naming the field and the estimate."""
    import tracemalloc

    import numpy as np

    cfg = SoundMapConfig(ransac_hypotheses=20000, max_rays=120)
    rng = np.random.default_rng(0)
    o = np.column_stack([rng.uniform(-3, 3, (120, 2)), np.full(120, 0.3)])
    d = np.array([1.0, 2.0, 0.2]) - o + 0.05 * rng.standard_normal((120, 3))
    tracemalloc.start()
    triangulate(o, d, cfg)
    peak_mb = tracemalloc.get_traced_memory()[1] / 1e6
    tracemalloc.stop()
    assert 0.7 * cfg.ransac_table_mb <= peak_mb <= 1.3 * cfg.ransac_table_mb, (peak_mb, cfg.ransac_table_mb)
    with pytest.raises(ValueError, match=r"SoundMapConfig\.max_rays=100000: expected a RANSAC table within "
                                         r"max_table_mb=512 MB: .* needs about [\d.]+ GB"):
        SoundMapConfig(max_rays=100_000)
    assert RescueConfig()   # the defaults pass


def test_scenario_localizer_grid_refused_at_load_with_its_memory_estimate(tmp_path):
    from ssl_core.geometry import cube8
    from ssl_core.localizer import Localizer, LocalizerConfig

    p = tmp_path / "s.toml"
    p.write_text(BASE + "[localizer]\nresolution_deg = 0.05\n")
    with pytest.raises(ScenarioError, match=r"^s\.toml: localizer\.resolution_deg=0\.05: .* steering tables need "
                                            r"about \d+ MB, more than max_table_mb=1024"):
        load_scenario(p)
    # the same limit the localizer itself applies when built
    with pytest.raises(ValueError, match="steering tables need about"):
        Localizer(cube8(), LocalizerConfig(resolution_deg=0.05))


def test_a_room_whose_truth_grid_exceeds_memory_is_refused_with_the_estimate(tmp_path):
    """A 300 x 300 m room: the run's 5 cm free-space grid would be 36 M cells, about 21.6 GB at the measured
    <= 600 B per cell; refused when the scenario is loaded, before any grid is built."""
    (tmp_path / "hall.toml").write_text('name = "hall"\nrobot_start = [1.0, 1.0, 0.0]\n[room]\n'
                                        'size = [300.0, 300.0, 3.0]\n')
    p = tmp_path / "s.toml"
    p.write_text(BASE.replace('name = "empty_lab"', 'file = "hall.toml"'))
    with pytest.raises(ScenarioError, match=r"^s\.toml: scene room\.size: 300 x 300 m: .* 36000000 cells and needs "
                                            r"about 21600 MB, more than 2048 MB"):
        load_scenario(p).world()


@pytest.mark.parametrize("case", ["seed", "building", "sweep"])
def test_a_refused_run_leaves_no_folder(case, tmp_path, capsys, monkeypatch):
    """Refused before simulating (a bad --seed), while the run is built (after --out was made and proven
    writable) or a sweep naming an unknown scenario: exit code 2, the reason on stderr, no output folder left."""
    import ssl_sim.runner as runner
    from ssl_sim.cli import main

    made = []

    def refused(*a, **k):
        made.append(out.is_dir())
        raise ScenarioError("robot.start: overlaps obstacle 3")

    monkeypatch.setattr(runner, "RescueRun", refused)
    out = tmp_path / "runs" / "x"
    argv = {"seed": ["run", "paper_lab", "--seed", "-1", "--out", str(out)],
            "building": ["run", "paper_lab", "--out", str(out), "-q"],
            "sweep": ["sweep", "no_such_scenario", "--seeds", "0:1", "--out", str(out), "-q"]}[case]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert {"seed": "--seed: expected an integer >= 0", "building": "overlaps obstacle",
            "sweep": "no_such_scenario"}[case] in err
    assert made == ([True] if case == "building" else [])   # the folder existed while the run was built
    assert not (tmp_path / "runs").exists()
