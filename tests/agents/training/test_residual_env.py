"""The residual hybrid end to end: ResidualVecEnv's commands, its filter and auto-reset,
the ``residual`` config key, the ``hybrid`` entry of agent files and kind "hybrid" in the
evaluation."""

from __future__ import annotations

import json
import re

import gymnasium as gym
import numpy as np
import pytest

import tether_gym
from tether_gym.safety import SafetyFilter
from tether_gym_agents import SlidingModeController
from tether_gym_agents.cli.train import main
from tether_gym_agents.evaluation.benchmark import PolicyKind, evaluate, resolve_policy
from tether_gym_agents.files.safe_format import AGENT_FILE, AgentLoadError
from tether_gym_agents.files.trained import TrainedAgent, hybrid_of
from tether_gym_agents.training.config import CONFIG_DIR, ConfigError, load_hyperparams
from tether_gym_agents.training.residual_env import BaseLaw, ResidualSpec, ResidualVecEnv
from tether_gym_agents.training.vec_env import make_sb3_vec_env

RATE = {"action_mode": "rate", "orbits_per_episode": 0.05}  # 13 steps per episode
N_ENVS = 3


def _venv(**kwargs):
    return make_sb3_vec_env(N_ENVS, seed=7, env_kwargs={**RATE, **kwargs})


def _smc(**kwargs):
    env = gym.make(tether_gym.ENV_ID, **{**RATE, **kwargs})
    smc = SlidingModeController.for_env(env)
    env.close()
    return smc


class Recording:
    """A base law that records the observations it is asked about."""

    def __init__(self, policy):
        self.policy = policy
        self.seen: list[np.ndarray] = []

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        self.seen.append(np.array(observation, copy=True))
        return self.policy.predict(observation, deterministic=deterministic)


def test_scale_zero_without_filter_is_smc_bit_for_bit():
    """u = clip(u_smc + 0 * a) = u_smc: the same episodes as SMC on a plain vec env,
    across auto-resets, whatever the residual actions."""
    hybrid = ResidualVecEnv(_venv(), _smc(), scale=0.0)
    plain = _venv()
    smc = _smc()
    rng = np.random.default_rng(0)
    obs, ref = hybrid.reset(), plain.reset()
    assert np.array_equal(obs, ref)
    resets = 0
    for _ in range(40):  # three episodes per sub-env
        action, _ = smc.predict(ref)
        ref, r_ref, d_ref, i_ref = plain.step(action)
        obs, r, d, infos = hybrid.step(rng.uniform(-1, 1, (N_ENVS, 2)).astype(np.float32))
        assert np.array_equal(obs, ref) and np.array_equal(r, r_ref) and np.array_equal(d, d_ref)
        for info, info_ref in zip(infos, i_ref, strict=True):
            assert np.array_equal(info["command"], info_ref["command"])
            assert info["filter_active"] is False
        resets += int(d.sum())
    assert resets >= 2 * N_ENVS
    hybrid.close()
    plain.close()


def test_command_is_clipped_base_plus_scaled_residual():
    smc = _smc()
    hybrid = ResidualVecEnv(_venv(), smc, scale=0.5)
    obs = hybrid.reset()
    rng = np.random.default_rng(1)
    clipped = False
    for _ in range(15):
        a = rng.uniform(-1, 1, (N_ENVS, 2)).astype(np.float32)
        base, _ = smc.predict(obs)
        expected = np.clip(base.astype(np.float64) + 0.5 * a.astype(np.float64), -1.0, 1.0)
        np.testing.assert_array_equal(hybrid.commands(a), expected)
        clipped |= bool((np.abs(base + 0.5 * a) > 1.0).any())
        obs, _, _, infos = hybrid.step(a)
        applied = np.array([info["command"] for info in infos])
        np.testing.assert_array_equal(applied, expected.astype(np.float32))
    assert clipped  # the clip was exercised
    hybrid.close()


def test_auto_reset_feeds_the_new_episode_to_the_base_law():
    base = Recording(_smc())
    hybrid = ResidualVecEnv(_venv(), base, scale=0.1)
    obs = hybrid.reset()
    ended = 0
    for _ in range(30):
        obs, _, dones, infos = hybrid.step(np.zeros((N_ENVS, 2), np.float32))
        hybrid.step_async(np.zeros((N_ENVS, 2), np.float32))  # the next base call
        np.testing.assert_array_equal(base.seen[-1], obs)
        for i in np.flatnonzero(dones):
            ended += 1
            terminal = infos[i]["terminal_observation"]
            assert not np.array_equal(base.seen[-1][i], terminal)
            assert np.array_equal(base.seen[-1][i], obs[i])  # reset observation
        obs, _, _, _ = hybrid.step_wait()
    assert ended >= N_ENVS
    hybrid.close()


