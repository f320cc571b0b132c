"""The GPU path's constraint cost (TorchTetherVecEnv, on the CPU) equals the numba env's.

Whole episodes of random reel-rate actions, from the same starts, until most end slack:
``info["cost"]`` and its parts agree step by step on every live row, the terminal step
included, with the default and with other ``cost_thresholds``. One step from random and
wild rows (diverged and non-finite ones, whose cost comes from the kept state) agrees on
every row.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

torch = pytest.importorskip("torch")

import tether_gym  # noqa: E402,F401
from tether_gym.envs.batch import ChainBatch  # noqa: E402
from tether_gym.envs.config import EnvConfig  # noqa: E402
from tether_gym.tasks.cost import COST_NAMES, CostThresholds  # noqa: E402
from tether_gym.tasks.termination import KEEP_PREVIOUS, Failure  # noqa: E402
from tether_gym_agents.accel import chain  # noqa: E402
from tether_gym_agents.accel.vec_env import TorchTetherVecEnv  # noqa: E402

B = 32
OTHER = {"tension": 0.9, "length_factor": 1.6, "tumble_fraction": 0.2}
"""Thresholds other than the defaults, each part reached more often."""


def _copy_rows(venv, env):
    """The native env's rows (state, parameters, command, noise, outputs) into the torch env."""
    r = venv.unwrapped._batch.rows
    def t(x):
        return torch.as_tensor(np.array(x), dtype=torch.float64)
    env.nu, env.y, env.par, env.u, env.noise = t(r.nu), t(r.y), t(r.par), t(r.command), t(r.noise)
    env.nu_end, env.tension, env.tension_min = t(r.nu_end), t(r.tension), t(r.tension_min)
    env.derivative = t(r.derivative)
    env.obs = torch.as_tensor(r.obs.copy())


@pytest.mark.parametrize("thresholds", [None, OTHER])
def test_episode_cost_equals_numba_through_slack(thresholds):
    kwargs = {"action_mode": "rate", "n_bodies": 3}
    if thresholds is not None:
        kwargs["cost_thresholds"] = thresholds
    venv = gym.make_vec(tether_gym.ENV_ID, num_envs=B, vectorization_mode="vector_entry_point",
                        parallel=False, **kwargs)
    _, info = venv.reset(seed=7)
    env = TorchTetherVecEnv(B, device="cpu", seed=0, **kwargs)
    _, tinfo = env.reset()
    for name in COST_NAMES:  # a reset costs nothing
        assert np.all(info[name] == 0.0) and torch.all(tinfo[name] == 0.0)
    _copy_rows(venv, env)
    rng = np.random.default_rng(11)
    alive = np.ones(B, dtype=bool)
    slack_before_end = np.zeros(B)  # cost_slack summed over the steps before the last
    terminal = np.full(B, np.nan)
    codes = np.zeros(B, dtype=int)
    for _ in range(800):
        action = rng.uniform(-1.0, 1.0, (B, 2))
        _, _, term, trunc, info = venv.step(action)
        _, _, tterm, ttrunc, tinfo = env.step(torch.as_tensor(action))
        live = alive.copy()
        np.testing.assert_array_equal(tterm.numpy()[live], term[live])
        for name in COST_NAMES:
            got = tinfo[name].numpy()
            assert got.dtype == np.float64
            np.testing.assert_array_equal(got[live], info[name][live], err_msg=name)
        parts = sum(info[f"cost_{p}"] for p in ("slack", "length", "tumble"))
        np.testing.assert_array_equal(info["cost"], parts)
        done = live & (term | trunc)
        slack_before_end[live & ~done] += info["cost_slack"][live & ~done]
        terminal[done] = info["cost"][done]
        codes[done] = tinfo["failure"].numpy()[done]
        alive &= ~(term | trunc)
        if not alive.any():
            break
    slack = codes == Failure.SLACK
    assert slack.sum() >= B // 2, codes  # random rate commands slacken most chains
    # the cost warned of the slack before it ended the episode, and its last step costs
    assert np.all(slack_before_end[slack] >= 1.0), slack_before_end[slack]
    assert np.all(terminal[codes != 0] >= 1.0), terminal


