"""ObservationLayout and ObservedState against the observation's declaration; the rate-mode
owner (RATE_ENV_KWARGS, with_rate_mode) and the policy check (require_predict)."""

from __future__ import annotations

import typing

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym.envs.layout import OBSERVATION
from tether_gym_agents.common.obs import (
    RATE_ENV_KWARGS,
    ObservationLayout,
    ObservedState,
    ReelRatePolicy,
    require_predict,
    with_rate_mode,
)


def test_observed_state_follows_the_observation_declaration():
    """A field added to OBSERVATION (tether_gym/envs/layout.py) must be added here too,
    in the same order, optional (``| None``) exactly when the declaration says so."""
    assert ObservedState._fields == OBSERVATION.names
    hints = typing.get_type_hints(ObservedState)
    for f in OBSERVATION:
        optional = type(None) in typing.get_args(hints[f.name])
        assert optional == (f.optional is not None), f.name


@pytest.mark.parametrize(("with_params", "with_eccentricity"),
                         [(False, False), (False, True), (True, False), (True, True)])
def test_layout_switches_are_the_optional_groups_of_the_observation(with_params,
                                                                    with_eccentricity):
    """An optional group added to OBSERVATION needs its switch here (and in from_env)."""
    layout = ObservationLayout(n_tethers=2, frequency=1.0, max_reel_rate=0.5,
                               with_params=with_params, with_eccentricity=with_eccentricity)
    assert tuple(layout.switches) == OBSERVATION.groups


@pytest.mark.parametrize("kwargs", [{}, {"observe_params": True},
                                    {"observe_params": "eccentricity", "n_bodies": 4},
                                    {"action_mode": "increment"}])
def test_layout_from_env_is_the_env_configuration(kwargs):
    env = gym.make(tether_gym.ENV_ID, **kwargs)
    cfg = env.unwrapped.config
    layout = ObservationLayout.from_env(env)
    assert layout == ObservationLayout(
        n_tethers=cfg.n_tethers, frequency=cfg.frequency, max_reel_rate=cfg.max_reel_rate,
        with_params=cfg.observed["masses"], with_eccentricity=cfg.observed["eccentricity"],
        action_mode=cfg.action_mode)
    assert layout.obs_dim == env.observation_space.shape[0]
    obs, info = env.reset(seed=2)
    st = layout.split(obs[None])
    for f in OBSERVATION:
        value = getattr(st, f.name)
        assert (value is None) == (f.name not in OBSERVATION.slices(
            cfg.n_tethers, **cfg.observed))
    nu, y = layout.state(obs[None])
    np.testing.assert_allclose(nu[0], info["nu"], atol=1e-6)
    np.testing.assert_allclose(y[0], np.concatenate(
        [info[k] for k in ("theta", "dtheta", "length", "dlength")]), atol=1e-6)
    env.close()


def test_layout_switches_and_mode_are_keyword_only():
    with pytest.raises(TypeError):
        ObservationLayout(2, 1.0, 0.5, True)  # type: ignore[misc]
    layout = ObservationLayout(2, 1.0, 0.5, action_mode="increment")
    with pytest.raises(ValueError, match="X commands reel rates.*action_mode='increment'"):
        layout.require_rate_mode("X")


def test_the_rate_mode_has_one_owner():
    assert ReelRatePolicy.ENV_KWARGS is RATE_ENV_KWARGS == {"action_mode": "rate"}
    given = {"obs_noise": 0.01}
    assert with_rate_mode(given, "X") == {"obs_noise": 0.01, "action_mode": "rate"}
    assert given == {"obs_noise": 0.01}  # a new dict
    assert with_rate_mode({"action_mode": "rate"}, "X") == RATE_ENV_KWARGS
    with pytest.raises(ValueError, match="Y commands reel rates.*action_mode='increment'"):
        with_rate_mode({"action_mode": "increment"}, "Y")


def test_require_predict():
    class Policy:
        def predict(self, observation):
            return observation, None

    policy = Policy()
    assert require_predict("base", policy) is policy
    for bad in (object(), type("P", (), {"predict": 1})()):
        with pytest.raises(TypeError, match="base must have a predict method, got"):
            require_predict("base", bad)
