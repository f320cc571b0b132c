"""The built-in scenario suites: every scenario builds its env, nominal models fit the chain."""

from __future__ import annotations

import pytest

from tether_gym.envs import EnvConfig
from tether_gym_agents.evaluation.scenarios import (
    DEFAULT_SUITE,
    NOMINAL_KEYS,
    PAPER_SCENARIO,
    SUITES,
)

SCENARIOS = [(suite, sc) for suite, scenarios in SUITES.items() for sc in scenarios]


@pytest.mark.parametrize(("suite", "scenario"), SCENARIOS,
                         ids=[f"{suite}-{sc.name}" for suite, sc in SCENARIOS])
def test_every_scenario_builds_its_env_and_nominal_model(suite, scenario):
    """A misspelt or invalid env argument fails here, not in ``evaluate.py --suite``."""
    cfg = EnvConfig.from_kwargs(**scenario.env_kwargs_with({}))
    if scenario.nominal is not None:
        assert sorted(scenario.nominal) == sorted(NOMINAL_KEYS)
        assert len(scenario.nominal["masses"]) == cfg.n_tethers == len(cfg.masses)
        assert 0.0 <= scenario.nominal["eccentricity"] < 1.0


@pytest.mark.parametrize("suite", SUITES)
def test_scenario_names_are_unique_in_a_suite(suite):
    names = [sc.name for sc in SUITES[suite]]
    assert len(set(names)) == len(names)


def test_the_paper_suite_is_the_paper_scenario_wherever_it_sits():
    assert SUITES["paper"] == (PAPER_SCENARIO,) and PAPER_SCENARIO in DEFAULT_SUITE
    assert PAPER_SCENARIO.env_kwargs == {} and PAPER_SCENARIO.nominal is None
