"""Generated scenario suites (ssl_sim.suite): deterministic, loadable like shipped files, solvable, and the real
recordings of the train and test splits never mix.

Truth is independent of the generator: the sound set's own files and bytes, the suite's stated ranges, and a
free-floor grid built here from the box geometry (distance to each footprint, robot radius) whose connected
component of the start is searched for floor within the find radius of every victim.
"""
from __future__ import annotations

import concurrent.futures as cf
import hashlib
import math
from dataclasses import replace

import numpy as np
import pytest
from scipy import ndimage

from ssl_sim import suite
from ssl_sim.acoustics.sound_set import SOUND_SPLITS, categories, sound_files
from ssl_sim.physics.robot_model import RobotModelConfig
from ssl_sim.physics.scenes import load_scene
from ssl_sim.scenario import SceneSpec, load_scenario
from ssl_sim.sweep import run_sweep
from ssl_sim.world import Box, Room, VictimSite, World

N_TRAIN = 200 - suite.TEST_SIZE    # with the whole test split: 200 scenarios
FIND_BASE_M = 1.5


def _as_generated(loaded):
    """A loaded scenario in the generator's form: scene held in memory, no file path."""
    return replace(loaded, path="", scene=SceneSpec(world=load_scene(loaded.scene.file)))


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """The whole test split and the first train scenarios, generated, written and loaded back from the files."""
    out = tmp_path_factory.mktemp("suite")
    gen = {("test", i): suite.generate("test", i) for i in suite.test_indices()}
    gen.update({("train", i): suite.generate("train", i) for i in range(N_TRAIN)})
    paths = {k: suite._write(sc, out / k[0]) for k, sc in gen.items()}
    loaded = {k: load_scenario(p) for k, p in paths.items()}
    return gen, loaded, paths


@pytest.fixture(scope="module")
def worlds(written):
    """The run World of every loaded scenario (its scene read from the written file)."""
    return {k: sc.world() for k, sc in written[1].items()}


# ----------------------------------------------------------------------------- determinism, round trip
def test_same_seed_gives_the_same_scenario_and_the_toml_round_trip_is_identical(written, tmp_path):
    gen, loaded, paths = written
    for split in suite.SPLITS:
        for i in range(len(suite.FAMILIES)):          # one of every family
            again = suite.generate(split, i)
            assert again == gen[split, i]
            assert suite.to_toml(again) == suite.to_toml(gen[split, i]) == paths[split, i].read_text()
            assert _as_generated(loaded[split, i]) == gen[split, i]
            # the written file, loaded and written again, is the same text
            assert suite.to_toml(loaded[split, i]) == paths[split, i].read_text()
    p = suite.write_scenario("test", 5, tmp_path)
    assert p.read_text() == paths["test", 5].read_text()
    assert (tmp_path / "scenes" / p.name).read_text() == (paths["test", 5].parent / "scenes" / p.name).read_text()
    # different indices are different scenarios
    assert gen["test", 0] != gen["test", 4] and gen["train", 0] != gen["test", 0]


def test_splits_use_disjoint_seeds_and_named_families(written):
    gen, _, _ = written
    train_seeds = {sc.seed for (s, _), sc in gen.items() if s == "train"}
    test_seeds = {sc.seed for (s, _), sc in gen.items() if s == "test"}
    assert len(test_seeds) == suite.TEST_SIZE >= 64 and len(train_seeds) == N_TRAIN
    assert max(train_seeds) < suite.TEST_SEED_BASE <= min(test_seeds)
    assert suite.suite_seed("train", suite.TEST_SEED_BASE - 1) < min(test_seeds)
    for (split, i), sc in gen.items():
        assert sc.name.startswith(f"{split}_{i:03d}_") and suite.family_of(sc.name) == suite.FAMILIES[i % 4]
    with pytest.raises(ValueError, match="index"):
        suite.generate("train", suite.TEST_SEED_BASE)
    with pytest.raises(ValueError, match="index"):
        suite.generate("test", suite.TEST_SIZE)
    with pytest.raises(ValueError, match="split"):
        suite.generate("dev", 0)
    with pytest.raises(ValueError, match="count"):
        suite.write_scenarios("test", "unused", count=suite.TEST_SIZE + 1)


