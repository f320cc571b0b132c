"""The shipped agents: safe files only, one folder of seed runs per policy, and they act."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym_agents.evaluation.registry import (
    FILTERED_OF,
    HANDOVER_OF,
    default_policies,
    make_policy,
    resolve_policy,
)
from tether_gym_agents.files.run_folder import ITERATION_LOG_FILE, seed_runs
from tether_gym_agents.files.safe_format import AGENT_FILE, load_agent
from tether_gym_agents.files.trained import PRETRAINED_DIR, TrainedAgent, pretrained_agents
from tether_gym_agents.training.settings import ALGOS


def _kind(folder) -> str:
    """The kind a shipped policy's run files record: ``hybrid`` when they name a hybrid."""
    kinds = {"rl" if json.loads((run / AGENT_FILE).read_text()).get("hybrid") is None
             else "hybrid" for run in seed_runs(folder) or [folder]}
    assert len(kinds) == 1, (folder, kinds)
    return kinds.pop()


SHIPPED = {name: _kind(path) for name, path in pretrained_agents().items()}
"""Policies the package ships (each a folder of seed_K runs) and the kind their run files
record: every folder of ``agents/pretrained/``, so a newly shipped agent is checked too."""
FEATURES = {"ppo_symlog": {"name": "symlog_errors", "scale": 0.01},
            "distill_bc": {"name": "symlog_errors", "scale": 0.0001},
            "distill_ppo": {"name": "symlog_errors", "scale": 0.0001}}
"""The input features of the shipped policies that have any."""
RUN_FILES = ("command.txt", "train_info.json", AGENT_FILE, "policy.safetensors",
             "eval/evaluations.npz")


def test_the_shipped_policies_are_there_without_pickles():
    assert {"ppo", "ppo_g025", "ppo_symlog", "smc_residual"} <= set(SHIPPED)
    assert set(HANDOVER_OF) <= set(SHIPPED) and set(FILTERED_OF) <= set(SHIPPED)
    assert {"handover:ppo", "filtered:distill_ppo"} <= set(default_policies())
    assert set(SHIPPED) <= set(default_policies())  # python evaluate.py runs each of them
    folders = {p.name for p in PRETRAINED_DIR.iterdir() if p.is_dir()}
    assert folders == set(SHIPPED)  # no folder that is not an agent
    pickles = sorted(p.name for p in PRETRAINED_DIR.rglob("*") if p.suffix in (".zip", ".pkl"))
    assert pickles == []


@pytest.mark.parametrize("name", SHIPPED)
def test_every_run_is_complete_and_acts_on_the_current_env(name):
    spec = resolve_policy(name)
    assert spec.kind.value == SHIPPED[name]
    assert spec.n_runs >= 5 and all(p.name.startswith("seed_") for p in spec.runs)
    for run in spec.runs:
        info = json.loads((run / "train_info.json").read_text())
        # a behaviour-cloned seed (train.py distill) has no evaluations during training; a
        # train.py gpu seed logs its training episodes per checkpoint instead (issue 34)
        files = {"dagger": RUN_FILES[:-1], "ppo_gpu": (*RUN_FILES[:-1], ITERATION_LOG_FILE)
                 }.get(info.get("algo"), RUN_FILES)
        for file in files:
            assert (run / file).is_file(), (run, file)
        _, meta = load_agent(run)
        # runs trained before v2 record v1: v2 returns exactly what v1 did, plus the
        # cost entries of info (tests/envs/test_env_versions.py), and they run on v2 below
        assert meta["algo"] in ALGOS
        assert meta["env"]["id"] in (tether_gym.ENV_ID, tether_gym.ENV_ID_V1)
        assert (meta.get("hybrid") is not None) == (SHIPPED[name] == "hybrid")
        assert meta["features"] == FEATURES.get(name)
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


@pytest.mark.parametrize("bad", [np.nan, np.inf, 1e300])  # 1e300: inf in float32
def test_agent_refuses_a_non_finite_observation(bad):
    """Before: a NaN observation acted [nan, nan] (and 1e300 warned of an overflow)."""
    agent = TrainedAgent.load(resolve_policy("ppo").runs[0])
    obs = np.zeros(agent.observation_space.shape)
    obs[3] = bad
    with pytest.raises(ValueError, match="observation holds NaN or inf"):
        agent.predict(obs)
    with pytest.raises(ValueError, match="observation holds NaN or inf"):
        agent.predict(np.stack([np.zeros_like(obs), obs]))  # one bad row of a batch