def test_filter_acts_and_reports_in_infos():
    """A reel-in residual on a short tether: the filter steps in, says so per sub-env and
    keeps the tether within its bounds; its command is what the env applies."""
    kwargs = {"initial_lengths": (0.1, 0.9), "orbits_per_episode": 0.3}
    venv = _venv(**kwargs)
    flt = SafetyFilter.for_env(gym.make(tether_gym.ENV_ID, **{**RATE, **kwargs}))
    hybrid = ResidualVecEnv(venv, _smc(**kwargs), scale=1.0, safety_filter=flt)
    hybrid.reset()
    push = np.tile(np.array([-1.0, 0.0], np.float32), (N_ENVS, 1))
    active = []
    for _ in range(60):
        desired = hybrid.commands(push)
        _, _, dones, infos = hybrid.step(push)
        flags = np.array([info["filter_active"] for info in infos])
        applied = np.array([info["command"] for info in infos])
        assert np.array_equal(flags, np.any(applied != desired.astype(np.float32), axis=1))
        assert all(info["failure"] is None for info in infos)
        assert all(set(("filter_correction", "filter_feasible")) <= set(i) for i in infos)
        active.append(flags)
        assert not dones.any()
    active = np.array(active)
    assert active.any() and not active.all()
    assert hybrid.filter_steps == active.size
    assert hybrid.filter_interventions == int(active.sum())
    hybrid.close()


def test_the_filter_sees_the_observation_as_at_evaluation():
    """Under observation noise the filter predicts from the observed state, as the
    evaluated ResidualPolicy does: the same commands for the same observations and
    residuals, across auto-resets."""
    from tether_gym_agents.hybrids.policies import ResidualPolicy

    kwargs = {"initial_lengths": (0.1, 0.9), "obs_noise": 0.01}
    hybrid = ResidualVecEnv.from_spec(_venv(**kwargs), ResidualSpec(scale=1.0))
    obs = hybrid.reset()
    rng = np.random.default_rng(3)
    ends = 0
    for _ in range(30):  # reel tether 1 in: the filter steps in
        a = np.clip(rng.normal([-1.0, 0.0], 0.3, (N_ENVS, 2)), -1, 1).astype(np.float32)
        policy = ResidualPolicy(hybrid.base, Constant(a), 1.0, hybrid.safety_filter)
        expected, _ = policy.predict(obs)
        obs, _, dones, infos = hybrid.step(a)
        applied = np.array([info["command"] for info in infos])
        np.testing.assert_array_equal(applied, expected)
        ends += int(dones.sum())
    assert ends >= N_ENVS and hybrid.filter_interventions > 0
    hybrid.close()


class Constant:
    """A residual model with fixed actions (one row per sub-env)."""

    def __init__(self, actions):
        self.actions = actions

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        return self.actions, None


def test_validation():
    with pytest.raises(ValueError, match="action_mode='rate'"):
        ResidualVecEnv(make_sb3_vec_env(1, env_kwargs={"orbits_per_episode": 0.05}), _smc(), 0.2)
    venv = _venv()
    with pytest.raises(ValueError, match="scale"):
        ResidualVecEnv(venv, _smc(), -0.1)
    with pytest.raises(TypeError, match="predict"):
        ResidualVecEnv(venv, object(), 0.2)
    four = gym.make(tether_gym.ENV_ID, n_bodies=4, action_mode="rate")
    with pytest.raises(ValueError, match="tethers"):
        ResidualVecEnv(venv, _smc(), 0.2, SafetyFilter.for_env(four))
    from stable_baselines3.common.env_util import make_vec_env

    with pytest.raises(TypeError, match="TetherLibration"):
        ResidualVecEnv(make_vec_env("Pendulum-v1", n_envs=1), _smc(), 0.2)
    venv.close()


@pytest.mark.parametrize("bad", [-0.1, True, float("nan"), "0.2"])
def test_the_scale_is_checked_alike_everywhere(bad):
    from tether_gym_agents.hybrids.policies import ResidualPolicy

    venv = _venv()
    message = f"scale {re.escape(repr(bad))} must be a finite number >= 0"
    for make in (lambda: ResidualVecEnv(venv, _smc(), bad),
                 lambda: ResidualPolicy(_smc(), _smc(), bad),
                 lambda: ResidualSpec.from_dict({"scale": bad})):
        with pytest.raises(ValueError, match=message):
            make()
    venv.close()


