"""The native vector env: the same trajectories as single envs, gymnasium's vector API."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import tether_gym
from tether_gym.envs import TetherLibrationEnv
from tether_gym.envs.vector import TetherLibrationVectorEnv

ENV_ID = tether_gym.ENV_ID
SHORT = {"orbits_per_episode": 0.05}  # 13 steps per episode
RANDOMISED = {
    "orbits_per_episode": 0.05, "obs_noise": 0.01, "disturbance": 0.1, "init_theta_range": 0.1,
    "init_dtheta_range": 0.1, "init_length_range": 0.05, "eccentricity_range": (0.1, 0.3),
    "mass_range": 0.2,
}
# with action +1 the reel pays out until the length leaves its bounds (after 14 steps)
FAILING = {"n_bodies": 2, "max_reel_rate": 2.0, "accel_limit": 0.05,
           "length_bounds": (0.3, 1.1), "orbits_per_episode": 0.2}
CONFIGS = {
    "short": SHORT,
    "randomised": RANDOMISED,
    "failing": FAILING,
    "four_bodies_full_gravity": {"n_bodies": 4, "gravity": "full", "orbits_per_episode": 0.04,
                                 "obs_noise": 0.02},
    "step_limit": {"max_episode_steps": 5, "disturbance": 0.05},
}


def make_vec(num_envs, **kwargs):
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="vector_entry_point",
                        **kwargs)


def make_sync(num_envs, **kwargs):
    return gym.make_vec(ENV_ID, num_envs=num_envs, vectorization_mode="sync", **kwargs)


def actions_for(name, num_envs, n, steps, seed=0):
    """Pre-drawn actions; in "failing", some envs push hard so that they fail early."""
    rng = np.random.default_rng(seed)
    acts = rng.uniform(-1.0, 1.0, (steps, num_envs, n)).astype(np.float32)
    if name == "failing":
        acts[:, ::2] = np.float32(1.0)
    return acts


def assert_identical(a, b, where=""):
    """Bitwise equality of nested dicts / tuples / arrays / scalars (dtype included)."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), f"{where}: keys {list(a)} != {list(b)}"
        for key in a:
            assert_identical(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, (tuple, list)):
        assert len(a) == len(b), f"{where}: lengths {len(a)} != {len(b)}"
        for i, (u, v) in enumerate(zip(a, b, strict=True)):
            assert_identical(u, v, f"{where}[{i}]")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.dtype == b.dtype and a.shape == b.shape, \
            f"{where}: {a.dtype}{a.shape} != {b.dtype}{b.shape}"
        if a.dtype == object:
            assert a.tolist() == b.tolist(), f"{where}: {a} != {b}"
        else:
            assert a.tobytes() == b.tobytes(), f"{where}: {a} != {b}"
    elif isinstance(a, float):
        assert type(a) is type(b) and np.float64(a).tobytes() == np.float64(b).tobytes(), \
            f"{where}: {a!r} != {b!r}"
    else:
        assert type(a) is type(b) and a == b, f"{where}: {a!r} != {b!r}"


# --------------------------------------------------------------------------- #
def test_make_vec_builds_the_native_env_without_warnings():
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        env = make_vec(3, n_bodies=4)
        default = gym.make_vec(ENV_ID, num_envs=2)  # vector entry point is the default
    assert [str(w.message) for w in caught] == []
    assert isinstance(env.unwrapped, TetherLibrationVectorEnv)
    assert isinstance(default.unwrapped, TetherLibrationVectorEnv)
    assert env.metadata["autoreset_mode"] is AutoresetMode.NEXT_STEP
    single = gym.make(ENV_ID, n_bodies=4)
    assert env.single_observation_space == single.observation_space
    assert env.single_action_space == single.action_space
    assert env.observation_space.shape == (3, *single.observation_space.shape)
    assert env.action_space.shape == (3, 3)
    assert env.observation_space.dtype == np.float32
    assert env.num_envs == 3
    assert env.spec.id == ENV_ID
    # no step limit is registered: the env truncates itself after orbits_per_episode
    assert env.unwrapped.max_episode_steps is None
    obs, info = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    obs, *_ = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs)
    env.close()
    default.close()