def _random_rows(config: EnvConfig, rng: np.random.Generator, rows: int) -> dict:
    """Random state, parameter, command, disturbance and noise rows (some far out)."""
    n = config.n_tethers
    th = rng.uniform(-1.3, 1.3, (rows, n))
    dth = rng.uniform(-0.5, 0.5, (rows, n))
    ln = rng.uniform(0.3, 1.5, (rows, n)) / n
    dl = rng.uniform(-0.05, 0.05, (rows, n))
    wild = rng.random(rows) < 0.15  # far from any healthy state: slack, diverged, ...
    dth[wild] *= rng.choice([10.0, 1e3, 1e7], (wild.sum(), 1))
    ln[wild] *= rng.choice([1e-3, 1.0, 30.0], (wild.sum(), 1))
    return {"nu": rng.uniform(-10.0, 30.0, rows),
            "y": np.concatenate([th, dth, ln, dl], axis=1),
            "par": config.param_rows(rng.uniform(0.0, 0.6, rows),
                                     rng.uniform(0.5, 2.0, (rows, n))),
            "command": rng.uniform(-1.0, 1.0, (rows, n)),
            "disturbance": rng.uniform(-0.1, 0.1, (rows, n)),
            "noise": rng.normal(0.0, 1e-3, (rows, 4 * n)),
            "action": rng.uniform(-1.5, 1.5, (rows, n))}


@pytest.mark.parametrize("n_bodies", [2, 4])
def test_one_step_cost_equals_numba_on_every_row(n_bodies):
    rows = 400
    kwargs = {"n_bodies": n_bodies, "initial_theta": [0.0] * (n_bodies - 1),
              "cost_thresholds": OTHER}
    config = EnvConfig.from_kwargs(**kwargs)
    draw = _random_rows(config, np.random.default_rng(n_bodies), rows)
    batch = ChainBatch(config, rows, check_start=False)
    r = batch.rows
    for key in ("nu", "y", "par", "command", "disturbance", "noise"):
        getattr(r, key)[...] = draw[key]
    r.nu_end[...] = draw["nu"] + 1.0
    assert batch._step(np.arange(rows, dtype=np.int64), np.ascontiguousarray(draw["action"]),
                       r, batch.cfg, batch._work[0], False, batch._once) == -1

    env = TorchTetherVecEnv(rows, device="cpu", seed=0, **kwargs)
    env.reset()
    def as_t(x):
        return torch.as_tensor(x, dtype=torch.float64)
    env.nu, env.y, env.par = as_t(draw["nu"]), as_t(draw["y"]), as_t(draw["par"])
    env.u, env.disturbance, env.noise = (as_t(draw["command"]), as_t(draw["disturbance"]),
                                         as_t(draw["noise"]))
    env.nu_end = env.nu + 1.0
    env._advance(as_t(draw["action"]), torch.ones(rows, dtype=torch.bool), draw=False)

    codes = env.failure.numpy()
    np.testing.assert_array_equal(codes, r.failure)
    assert np.isin(codes, KEEP_PREVIOUS).any()  # the kept states' cost is compared too
    got = env.cost.numpy()
    np.testing.assert_array_equal(got, r.cost)
    info = env.info()
    for c, name in enumerate(COST_NAMES):
        np.testing.assert_array_equal(info[name].numpy(), r.cost[:, c], err_msg=name)
    for c in range(1, len(COST_NAMES)):  # every part is both reached and not
        assert set(np.unique(got[:, c])) == {0.0, 1.0}, COST_NAMES[c]
    # the thresholds are the configuration's: the defaults would cost otherwise
    default = env.cc._replace(cost=CostThresholds().record(config.episode.length_bounds))
    assert not torch.equal(chain.cost(env.y, env.tension_min, default), env.cost)


@pytest.mark.parametrize("mode", ["next_step", "same_step"])
def test_the_failing_step_reports_its_cost_in_both_autoreset_modes(mode):
    """A same_step autoreset returns the ended step's cost (as its reward), not the reset's."""
    env = TorchTetherVecEnv(8, device="cpu", seed=5, autoreset_mode=mode, action_mode="rate")
    env.reset()
    wild = torch.ones((8, 2), dtype=torch.float64)  # reel out flat out: ends early
    for _ in range(2000):
        _, _, term, _, info = env.step(wild)
        if term.any():
            break
    assert term.any()
    assert torch.all(info["cost"][term] >= 1.0), info["cost"][term]
    parts = info["cost_slack"] + info["cost_length"] + info["cost_tumble"]
    assert torch.equal(info["cost"], parts)
    if mode == "same_step":
        assert torch.all(env.cost[term] == 0.0)  # the ended rows are reset already