def test_residual_spec():
    spec = ResidualSpec.from_dict({"base": "smc", "scale": 0.3, "filter": False})
    assert spec == ResidualSpec(BaseLaw.SMC, 0.3, False)
    assert ResidualSpec.from_dict(spec.to_dict()) == spec
    assert ResidualSpec.from_dict({}) == ResidualSpec()
    for bad, match in (({"scal": 0.2}, r"unknown key\(s\) \['scal'\]; valid keys: "
                                       r"\['base', 'scale', 'filter'\]"),
                       ({"base": "pid"}, r"base 'pid' is not one of \['smc'\]"),
                       ({"scale": -1}, "scale -1 must be"), ({"scale": True}, "scale"),
                       ({"scale": float("nan")}, "scale"),
                       ({"filter": "yes"}, "filter 'yes' must be true or false"),
                       ([0.2], "must be a mapping")):
        with pytest.raises(ValueError, match=match):
            ResidualSpec.from_dict(bad)


def test_config_key_is_validated(tmp_path, capsys):
    params = load_hyperparams(CONFIG_DIR / "ppo_residual.yml", "ppo", tether_gym.ENV_ID)
    assert params["residual"] == {"base": "smc", "scale": 0.2, "filter": True}
    assert params["n_timesteps"] == 1_000_000
    assert params["policy_kwargs"]["log_std_init"] == -3.5
    bad = tmp_path / "bad.yml"
    bad.write_text("default:\n  residual: {base: smc, gain: 2}\n")
    with pytest.raises(ConfigError, match=r"residual: unknown key\(s\) \['gain'\]; valid keys"):
        load_hyperparams(bad, "ppo", tether_gym.ENV_ID)
    # the hybrid commands reel rates: an explicit increment mode is an error before work
    assert main(["--config", str(CONFIG_DIR / "ppo_residual.yml"), "--out",
                 str(tmp_path / "run"), "--env-kwargs", "action_mode=increment"]) == 2
    err = capsys.readouterr().err
    assert "action_mode='increment'" in err and "'rate'" in err
    assert not (tmp_path / "run" / "config.yml").exists()


@pytest.fixture(scope="module")
def hybrid_run(tmp_path_factory):
    """A residual PPO run of 2048 steps (python train.py --config ppo_residual.yml ...)."""
    out = tmp_path_factory.mktemp("hybrid") / "run"
    code = main(["--config", str(CONFIG_DIR / "ppo_residual.yml"), "--timesteps", "2048",
                 "--n-envs", "2", "--out", str(out), "--no-progress", "--eval-episodes", "1",
                 "--env-kwargs", "orbits_per_episode=0.05"])
    assert code == 0
    return out


def test_training_records_the_hybrid(hybrid_run):
    expected = {"base": "smc", "scale": 0.2, "filter": True}
    for unit in (hybrid_run, hybrid_run / "final_agent"):
        meta = json.loads((unit / AGENT_FILE).read_text())
        assert meta["hybrid"] == expected
        assert meta["env"]["kwargs"]["action_mode"] == "rate"
        assert TrainedAgent.load(unit).hybrid == expected
    assert hybrid_of(hybrid_run) == expected
    assert "residual:" in (hybrid_run / "config.yml").read_text()


def test_a_malformed_hybrid_entry_is_refused(hybrid_run, tmp_path):
    import shutil

    unit = tmp_path / "agent"
    shutil.copytree(hybrid_run / "final_agent", unit)
    meta = json.loads((unit / AGENT_FILE).read_text())
    meta["hybrid"] = {"base": "smc", "scale": "big"}
    (unit / AGENT_FILE).write_text(json.dumps(meta))
    with pytest.raises(AgentLoadError, match="hybrid: scale 'big'"):
        TrainedAgent.load(unit)


def test_evaluation_runs_the_hybrid(hybrid_run):
    spec = resolve_policy(str(hybrid_run))
    assert spec.kind is PolicyKind.HYBRID and spec.env_kwargs == {"action_mode": "rate"}
    results = evaluate([str(hybrid_run), "smc"], "paper", 1,
                       env_kwargs={"orbits_per_episode": 0.1}, out=None, log=None)
    block = results["policies"][str(hybrid_run)]
    assert block["kind"] == "hybrid" and block["env_kwargs"] == {"action_mode": "rate"}
    assert 0.0 <= block["filter_rate"] <= 1.0  # the filter ran (one policy per episode)
    assert results["policies"]["smc"]["kind"] == "baseline"