@pytest.mark.parametrize("name", sorted(CONFIGS))
def test_matches_sync_vector_env_of_single_envs(name):
    """Step by step, bitwise: obs, rewards, flags and infos (with masks), across autoresets."""
    kwargs = CONFIGS[name]
    num_envs, steps = 5, 40
    vec, sync = make_vec(num_envs, **kwargs), make_sync(num_envs, **kwargs)
    n = vec.single_action_space.shape[0]
    acts = actions_for(name, num_envs, n, steps)
    assert_identical(vec.reset(seed=7), sync.reset(seed=7), "reset")
    ended = 0
    for t in range(steps):
        if t == 25:  # a reset without seed continues every env's generator
            assert_identical(vec.reset(), sync.reset(), f"reset at {t}")
        out_vec, out_sync = vec.step(acts[t]), sync.step(acts[t])
        assert_identical(out_vec, out_sync, f"step {t}")
        ended += int(np.sum(out_vec[2] | out_vec[3]))
    assert ended >= num_envs  # every config ends episodes inside the window
    vec.close()
    sync.close()


def test_failures_are_reported_like_the_single_env():
    vec, sync = make_vec(4, **FAILING), make_sync(4, **FAILING)
    acts = actions_for("failing", 4, 1, 30)
    vec.reset(seed=1)
    sync.reset(seed=1)
    labels = set()
    for t in range(30):
        out = vec.step(acts[t])
        assert_identical(out, sync.step(acts[t]), f"step {t}")
        labels.update(label for label in out[4]["failure"] if label is not None)
        assert np.array_equal(out[2], out[4]["failure"] != None)  # noqa: E711 - object array
    assert "length" in labels


@pytest.mark.parametrize("name", ["randomised", "failing"])
def test_each_sub_env_is_a_single_env(name):
    """Sub-env i == TetherLibrationEnv reset(seed=s+i), then reset() after each episode."""
    kwargs = CONFIGS[name]
    num_envs, steps, seed = 3, 45, 11
    vec = TetherLibrationVectorEnv(num_envs, **kwargs)
    singles = [TetherLibrationEnv(**kwargs) for _ in range(num_envs)]
    n = vec.single_action_space.shape[0]
    acts = actions_for(name, num_envs, n, steps, seed=3)
    obs, infos = vec.reset(seed=seed)
    for i, env in enumerate(singles):
        o, info = env.reset(seed=seed + i)
        assert_identical(obs[i], o, f"reset obs {i}")
        for key, value in info.items():
            assert infos["_" + key][i]
            assert_identical(infos[key][i], np.asarray(value), f"reset info {i} {key}")
    ended = [False] * num_envs
    resets = 0
    for t in range(steps):
        obs, rew, term, trunc, infos = vec.step(acts[t])
        for i, env in enumerate(singles):
            if ended[i]:
                o, info = env.reset()
                r, te, tr = 0.0, False, False
                resets += 1
            else:
                o, r, te, tr, info = env.step(acts[t, i])
            ended[i] = te or tr
            where = f"step {t} env {i}"
            assert_identical(obs[i], o, where)
            assert rew[i] == r and term[i] == te and trunc[i] == tr, where
            for key, value in info.items():
                assert_identical(infos[key][i], np.asarray(value), f"{where} {key}")
    assert resets >= num_envs


def test_seeds_follow_sync_vector_env_convention():
    env = TetherLibrationVectorEnv(3, **RANDOMISED)
    env.reset(seed=5)
    assert env.np_random_seed == (5, 6, 7)
    env.reset(seed=[9, None, 2])
    assert env.np_random_seed == (9, 6, 2)
    single = TetherLibrationEnv(**RANDOMISED)
    obs, _ = env.reset(seed=[3, 4, 3])
    assert_identical(obs[0], obs[2])
    assert_identical(obs[0], single.reset(seed=3)[0])
    assert len(env.np_random) == 3
    with pytest.raises(ValueError, match="one per env"):
        env.reset(seed=[1, 2])
    with pytest.raises(TypeError, match="seed"):
        env.reset(seed="1")


