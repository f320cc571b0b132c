"""``filtered:AGENT``: a trained agent that commands reel rates, behind the safety filter.

The filtered policy's action on an observation is exactly the safety filter's output for
the agent's own action (the filter of ``smc_filtered``, on the scenario's nominal model);
``evaluate.py`` scores it in the rate mode; an agent trained in another action mode, a
registered policy and a residual are refused with a message naming them.
"""

from __future__ import annotations

import contextlib
import io
import json

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym.safety import SafetyFilter
from tether_gym_agents.cli.evaluate import main as evaluate_main
from tether_gym_agents.common.obs import ObservationLayout
from tether_gym_agents.evaluation import registry
from tether_gym_agents.evaluation.scenarios import Scenario
from tether_gym_agents.files import TrainedAgent
from tether_gym_agents.files.safe_format import save_agent

torch = pytest.importorskip("torch")


def _agent(folder, action_mode="rate"):
    """A random rate-mode MLP agent written as safe agent files."""
    from stable_baselines3.common.policies import ActorCriticPolicy

    env = gym.make(tether_gym.ENV_ID, action_mode=action_mode)
    torch.manual_seed(0)
    policy = ActorCriticPolicy(env.observation_space, env.action_space, lambda _: 0.0,
                               net_arch={"pi": [16], "vf": []})
    with torch.no_grad():  # reel out at full rate: the filter must stop the slack
        policy.action_net.weight.zero_()
        policy.action_net.bias.fill_(1.0)
    save_agent(folder, policy, "ppo", env_id=tether_gym.ENV_ID,
               env_kwargs={"action_mode": action_mode})
    return folder


def test_the_filtered_action_is_the_filters_output_for_the_agents_action(tmp_path):
    run = _agent(tmp_path / "rate")
    spec = registry.resolve_policy(f"filtered:{run}")
    assert spec.kind is registry.PolicyKind.HYBRID and spec.runs == [run]
    assert spec.env_kwargs["action_mode"] == "rate"
    env = gym.make(tether_gym.ENV_ID, **spec.env_kwargs)
    policy = spec.policies(0, env, Scenario("env", ""), [0])[0]
    agent = TrainedAgent.load(run)
    reference = SafetyFilter.for_env(env)
    layout = ObservationLayout.from_env(env)
    obs, _ = env.reset(seed=3)
    changed = 0
    for _ in range(env.unwrapped.config.max_episode_steps):
        action = policy.predict(obs)[0]
        raw = np.asarray(agent.predict(obs)[0], np.float64)
        nu, y = layout.state(obs[None])
        expected = reference.project(nu, y, raw[None]).command[0]
        np.testing.assert_allclose(action, expected, rtol=0, atol=1e-6)
        changed += not np.allclose(action, raw, atol=1e-9)
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated or changed >= 3:
            break
    assert changed > 0  # the filter acted on some of the agent's commands


def test_evaluate_scores_a_filtered_agent(tmp_path):
    run = _agent(tmp_path / "rate")
    name = f"filtered:{run}"
    with contextlib.redirect_stdout(io.StringIO()):
        code = evaluate_main([name, "--seeds", "1", "--no-plots", "--suite", "paper",
                              "--env-kwargs", "orbits_per_episode=0.2",
                              "--out", str(tmp_path / "eval")])
    assert code == 0
    row = json.loads((tmp_path / "eval" / "results.json").read_text())["policies"][name]
    assert row["kind"] == "hybrid" and row["env_kwargs"]["action_mode"] == "rate"


@pytest.mark.parametrize("inner, named", [
    ("smc", "a filtered agent needs a trained agent that acts alone, 'smc' is a registered"),
    ("nothing_here", "unknown policy 'nothing_here'"),
])
def test_what_cannot_be_filtered_is_refused(inner, named):
    with pytest.raises(ValueError, match=named):
        registry.resolve_policy(f"filtered:{inner}")


def test_an_increment_mode_agent_is_refused(tmp_path):
    run = _agent(tmp_path / "increment", action_mode="increment")
    spec = registry.resolve_policy(f"filtered:{run}")
    with pytest.raises(ValueError, match="trained with action_mode='increment'; only an "
                       "agent trained with action_mode='rate' can run filtered"):
        _ = spec.env_kwargs
