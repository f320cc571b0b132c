"""The stable-baselines3 adapter honours SB3's VecEnv contract."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from gymnasium.wrappers import TimeLimit  # noqa: E402
from stable_baselines3 import PPO  # noqa: E402
from stable_baselines3.common.evaluation import evaluate_policy  # noqa: E402
from stable_baselines3.common.monitor import Monitor  # noqa: E402
from stable_baselines3.common.vec_env import VecEnv, VecMonitor, VecNormalize  # noqa: E402

from tether_gym.envs import TetherLibrationEnv  # noqa: E402
from tether_gym_agents.training.vec_env import TetherSB3VecEnv, make_sb3_vec_env  # noqa: E402

SHORT = {"orbits_per_episode": 0.05}  # 13 steps
# action +1 pays out until the length leaves its bounds (terminated after 14 steps);
# other actions reach the end of the 26-step episode (truncated)
MIXED = {"n_bodies": 2, "max_reel_rate": 2.0, "accel_limit": 0.05,
         "length_bounds": (0.3, 1.1), "orbits_per_episode": 0.1, "obs_noise": 0.01,
         "action_mode": "rate"}


def test_make_sb3_vec_env_is_an_sb3_vec_env():
    env = make_sb3_vec_env(3, seed=0, env_kwargs={"n_bodies": 4})
    single = TetherLibrationEnv(n_bodies=4)
    assert isinstance(env, VecEnv) and isinstance(env, TetherSB3VecEnv)
    assert env.num_envs == 3
    assert env.observation_space == single.observation_space
    assert env.action_space == single.action_space
    assert env.render_mode is None
    obs = env.reset()
    assert isinstance(obs, np.ndarray) and obs.shape == (3, *single.observation_space.shape)
    obs, rewards, dones, infos = env.step(np.zeros((3, 3), dtype=np.float32))
    assert obs.dtype == np.float32 and rewards.dtype == np.float32 and dones.dtype == np.bool_
    assert isinstance(infos, list) and len(infos) == 3
    assert set(single.reset(seed=0)[1]) <= set(infos[0])
    assert infos[0]["TimeLimit.truncated"] is False
    env.close()


def test_same_step_autoreset_matches_single_envs():
    """done -> obs is the reset obs, terminal_observation the last one, flags per SB3."""
    num_envs, seed, steps = 3, 4, 60
    env = make_sb3_vec_env(num_envs, seed=seed, env_kwargs=MIXED, monitor=True)
    singles = [TetherLibrationEnv(**MIXED) for _ in range(num_envs)]
    rng = np.random.default_rng(0)
    acts = rng.uniform(-0.3, 0.3, (steps, num_envs, 1)).astype(np.float32)
    acts[:, 0] = 1.0  # env 0 fails (terminated), envs 1, 2 run to the time limit
    obs = env.reset()
    returns, lengths = np.zeros(num_envs), np.zeros(num_envs, dtype=int)
    for i, single in enumerate(singles):
        o, info = single.reset(seed=seed + i)
        assert np.array_equal(obs[i], o)
        assert env.reset_infos[i]["nu"] == info["nu"]
    seen = {"terminated": 0, "truncated": 0}
    for t in range(steps):
        obs, rewards, dones, infos = env.step(acts[t])
        for i, single in enumerate(singles):
            o, r, te, tr, info = single.step(acts[t, i])
            returns[i] += r
            lengths[i] += 1
            assert rewards[i] == np.float32(r)
            assert dones[i] == (te or tr)
            assert infos[i]["TimeLimit.truncated"] == (tr and not te)
            assert infos[i]["failure"] == info["failure"]
            assert np.array_equal(infos[i]["theta"], info["theta"])
            if te or tr:
                seen["terminated" if te else "truncated"] += 1
                assert np.array_equal(infos[i]["terminal_observation"], o)
                assert infos[i]["episode"]["l"] == lengths[i]
                assert infos[i]["episode"]["r"] == pytest.approx(returns[i], abs=1e-5)
                o, info = single.reset()
                assert env.reset_infos[i]["nu"] == info["nu"]
                returns[i], lengths[i] = 0.0, 0
            else:
                assert "terminal_observation" not in infos[i] and "episode" not in infos[i]
            assert np.array_equal(obs[i], o), (t, i)
    assert seen["terminated"] >= 2 and seen["truncated"] >= 2


def test_seed_is_used_at_the_next_reset_only():
    env = make_sb3_vec_env(2, env_kwargs=dict(SHORT, init_theta_range=0.1))
    assert env.seed(10) == [10, 11]
    first = env.reset()
    again = env.reset()  # continues the generators
    single = TetherLibrationEnv(**SHORT, init_theta_range=0.1)
    assert np.array_equal(first[1], single.reset(seed=11)[0])
    assert np.array_equal(again[1], single.reset()[0])
    assert env.get_attr("np_random_seed") == [10, 11]


def test_set_options_per_env():
    env = make_sb3_vec_env(3, seed=0)
    env.set_options([{"theta": [0.05, 0.0]}, {}, {"theta": [0.05, 0.0]}])
    obs = env.reset()
    single = TetherLibrationEnv()
    for i, opts in enumerate(({"theta": [0.05, 0.0]}, None, {"theta": [0.05, 0.0]})):
        assert np.array_equal(obs[i], single.reset(seed=i, options=opts)[0])
    env.set_options({"nu": 1.0})
    assert np.all(env.reset()[:, 0] == np.float32(np.sin(1.0)))


@pytest.mark.parametrize("options", [[{}, {}], [{}, {}, {}, {}]])
def test_set_options_of_the_wrong_length_is_an_error(options):
    env = make_sb3_vec_env(3, seed=0)
    with pytest.raises(ValueError, match=f"options has {len(options)} entries but there are 3 "
                                         "sub-envs"):
        env.set_options(options)
    with pytest.raises(TypeError, match=r"options\[1\] must be a dict"):
        env.set_options([{}, 5, {}])
    with pytest.raises(TypeError, match="must be a dict, a list of 3 dicts or None"):
        env.set_options("theta")
    env.set_options([None, {"nu": 1.0}, None])  # None entries: no options
    obs = env.reset()
    assert obs[1, 0] == np.float32(np.sin(1.0)) and obs[0, 0] != obs[1, 0]
    env.close()


def test_attributes_methods_and_wrappers():
    env = make_sb3_vec_env(2, seed=0)
    env.reset()
    assert env.get_attr("render_mode") == [None, None]
    assert env.get_attr("observation_space", indices=1) == [env.observation_space]
    assert env.get_attr("config")[0].n_bodies == 3
    assert env.has_attr("config") and not env.has_attr("no_such_attribute")
    env.set_attr("max_episode_steps", 5)
    assert env.get_attr("max_episode_steps") == [5, 5]
    with pytest.raises(ValueError, match="share one"):
        env.set_attr("max_episode_steps", 6, indices=[0])
    results = env.env_method("__repr__")
    assert len(results) == 2 and results[0].startswith("TetherLibrationVectorEnv")
    with pytest.raises(ValueError, match="share one"):
        env.env_method("__repr__", indices=1)
    assert env.env_is_wrapped(Monitor) == [False, False]
    assert env.env_is_wrapped(TimeLimit) == [False, False]
    assert make_sb3_vec_env(2, monitor=True).env_is_wrapped(Monitor) == [True, True]
    for _ in range(5):
        *_, dones, infos = env.step(np.zeros((2, 2), dtype=np.float32))
    assert dones.all() and all(info["TimeLimit.truncated"] for info in infos)


def test_vec_monitor_and_evaluate_policy():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "already wrapped with a Monitor" warning
        env = VecMonitor(make_sb3_vec_env(2, seed=0, env_kwargs=SHORT))
    env.reset()
    episodes = []
    for _ in range(13):
        *_, infos = env.step(np.zeros((2, 2), dtype=np.float32))
        episodes += [info["episode"] for info in infos if "episode" in info]
    assert [ep["l"] for ep in episodes] == [13, 13]

    class Zero:
        def predict(self, observation, state=None, episode_start=None, deterministic=False):
            return np.zeros((len(observation), 2), dtype=np.float32), None

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no "not wrapped with a Monitor" warning
        rewards, lengths = evaluate_policy(
            Zero(), make_sb3_vec_env(2, seed=0, env_kwargs=SHORT, monitor=True),
            n_eval_episodes=4, return_episode_rewards=True)
    assert lengths == [13] * 4 and all(0.0 < r <= 13.0 for r in rewards)


def test_ppo_learns_on_the_adapter():
    env = VecNormalize(VecMonitor(make_sb3_vec_env(2, seed=0, env_kwargs=SHORT)))
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=64, n_epochs=1, seed=0, device="cpu")
    model.learn(256)
    assert model.num_timesteps >= 256
    assert len(model.ep_info_buffer) > 0 and model.ep_info_buffer[0]["l"] == 13