def test_unseeded_envs_differ():
    env = TetherLibrationVectorEnv(4, **RANDOMISED)
    obs, _ = env.reset()
    assert len({row.tobytes() for row in obs}) == 4


def test_step_limit_of_make_vec_is_the_time_limit_of_make():
    kwargs = {"orbits_per_episode": 1.0}  # 252 steps of true anomaly
    for limit, expect in ((None, 252), (3, 3), (-1, 252)):
        extra = {} if limit is None else {"max_episode_steps": limit}
        vec = make_vec(1, **extra, **kwargs)
        single = gym.make(ENV_ID, **extra, **kwargs)
        vec.reset(seed=0)
        single.reset(seed=0)
        for t in range(1, expect + 1):
            out = vec.step(np.zeros((1, 2)))
            _, _, te, tr, _ = single.step(np.zeros(2))
            assert (bool(out[3][0]), tr) == ((t == expect),) * 2, (limit, t)
            assert not out[2][0] and not te


def test_partial_reset_with_reset_mask_matches_sync():
    num_envs = 4
    vec, sync = make_vec(num_envs, **RANDOMISED), make_sync(num_envs, **RANDOMISED)
    acts = actions_for("randomised", num_envs, 2, 30)
    assert_identical(vec.reset(seed=0), sync.reset(seed=0))
    for t in range(30):
        assert_identical(vec.step(acts[t]), sync.step(acts[t]), f"step {t}")
        if t in (6, 12, 20):
            mask = np.array([t % 4 == 0, True, False, t == 12])
            options = {"reset_mask": mask}
            seed = None
            if t == 12:
                options["theta"] = [0.05, -0.05]
                seed = [None, 40, 41, None]
            out_vec = vec.reset(seed=seed, options=dict(options))
            out_sync = sync.reset(seed=seed, options=dict(options))
            assert_identical(out_vec, out_sync, f"partial reset at {t}")
            assert np.array_equal(out_vec[1]["_theta"], mask)


def test_partial_reset_clears_pending_autoreset():
    env = TetherLibrationVectorEnv(2, **SHORT)
    env.reset(seed=0)
    for _ in range(13):
        *_, trunc, _ = env.step(np.zeros((2, 2)))
    assert trunc.all()
    env.reset(options={"reset_mask": np.array([True, False])})
    obs, rew, term, trunc, info = env.step(np.zeros((2, 2)))
    assert info["nu"][0] == pytest.approx(0.025)  # stepped, not reset again
    assert info["nu"][1] == 0.0 and rew[1] == 0.0  # auto-reset on this step


def test_reset_options_apply_to_every_env():
    env = TetherLibrationVectorEnv(3, **RANDOMISED)
    theta = [0.05, -0.02]
    obs, info = env.reset(seed=0, options={"theta": theta, "nu": 1.0})
    assert np.array_equal(info["theta"], np.tile(theta, (3, 1)))
    assert np.all(info["nu"] == 1.0)
    assert_identical(obs[1], TetherLibrationEnv(**RANDOMISED).reset(
        seed=1, options={"theta": theta, "nu": 1.0})[0])