# ----------------------------------------------------------------------------- sound parts
def _sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_dev_and_test_recordings_never_mix(written):
    dev, test = sound_files("dev"), sound_files("test")
    assert SOUND_SPLITS == ("dev", "test") and dev and test
    assert set(categories()) >= {"speech", "shouts", "machinery", "engine", "alarm", "music"}
    # no file, no recording (bytes) and no original source file in both parts
    assert not {f.path for f in dev} & {f.path for f in test}
    assert not {_sha(f.path) for f in dev} & {_sha(f.path) for f in test}
    assert not {s for f in dev for s in f.sources} & {s for f in test for s in f.sources}
    assert all(f.path.parent.parent.name == f.split and f.path.parent.name == f.category for f in dev + test)

    gen, loaded, _ = written
    allowed = {"train": {str(f.path) for f in dev}, "test": {str(f.path) for f in test}}
    used = {"train": set(), "test": set()}
    for (split, _), sc in loaded.items():
        files = [v.file for v in sc.victims if v.sound == "file"] + [s.file for s in sc.interferers if s.kind == "file"]
        assert set(files) <= allowed[split], sc.name
        used[split] |= set(files)
    for split in suite.SPLITS:
        cats = {p.split("/")[-2] for p in used[split]}
        # the suites really use real voices and real machines (else the check above would be empty)
        assert {"speech", "shouts"} <= cats and len(cats & {"machinery", "engine", "alarm", "music"}) >= 3, split


# ----------------------------------------------------------------------------- solvable
ROBOT = RobotModelConfig()
RADIUS = ROBOT.bumper_radius
TOP = ROBOT.array_height + ROBOT.cube_edge / 2


