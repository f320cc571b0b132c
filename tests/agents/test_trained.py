"""The shipped agents load and act on the default env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym_agents.evaluation import make_policy
from tether_gym_agents.trained import TrainedAgent, pretrained_agents


@pytest.mark.parametrize("algo", ["ppo", "sac"])
def test_shipped_agent_loads_and_acts(algo):
    shipped = pretrained_agents()
    assert algo in shipped, f"no shipped {algo} agent in {sorted(shipped)}"
    for name in ("config.yml", "command.txt", "train_info.json", "agent.json", "policy.safetensors",
                 "learning_curve.png", "eval/evaluations.npz"):
        assert (shipped[algo] / name).is_file(), name
    agent = TrainedAgent.load(shipped[algo])
    env = gym.make(tether_gym.ENV_ID)
    obs, _ = env.reset(seed=0)
    steps = 0
    for _ in range(200):
        action, _ = agent.predict(obs)
        assert action.shape == env.action_space.shape and np.all(np.abs(action) <= 1.0)
        obs, reward, terminated, truncated, info = env.step(action)
        steps += 1
        assert np.isfinite(reward)
        if terminated or truncated:
            break
    assert steps == 200 and info["failure"] is None  # it keeps the chain healthy
    assert make_policy(algo, env).name == agent.name  # evaluate.py finds it by name


def test_agent_rejects_foreign_observation():
    agent = TrainedAgent.load(pretrained_agents()["ppo"])
    with pytest.raises(ValueError, match="does not fit this agent"):
        agent.predict(np.zeros(5, dtype=np.float32))