def test_invalid_arguments_are_rejected_with_the_value():
    env = TetherLibrationVectorEnv(2)
    with pytest.raises(RuntimeError, match="reset"):
        env.step(np.zeros((2, 2)))
    env.reset(options={"reset_mask": np.array([True, False])})
    with pytest.raises(RuntimeError, match=r"sub-envs \[1\] were never reset"):
        env.step(np.zeros((2, 2)))
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(2, 2\).*\(2,\)"):
        env.step(np.zeros(2))
    with pytest.raises(ValueError, match="finite.*nan"):
        env.step(np.array([[0.0, 0.0], [np.nan, 0.0]]))
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"thetta": 0.0})
    with pytest.raises(TypeError, match="numpy array"):
        env.reset(options={"reset_mask": [True, False]})
    with pytest.raises(ValueError, match="at least one True"):
        env.reset(options={"reset_mask": np.zeros(2, dtype=bool)})
    with pytest.raises(ValueError, match="shape"):
        env.reset(options={"reset_mask": np.ones(3, dtype=bool)})
    obs, *_, info = env.step(np.zeros((2, 2)))  # the rejected calls changed nothing
    assert_identical(obs[0], obs[1])
    assert np.all(info["nu"] == 0.025)
    with pytest.raises(ValueError, match="did you mean 'n_bodies'"):
        make_vec(2, n_body=3)
    with pytest.raises(ValueError, match="num_envs"):
        TetherLibrationVectorEnv(0)
    # before: 10**8 sub-envs allocated until the machine ran out of memory (10**7: 6.5 GB)
    with pytest.raises(ValueError, match=r"num_envs=100000000 must be in \[1, 4194304\]"):
        gym.make_vec(tether_gym.ENV_ID, num_envs=10**8)
    with pytest.raises(ValueError, match="human"):
        TetherLibrationVectorEnv(2, render_mode="human")
    with pytest.raises(ValueError, match="max_episode_steps"):
        TetherLibrationVectorEnv(2, max_episode_steps=0)
    with pytest.raises(TypeError, match="parallel"):
        TetherLibrationVectorEnv(2, parallel="yes")


def test_gymnasium_vector_wrappers_work():
    from gymnasium.wrappers.vector import ClipAction, NormalizeObservation, RecordEpisodeStatistics

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = RecordEpisodeStatistics(NormalizeObservation(ClipAction(make_vec(3, **SHORT))))
        env.reset(seed=0)
        lengths = []
        for _ in range(27):  # 13 steps, the auto-reset step, 13 steps
            *_, info = env.step(2.0 * env.action_space.sample())
            if "episode" in info:
                lengths += info["episode"]["l"][info["_episode"]].tolist()
    assert lengths == [13] * 6


def test_returned_arrays_are_not_reused():
    env = TetherLibrationVectorEnv(2)
    obs, info = env.reset(seed=0)
    obs_copy, theta = obs.copy(), info["theta"].copy()
    obs2, rew, *_, info2 = env.step(np.zeros((2, 2)))
    assert np.array_equal(obs, obs_copy) and np.array_equal(info["theta"], theta)
    assert obs2 is not obs and info2["theta"] is not info["theta"]
    # the entries (and the "_key" masks) are separate arrays, even where they share
    # one buffer: writing one changes no other
    info2["theta"][:] = 7.0
    info2["_theta"][:] = False
    assert not np.any(info2["dtheta"] == 7.0) and not np.any(info2["length"] == 7.0)
    assert info2["_dtheta"].all() and info2["_nu"].all()
    _, _, _, _, info3 = env.step(np.zeros((2, 2)))
    assert not np.any(info3["theta"] == 7.0) and info3["_theta"].all()


@pytest.mark.parametrize("lead", [None, 0.0, 11.0, 1e9])
def test_threaded_kernel_gives_the_serial_results(lead):
    kwargs = dict(FAILING, disturbance=0.1, obs_noise=0.01)
    serial = TetherLibrationVectorEnv(37, parallel=False, **kwargs)
    threaded = TetherLibrationVectorEnv(37, parallel=True, **kwargs)
    if lead is not None:  # a fixed split of the rows between the threads
        threaded._batch._adjust_lead = lambda *args: None
        threaded._batch._lead = lead
    acts = actions_for("failing", 37, 1, 25)
    assert_identical(serial.reset(seed=2), threaded.reset(seed=2))
    for t in range(25):
        assert_identical(serial.step(acts[t]), threaded.step(acts[t]), f"step {t}")
    assert len(threaded._batch._workers) == 1  # the steps did run on two threads


