"""The built-in scenario suites: every scenario builds its env, nominal models fit the chain."""

from __future__ import annotations

import pytest

from tether_gym.envs import EnvConfig
from tether_gym_agents.evaluation.scenarios import (
    DEFAULT_SUITE,
    NOMINAL_KEYS,
    PAPER_SCENARIO,
    SUITES,
    Scenario,
    default_masses,
    per_tether,
)

SCENARIOS = [(suite, sc) for suite, scenarios in SUITES.items() for sc in scenarios]


@pytest.mark.parametrize(("suite", "scenario"), SCENARIOS,
                         ids=[f"{suite}-{sc.name}" for suite, sc in SCENARIOS])
def test_every_scenario_builds_its_env_and_nominal_model(suite, scenario):
    """A misspelt or invalid env argument fails here, not in ``evaluate.py --suite``."""
    cfg = EnvConfig.from_kwargs(**scenario.env_kwargs_with({}))
    if scenario.nominal is not None:
        assert scenario.nominal and set(scenario.nominal) <= set(NOMINAL_KEYS)
        # the nominal model is a valid env configuration of the same chain
        nominal = EnvConfig.from_kwargs(**{**scenario.env_kwargs_with({}),
                                           **scenario.nominal})
        assert nominal.n_tethers == cfg.n_tethers


def test_the_robust_suite_mismatches_what_it_says():
    """Each robust scenario's nominal model differs from its plant in its nominal keys,
    and the plant differs from the default suite's random_init there."""
    import gymnasium as gym
    import numpy as np

    import tether_gym
    from tether_gym.safety import SafetyFilter

    robust = SUITES["robust"]
    assert len(robust) >= 6 and all(sc.env_kwargs.get("n_bodies", 3) == 3 for sc in robust)
    for sc in robust:
        env = gym.make(tether_gym.ENV_ID, action_mode="rate", **sc.env_kwargs)
        plant = SafetyFilter.for_env(env).par
        model = SafetyFilter.for_env(env, **(sc.nominal or {})).par
        assert (sc.nominal is None) == np.array_equal(plant, model), sc.name
        env.close()
    unknown = {sc.name for sc in robust if sc.nominal is None}
    assert unknown == {"obs_noise_bias", "disturbed_0.3"}  # no model knows these


@pytest.mark.parametrize("suite", SUITES)
def test_scenario_names_are_unique_in_a_suite(suite):
    names = [sc.name for sc in SUITES[suite]]
    assert len(set(names)) == len(names)


def test_the_paper_suite_is_the_paper_scenario_wherever_it_sits():
    assert SUITES["paper"] == (PAPER_SCENARIO,) and PAPER_SCENARIO in DEFAULT_SUITE
    assert PAPER_SCENARIO.env_kwargs == {} and PAPER_SCENARIO.nominal is None


# --------------------------------------------------------------------------- #
# any number of bodies (issue 24)
# --------------------------------------------------------------------------- #
@pytest.mark.parametrize("n_bodies", [2, 4, 6])
@pytest.mark.parametrize(("suite", "scenario"), SCENARIOS,
                         ids=[f"{suite}-{sc.name}" for suite, sc in SCENARIOS])
def test_every_scenario_is_defined_for_any_n(suite, scenario, n_bodies):
    """Env arguments and nominal model fit an N-body chain (mismatch's 2 masses did not)."""
    resolved, kwargs = scenario.resolved({"n_bodies": n_bodies})
    cfg = EnvConfig.from_kwargs(**kwargs)
    assert cfg.n_bodies == n_bodies
    if resolved.nominal is not None and "masses" in resolved.nominal:
        assert len(resolved.nominal["masses"]) == n_bodies - 1 == len(cfg.masses)


@pytest.mark.parametrize(("suite", "scenario"), SCENARIOS,
                         ids=[f"{suite}-{sc.name}" for suite, sc in SCENARIOS])
def test_at_three_bodies_every_scenario_is_exactly_as_written(suite, scenario):
    for overrides in ({}, {"n_bodies": 3}):
        resolved, kwargs = scenario.resolved(overrides)
        assert resolved is scenario
        assert kwargs == {**scenario.env_kwargs, **overrides}
        assert all(type(kwargs[k]) is type(v) and kwargs[k] == v
                   for k, v in scenario.env_kwargs.items())


def test_mismatch_keeps_its_mass_factors_over_the_default_masses_for_n():
    mismatch = next(sc for sc in DEFAULT_SUITE if sc.name == "mismatch")
    resolved, kwargs = mismatch.resolved({"n_bodies": 4})
    assert default_masses(4) == (1.0, 1.0, 1.0) and default_masses(3) == (1.0, 2.0)
    assert kwargs["masses"] == pytest.approx((1.2, 0.8, 1.2))      # +20 %, -20 %, +20 %
    assert resolved.nominal == {"masses": (1.0, 1.0, 1.0), "eccentricity": 0.2}
    assert kwargs["initial_theta"] == (0.0, 0.0, 0.0)
    # what --env-kwargs gives is never resized; the nominal model still follows N
    resolved, kwargs = mismatch.resolved({"n_bodies": 4, "masses": (1, 1, 1)})
    assert kwargs["masses"] == (1, 1, 1) and len(resolved.nominal["masses"]) == 3


def test_a_base_lies_under_the_scenario_and_sets_n():
    """The env the agents were trained on (base) sets N; the scenario's values win over it."""
    amp = next(sc for sc in SUITES["beyond"] if sc.name == "amp_0.1")
    _, kwargs = amp.resolved({}, base={"n_bodies": 4, "amplitude": 0.3})
    assert kwargs["n_bodies"] == 4 and kwargs["amplitude"] == 0.1
    assert kwargs["initial_theta"] == (0.0, 0.0, 0.0)


def test_an_unequal_per_tether_value_without_a_rule_names_key_and_n():
    sc = Scenario("tilted", "", {"initial_theta": (0.1, 0.0)})
    with pytest.raises(ValueError, match=r"'tilted'.*initial_theta.*n_bodies=4"):
        sc.resolved({"n_bodies": 4})
    assert per_tether("initial_theta", (0.1, 0.0, 0.0), 4) == (0.1, 0.0, 0.0)
