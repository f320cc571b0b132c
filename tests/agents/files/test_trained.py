"""The shipped agents: safe files only, one folder of seed runs per policy, and they act."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym_agents.evaluation.registry import make_policy, resolve_policy
from tether_gym_agents.files.safe_format import AGENT_FILE, load_agent
from tether_gym_agents.files.trained import PRETRAINED_DIR, TrainedAgent, pretrained_agents

SHIPPED = {"ppo": "rl", "ppo_symlog": "rl", "smc_residual": "hybrid"}
"""Policies the package ships (each a folder of seed_K runs) and their kind."""
FEATURES = {"ppo_symlog": {"name": "symlog_errors", "scale": 0.01}}
"""The input features of the shipped policies that have any."""
RUN_FILES = ("command.txt", "train_info.json", AGENT_FILE, "policy.safetensors",
             "eval/evaluations.npz")


def test_the_shipped_policies_are_there_without_pickles():
    assert set(SHIPPED) <= set(pretrained_agents())
    pickles = sorted(p.name for p in PRETRAINED_DIR.rglob("*") if p.suffix in (".zip", ".pkl"))
    assert pickles == []


@pytest.mark.parametrize("name", SHIPPED)
def test_every_run_is_complete_and_acts_on_the_current_env(name):
    spec = resolve_policy(name)
    assert spec.kind.value == SHIPPED[name]
    assert spec.n_runs >= 5 and all(p.name.startswith("seed_") for p in spec.runs)
    for run in spec.runs:
        for file in RUN_FILES:
            assert (run / file).is_file(), (run, file)
        _, meta = load_agent(run)
        assert meta["algo"] == "ppo" and meta["env"]["id"] == tether_gym.ENV_ID
        assert (meta.get("hybrid") is not None) == (SHIPPED[name] == "hybrid")
        assert meta["features"] == FEATURES.get(name)
        info = json.loads((run / "train_info.json").read_text())
        assert info["num_timesteps"] > 0
    env = gym.make(tether_gym.ENV_ID, **spec.env_kwargs)
    policy = make_policy(name, env)  # what evaluate.py runs: the agent, or the hybrid
    obs, _ = env.reset(seed=0)
    for _ in range(200):
        action, _ = policy.predict(obs)
        assert np.shape(action) == env.action_space.shape and np.all(np.abs(action) <= 1.0)
        obs, reward, terminated, truncated, info = env.step(action)
        assert np.isfinite(reward) and not terminated, info["failure"]


def test_agent_rejects_foreign_observation():
    agent = TrainedAgent.load(resolve_policy("ppo").runs[0])
    with pytest.raises(ValueError, match="does not fit this agent"):
        agent.predict(np.zeros(5, dtype=np.float32))