def test_the_lead_moves_towards_workers_that_end_just_before_the_caller():
    from tether_gym.envs.batch import LEAD_MARGIN, ChainBatch

    batch = ChainBatch(TetherLibrationVectorEnv(4).config, 4)
    batch._lead = 10.0
    batch._adjust_lead(late=-LEAD_MARGIN * 1e-6, per_row=1e-6, most=100)
    assert batch._lead == 10.0  # on target: unchanged
    batch._adjust_lead(late=20e-6, per_row=1e-6, most=100)  # worker 20 rows late
    assert batch._lead == pytest.approx(10.0 + 0.5 * (20 + LEAD_MARGIN))
    batch._adjust_lead(late=-1.0, per_row=1e-6, most=100)
    assert batch._lead == -100.0  # workers far early: they get up to half more rows
    batch._adjust_lead(late=1.0, per_row=1e-6, most=100)
    assert batch._lead == 100.0


def test_autoresets_run_beside_the_threaded_step_with_the_serial_results():
    """The ended rows are reset while the workers step the others (``meanwhile``); with a
    negative lead (workers given more rows) the results stay bitwise the serial ones."""
    kwargs = dict(FAILING, disturbance=0.1, obs_noise=0.01)
    serial = TetherLibrationVectorEnv(37, parallel=False, **kwargs)
    threaded = TetherLibrationVectorEnv(37, parallel=True, **kwargs)
    threaded._batch._adjust_lead = lambda *args: None
    threaded._batch._lead = -15.0
    calls = []
    reset_rows = threaded._batch.reset_rows
    threaded._batch.reset_rows = lambda *a, **k: calls.append(len(a[0])) or reset_rows(*a, **k)
    acts = actions_for("failing", 37, 1, 25)
    serial.reset(seed=4)
    threaded.reset(seed=4)
    calls.clear()
    for t in range(25):
        assert_identical(serial.step(acts[t]), threaded.step(acts[t]), f"step {t}")
    assert sum(calls) > 0  # some rows ended and were reset during threaded steps


def test_render_rgb_array_gives_one_frame_per_env():
    pytest.importorskip("matplotlib")
    env = make_vec(2, render_mode="rgb_array")
    env.reset(seed=0)
    frames = env.render()
    assert len(frames) == 2
    assert all(f.dtype == np.uint8 and f.ndim == 3 and f.shape[2] == 3 for f in frames)
    env.close()
    with pytest.warns(UserWarning, match="render_mode"):
        assert make_vec(1).render() is None


def test_parallel_auto_threads_only_large_batches():
    """parallel="auto" (the default) is serial below PARALLEL_MIN_ENVS, threaded from it."""
    import os

    from tether_gym.envs.vector import PARALLEL_MIN_ENVS

    small = TetherLibrationVectorEnv(4)
    assert small.parallel == "auto" and small._n_chunks(4) == 0
    big = TetherLibrationVectorEnv(PARALLEL_MIN_ENVS)
    cores = len(os.sched_getaffinity(0))
    expected = 0 if cores < 2 else min(cores, PARALLEL_MIN_ENVS)
    assert big._n_chunks(PARALLEL_MIN_ENVS) == expected
    assert TetherLibrationVectorEnv(PARALLEL_MIN_ENVS, parallel=False)._n_chunks(200) == 0


def test_small_auto_batches_leave_numbas_thread_pool_alone():
    """Stepping fewer than PARALLEL_MIN_ENVS envs must not launch numba's threads.

    Launching them (numba.get_num_threads() does) leaves an OpenMP worker spinning at
    about half a core beside every training run; measured here, it slowed PPO ~5x.
    """
    import subprocess
    import sys

    code = ("import numpy as np, numba.np.ufunc.parallel as p\n"
            "from tether_gym.envs.vector import TetherLibrationVectorEnv\n"
            "env = TetherLibrationVectorEnv(8)\n"
            "env.reset(seed=0)\n"
            "for _ in range(3):\n"
            "    env.step(np.zeros((8, 2), dtype=np.float32))\n"
            "print(p._is_initialized)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
