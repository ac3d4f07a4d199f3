"""The drive's own noise is part of every simulated world: on by default, its level a scenario field."""
import tomllib

import pytest

from ssl_sim.acoustics.ego_noise import EgoNoiseConfig
from ssl_sim.envs.config import EnvConfig
from ssl_sim.resources import SCENARIOS_DIR
from ssl_sim.scenario import ScenarioError, load_scenario, parse_scenario, scenario_names


def _paper_lab() -> dict:
    return tomllib.loads((SCENARIOS_DIR / "paper_lab.toml").read_text())


def test_every_shipped_scenario_has_the_motors_on():
    for name in scenario_names():
        assert load_scenario(name).ego_noise == EgoNoiseConfig(), name


def test_level_is_a_scenario_field_and_it_can_be_switched_off():
    d = _paper_lab()
    d["ego_noise"] = {"level_db_spl_1m": 46.0}
    assert parse_scenario(d).ego_noise.level_db_spl_1m == 46.0
    d["ego_noise"] = {"enabled": False}
    assert parse_scenario(d).ego_noise is None


@pytest.mark.parametrize("table, field", [({"level_db_spl_1m": 200.0}, "level_db_spl_1m"),
                                          ({"loudness": 3.0}, "loudness"),
                                          ({"enabled": False, "level_db_spl_1m": 40.0}, "ego_noise")])
def test_bad_ego_noise_is_named(table, field):
    d = _paper_lab()
    d["ego_noise"] = table
    with pytest.raises(ScenarioError, match=field):
        parse_scenario(d)


def test_gym_env_drives_with_its_motors_audible_by_default():
    assert EnvConfig().ego_noise_db_spl == EgoNoiseConfig().level_db_spl_1m
    with pytest.raises(ValueError, match="ego_noise_db_spl"):
        EnvConfig(ego_noise_db_spl=500.0)
