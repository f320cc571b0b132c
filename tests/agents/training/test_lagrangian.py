"""PPO-Lagrangian (tether_gym_agents.training.lagrangian): its cost GAE, multiplier and files.

The cost advantages are checked against GAE computed here by hand from the recorded
costs, cost values and episode starts; the multiplier against its update rule; the
run through ``train.py --algo ppo_lag`` (tiny budget) for its saved and resumed state.
"""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest
import torch
import yaml

import tether_gym
from tether_gym_agents.cli.train import main
from tether_gym_agents.files import run_folder as rf
from tether_gym_agents.training.lagrangian import PPOLagrangian
from tether_gym_agents.training.vec_env import make_sb3_vec_env

FAST = ["--algo", "ppo_lag", "--n-envs", "4", "--no-progress", "--eval-episodes", "1",
        "--eval-freq", "256", "--checkpoint-freq", "256"]


def _config(tmp_path, **extra):
    config = tmp_path / "ppo_lag.yml"
    config.write_text(yaml.safe_dump({tether_gym.ENV_ID: {
        "n_envs": 4, "n_steps": 32, "batch_size": 64, "n_epochs": 2,
        "policy_kwargs": {"net_arch": [16, 16]}, **extra}}))
    return config


def _model(cost_limit=0.01, lagrange_lr=0.05, **env_kwargs):
    venv = make_sb3_vec_env(4, seed=0, env_kwargs={"action_mode": "rate", **env_kwargs})
    return PPOLagrangian("MlpPolicy", venv, n_steps=32, batch_size=64, n_epochs=1, seed=0,
                         cost_limit=cost_limit, lagrange_lr=lagrange_lr, device="cpu",
                         policy_kwargs={"net_arch": [16, 16]})


def _hand_gae(costs, values, starts, last_values, last_dones, gamma, lam):
    adv = np.zeros_like(costs)
    gae = np.zeros(costs.shape[1])
    for t in reversed(range(costs.shape[0])):
        if t == costs.shape[0] - 1:
            nonterminal, nxt = 1.0 - last_dones, last_values
        else:
            nonterminal, nxt = 1.0 - starts[t + 1], values[t + 1]
        delta = costs[t] + gamma * nxt * nonterminal - values[t]
        gae = delta + gamma * lam * nonterminal * gae
        adv[t] = gae
    return adv


def test_cost_advantages_are_gae_of_the_envs_costs():
    """A bang-bang policy from a large libration pays costs; its advantages are GAE of them."""
    model = _model(initial_theta=(0.9, -0.9), init_theta_range=0.2)
    seen = {}
    original = model._finish_costs

    def spy(locals_):
        seen["last"] = model._cost_value(locals_["new_obs"])  # before the critic's update
        seen["dones"] = np.array(locals_["dones"], dtype=float)
        original(locals_)

    model._finish_costs = spy
    model.learn(32 * 4)
    costs = model._costs.astype(float)
    assert model._env_costs.sum() > 0  # the test means something only with costs
    assert set(np.unique(model._env_costs)) <= {0.0, 1.0, 2.0, 3.0}
    last = seen["last"]
    hand = _hand_gae(costs, model._cost_values.astype(float),
                     model.rollout_buffer.episode_starts, last, seen["dones"],
                     model.gamma, model.gae_lambda)
    np.testing.assert_allclose(model._cost_advantages, hand, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(model._cost_returns, hand + model._cost_values, rtol=1e-5,
                               atol=1e-5)


@pytest.mark.parametrize("limit", [0.0, 3.0])
def test_the_multiplier_follows_the_relative_violation(limit):
    """lambda <- max(0, lambda + lr (J_c - d) / d): up above the limit, down to 0 below it."""
    model = _model(cost_limit=limit if limit else 1e-3, lagrange_lr=0.5,
                   initial_theta=(0.9, -0.9), init_theta_range=0.2)
    model.lagrange_multiplier.fill_(1.0)
    model.learn(32 * 4)
    rate = float(model._env_costs.mean())
    d = model.cost_limit
    expected = max(0.0, 1.0 + 0.5 * (rate - d) / d)
    assert float(model.lagrange_multiplier) == pytest.approx(expected, rel=1e-6)
    if limit == 3.0:
        assert float(model.lagrange_multiplier) < 1.0
    else:
        assert rate > d and float(model.lagrange_multiplier) > 1.0


def test_train_py_saves_and_resumes_the_multiplier_and_cost_critic(tmp_path):
    out = tmp_path / "run"
    config = _config(tmp_path, cost_limit=0.0005, lagrange_lr=0.5)
    assert main([*FAST, "--config", str(config), "--out", str(out), "--timesteps", "512",
                 "--env-kwargs", "initial_theta=[0.6,-0.6]"]) == 0
    with zipfile.ZipFile(out / rf.FINAL_MODEL_FILE) as zf:
        names = set(zf.namelist())
        variables = torch.load(io.BytesIO(zf.read("pytorch_variables.pth")), weights_only=True)
    assert {"cost_critic.pth", "cost_optimizer.pth"} <= names
    saved = float(variables["lagrange_multiplier"])
    resumed = []
    original = PPOLagrangian.train

    def record(self):
        resumed.append(float(self.lagrange_multiplier))
        original(self)

    PPOLagrangian.train = record
    try:
        assert main([*FAST, "--config", str(config), "--out", str(out), "--timesteps", "128",
                     "--env-kwargs", "initial_theta=[0.6,-0.6]", "--resume"]) == 0
    finally:
        PPOLagrangian.train = original
    assert resumed and resumed[0] == pytest.approx(saved)
    assert (out / rf.FINAL_AGENT_DIR / "agent.json").is_file()


def test_ppo_lag_on_an_env_without_cost_is_refused_before_training(tmp_path, capsys):
    out = tmp_path / "run"
    code = main([*FAST, "--config", str(_config(tmp_path)), "--out", str(out),
                 "--timesteps", "256", "--env-id", tether_gym.ENV_ID_V1])
    assert code == 2
    err = capsys.readouterr().err
    assert "ppo_lag" in err and "cost" in err
    assert not (out / rf.FINAL_MODEL_FILE).exists()


def test_failure_cost_is_added_to_the_critics_cost_of_a_failing_step_only():
    """failure_cost lands on the steps that terminate (not truncate), never in J_c."""
    model = _model(initial_theta=(0.9, -0.9), init_theta_range=0.2)
    model.failure_cost = 7.0
    model.learn(32 * 4)
    extra = model._costs - model._env_costs
    assert set(np.round(np.unique(extra), 6)) == {0.0, 7.0}  # episodes failed in the rollout
    rate, d = float(model._env_costs.mean()), model.cost_limit  # J_c without the extra
    assert float(model.lagrange_multiplier) == pytest.approx(max(0.0, 0.05 * (rate - d) / d),
                                                             rel=1e-6)
