"""The table of learning algorithms agrees with the libraries it names.

Each row's classes import (when its extra is installed), its keyword sets are those the
classes take, its network sizes are those the policy builds: a row that drifts from
stable-baselines3 or sb3-contrib fails here, not in a user's run.
"""

from __future__ import annotations

import importlib
import inspect
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from gymnasium import spaces

from tether_gym_agents.common.algorithms import ALGORITHMS, ALGOS, algorithm, split_name

ROOT = Path(__file__).resolve().parents[3]
NOT_CONFIG_KEYWORDS = {"self", "env", "policy", "_init_setup_model", "tensorboard_log",
                       "verbose", "seed", "device"}
"""Constructor keywords that train.py sets itself (never from a config)."""
NOT_POLICY_KWARGS = {"self", "observation_space", "action_space", "lr_schedule",
                     "optimizer_class"}
"""Policy constructor arguments no config or agent file holds."""


def _load(ref: str):
    module, name = split_name(ref)
    return getattr(importlib.import_module(module), name)


def _row_classes(row):
    """(trained class, library class, policy class) of a row; skipped without its extra."""
    pytest.importorskip(row.package)
    return (_load(row.model), _load(row.library_model),
            _load(f"{row.policy_module}:{row.policy}"))


@pytest.mark.parametrize("name", ALGOS)
def test_hyperparams_are_the_trained_class_keywords(name):
    row = ALGORITHMS[name]
    model, library, _ = _row_classes(row)
    assert issubclass(model, library)
    keywords = set(inspect.signature(model.__init__).parameters) - NOT_CONFIG_KEYWORDS
    assert set(row.hyperparams) == keywords, (name, set(row.hyperparams) ^ keywords)


@pytest.mark.parametrize("name", ALGOS)
def test_policy_class_and_kwargs_fit_the_library(name):
    row = ALGORITHMS[name]
    _, library, policy = _row_classes(row)
    assert library.policy_aliases["MlpPolicy"] is policy
    accepted = set(inspect.signature(policy.__init__).parameters) - NOT_POLICY_KWARGS
    assert set(row.policy_kwargs) <= accepted, set(row.policy_kwargs) - accepted
    # every setting a saved agent records (policy._get_constructor_parameters) is allowed
    box = spaces.Box(-1.0, 1.0, (3,), np.float32)
    built = policy(box, box, lambda _: 1e-3)
    recorded = set(built._get_constructor_parameters()) - {
        "observation_space", "action_space", "lr_schedule", "optimizer_class"}
    assert recorded <= set(row.policy_kwargs), recorded - set(row.policy_kwargs)
    for key, default in row.defaults.items():
        assert inspect.signature(policy.__init__).parameters[key].default == default
        low, high = row.bounds[key]
        assert 1 <= low <= default <= high
    assert set(row.bounds) <= set(row.policy_kwargs)


@pytest.mark.parametrize("name", ALGOS)
def test_on_policy_and_the_saved_module(name):
    from stable_baselines3.common.on_policy_algorithm import OnPolicyAlgorithm

    row = ALGORITHMS[name]
    _, library, policy = _row_classes(row)
    assert issubclass(library, OnPolicyAlgorithm) == row.on_policy
    assert row.action_noise == (not row.on_policy)
    assert row.weights in ("policy", "actor")
    box = spaces.Box(-1.0, 1.0, (3,), np.float32)
    built = policy(box, box, lambda _: 1e-3,
                   net_arch={row.net_keys[0]: [8], row.net_keys[1]: [6]})
    module = built if row.weights == "policy" else getattr(built, row.weights)
    has_log_std = any("log_std" in key for key in module.state_dict())
    assert has_log_std == row.stochastic_actor


def _mlp(n_in: int, widths: list[int], n_out: int) -> int:
    sizes = [n_in, *widths, n_out]
    return sum((a + 1) * b for a, b in zip(sizes[:-1], sizes[1:], strict=True))


@pytest.mark.parametrize("name", ALGOS)
def test_network_sizes_are_those_the_policy_builds(name):
    """actor_outputs, critic, copies and defaults give the parameter count of the policy."""
    row = ALGORITHMS[name]
    _, _, policy = _row_classes(row)
    n_obs, n_act, pi, other = 5, 2, [7, 3], [4]
    built = policy(spaces.Box(-1.0, 1.0, (n_obs,), np.float32),
                   spaces.Box(-1.0, 1.0, (n_act,), np.float32), lambda _: 1e-3,
                   net_arch={row.net_keys[0]: pi, row.net_keys[1]: other})
    actual = sum(p.numel() for p in built.parameters())  # target copies included
    actor = row.copies[0] * _mlp(n_obs, pi, row.actor_outputs * n_act)
    if row.critic == "value":
        critics = row.copies[1] * _mlp(n_obs, other, 1)
    else:
        outputs = row.defaults.get("n_quantiles", 1)
        critics = row.copies[1] * row.defaults["n_critics"] * _mlp(n_obs + n_act, other,
                                                                  outputs)
    log_std = n_act if row.stochastic_actor and row.on_policy else 0
    assert actual == actor + critics + log_std


def test_every_extra_lists_its_requirement():
    tomllib = pytest.importorskip("tomllib")  # Python >= 3.11
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"][
        "optional-dependencies"]
    for row in ALGORITHMS.values():
        assert row.requirement in extras[row.extra], (row.name, row.extra)
        assert f'".[{row.extra}]"' in row.install() and row.requirement in row.install()


def test_names():
    assert ALGOS == tuple(sorted(ALGORITHMS)) and set(ALGOS) >= {"ppo", "sac", "tqc", "td3"}
    assert all(row.name == name for name, row in ALGORITHMS.items())
    assert algorithm("TD3") is ALGORITHMS["td3"]
    with pytest.raises(TypeError, match=r"\['ppo'\] must be a string"):
        algorithm(["ppo"])
    with pytest.raises(ValueError,
                       match=r"'dqn' is not one of \['ppo', 'ppo_lag', 'sac', 'td3', 'tqc'\]"):
        algorithm("dqn")


def test_importing_the_table_imports_no_library():
    code = ("import sys, tether_gym_agents.common.algorithms; "
            "print(sorted(m for m in ('torch', 'stable_baselines3', 'sb3_contrib') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"