def _reachable_within(world: World, reach: float, res: float = 0.05) -> list[bool]:
    """Independent check: cells where the robot centre keeps its bumper radius from every footprint of an
    obstacle it cannot pass (not climbable, bottom below the robot's top) and from the room walls; the
    4-connected component of the start; per victim, does it hold a cell within ``reach`` (horizontal)?"""
    lx, ly = world.room.size[:2]
    x = np.arange(res / 2, lx, res)
    y = np.arange(res / 2, ly, res)
    X, Y = np.meshgrid(x, y, indexing="ij")
    free = (X > RADIUS) & (X < lx - RADIUS) & (Y > RADIUS) & (Y < ly - RADIUS)
    for b in world.obstacles:
        if b.climbable or b.center[2] - b.size[2] / 2 >= TOP:
            continue
        c, s = math.cos(b.yaw), math.sin(b.yaw)
        dx, dy = X - b.center[0], Y - b.center[1]
        u = np.abs(c * dx + s * dy) - b.size[0] / 2
        v = np.abs(-s * dx + c * dy) - b.size[1] / 2
        free &= np.hypot(np.maximum(u, 0), np.maximum(v, 0)) > RADIUS + 1e-9
    labels, _ = ndimage.label(free)      # 4-connected: no corner cutting
    i, j = int(world.robot_start[0] // res), int(world.robot_start[1] // res)
    assert free[i, j], f"{world.name}: start {world.robot_start} not on free floor"
    mine = labels == labels[i, j]
    return [bool(np.any(mine & (np.hypot(X - p.position[0], Y - p.position[1]) <= reach))) for p in world.victims]


def test_the_independent_reachability_check_sees_a_walled_off_victim():
    wall = Box((3.0, 2.0, 1.5), (0.2, 4.0, 3.0), kind="wall")
    world = World(Room((6.0, 4.0, 3.0)), (wall,), (VictimSite((5.0, 2.0, 0.2)), VictimSite((1.8, 3.0, 0.2))),
                  robot_start=(1.0, 1.0, 0.0))
    assert _reachable_within(world, FIND_BASE_M) == [False, True]   # 1.8 m behind the wall vs in the open
    door = replace(world, obstacles=(Box((3.0, 1.5, 1.5), (0.2, 3.0, 3.0), kind="wall"),))  # 1 m gap at y > 3 m
    assert _reachable_within(door, FIND_BASE_M) == [True, True]


def test_every_generated_victim_has_reachable_floor_within_the_find_radius(written, worlds):
    _, loaded, _ = written
    for k, sc in loaded.items():
        world = worlds[k]
        assert all(_reachable_within(world, FIND_BASE_M)), sc.name
        start = np.asarray(world.robot_start[:2])
        assert all(np.linalg.norm(np.asarray(v.position[:2]) - start) > FIND_BASE_M for v in world.victims), sc.name


# ----------------------------------------------------------------------------- 200 load and validate
def test_200_generated_scenarios_load_validate_and_span_the_stated_ranges(written, worlds):
    gen, loaded, _ = written
    assert len(loaded) == 200
    fam, n_vict, n_int, buried = set(), set(), set(), 0
    for k, sc in loaded.items():
        world = worlds[k]
        lx, ly, _ = world.room.size
        assert 4.0 <= min(lx, ly) and max(lx, ly) <= 10.0 and min(lx, ly) <= 8.0, sc.name
        assert 1 <= len(sc.victims) <= 3 and 0 <= len(sc.interferers) <= 2, sc.name
        assert 30.0 <= sc.noise.level_db_spl <= 50.0 and 0.3 <= sc.acoustics["rt60_s"] <= 1.2, sc.name
        assert 180.0 <= sc.time_limit_s <= 300.0, sc.name
        assert all(v.sound != "continuous" and (v.sound == "file" or v.p_event < 1.0) for v in sc.victims), sc.name
        fam.add(suite.family_of(sc.name))
        n_vict.add(len(sc.victims))
        n_int.add(len(sc.interferers))
        buried += sum((v.buried or 0) >= 0.3 for v in sc.victims)
        if suite.family_of(sc.name) == "partitions":   # full-height walls across the room
            walls = [b for b in world.obstacles if b.kind == "wall" and b.size[2] >= world.room.size[2] - 1e-6]
            assert walls, sc.name
    assert fam == set(suite.FAMILIES) and n_vict == {1, 2, 3} and n_int == {0, 1, 2} and buried >= 20


# ----------------------------------------------------------------------------- end to end
class _Inline(cf.Executor):
    """Runs each task at submit, in this process."""

    def submit(self, fn, *args, **kwargs):
        f = cf.Future()
        f.set_result(fn(*args, **kwargs))
        return f


def test_a_generated_test_scenario_runs_end_to_end(written):
    gen, _, _ = written
    # the first test scenario with a real recorded victim and a real recorded machine
    sc = next(gen["test", i] for i in suite.test_indices()
              if any(v.sound == "file" for v in gen["test", i].victims)
              and any(s.kind == "file" for s in gen["test", i].interferers))
    rows = run_sweep([sc], None, executor=_Inline(), time_limit_s=20.0)   # None: the scenario's own seed
    (r,) = rows
    assert r["seed"] == sc.seed and r["scenario"] == sc.name and r["n_victims"] == len(sc.victims)
    # (the last cycle may start just before the limit: a 0.6 m step at 0.25 m/s, the settle and a listen)
    assert 19.0 <= r["sim_time_s"] <= 24.0 and r["n_listens"] >= 5
    # the robot heard sources: detections land near a sounding source's direction
    errs = np.asarray(r["detection_errors_deg"])
    # (a random direction lies a median 54 deg from the nearest of three random sources, less with more)
    assert errs.size >= 5 and np.median(errs) < 30.0


def test_cli_suite_show_writes_a_rerunnable_file_and_list_prints_the_split(written, tmp_path, capsys):
    from ssl_sim.cli import main

    gen, _, _ = written
    assert main(["suite", "show", "test", "17", "--out", str(tmp_path)]) == 0
    path = tmp_path / f"{gen['test', 17].name}.toml"
    assert _as_generated(load_scenario(path)) == gen["test", 17]
    assert main(["suite", "list", "train", "--count", "2"]) == 0
    out = capsys.readouterr().out
    assert gen["train", 0].name in out and gen["train", 1].name in out and gen["train", 2].name not in out
    assert main(["suite", "show", "test", str(suite.TEST_SIZE), "--out", str(tmp_path)]) == 2
    assert "index" in capsys.readouterr().err
    with pytest.raises(ValueError, match="split"):
        sound_files("train")
    with pytest.raises(ValueError, match="category"):
        sound_files("dev", "sirens")


def test_the_test_split_runs_in_parts_that_join_to_the_whole():
    whole = suite.indices("test")
    assert whole == suite.test_indices() and len(whole) == suite.TEST_SIZE
    assert suite.indices("test", 32) + suite.indices("test", 32, 32) == whole
    assert suite.indices("test", None, 60) == whole[60:]
    for count, first in ((65, 0), (8, 60), (None, 64)):
        with pytest.raises(ValueError, match="test split has 64"):
            suite.indices("test", count, first)
    assert suite.indices("train", 3, 200) == [200, 201, 202]
