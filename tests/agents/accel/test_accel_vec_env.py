"""TorchTetherVecEnv against the native vector env: episodes, starts, autoreset, errors."""

from __future__ import annotations

import os

import gymnasium as gym
import numpy as np
import pytest

torch = pytest.importorskip("torch")

import tether_gym  # noqa: E402,F401
from tether_gym.envs.layout import OBSERVATION  # noqa: E402
from tether_gym_agents.accel.vec_env import TorchTetherVecEnv  # noqa: E402

B = 48
DEVICE = os.environ.get("TETHER_TEST_DEVICE", "cpu")
BACKEND = os.environ.get("TETHER_TEST_BACKEND", "torch")
"""Where and by which backend the torch env steps (test_accel_chain.py says how they are set)."""
TRAINING = {"increment_gain": 0.5, "initial_theta": [0.0, 0.0], "init_theta_range": 0.15,
            "init_dtheta_range": 0.1, "eccentricity_range": [0.0, 0.35], "mass_range": 0.25,
            "observe_params": False}


def _native(kwargs, seed=3):
    venv = gym.make_vec("tether_gym/TetherLibration-v2", num_envs=B,
                        vectorization_mode="vector_entry_point", parallel=False, **kwargs)
    obs, _ = venv.reset(seed=seed)
    return venv, obs


def _copy_rows(venv, env):
    """The native env's rows (state, parameters, command, noise, outputs) into the torch env."""
    r = venv.unwrapped._batch.rows
    def t(x):
        return (torch.as_tensor(np.array(x), dtype=torch.float64, device=env.device))
    env.nu, env.y, env.par, env.u, env.noise = t(r.nu), t(r.y), t(r.par), t(r.command), t(r.noise)
    env.nu_end, env.tension, env.tension_min = t(r.nu_end), t(r.tension), t(r.tension_min)
    env.derivative = t(r.derivative)
    env.obs = torch.as_tensor(r.obs.copy(), device=env.device)


@pytest.mark.parametrize("n_bodies", [3, 5])
def test_whole_episodes_equal_numba(n_bodies):
    """754-step episodes from the same starts, driven by the same actions: 1e-9, same ends."""
    kwargs = {**TRAINING, "n_bodies": n_bodies, "initial_theta": [0.0] * (n_bodies - 1)}
    venv, obs = _native(kwargs)
    env = TorchTetherVecEnv(B, device=DEVICE, seed=0, backend=BACKEND, **kwargs)
    assert env.backend == BACKEND
    env.reset()
    _copy_rows(venv, env)
    n = n_bodies - 1
    # from holding the reels (the first third) to swinging them hard enough to fail
    amplitude = np.clip(np.linspace(-0.3, 0.6, B), 0.0, None)[:, None]
    alive = np.ones(B, dtype=bool)
    ended_at = np.full(B, -1)
    codes = np.zeros(B, dtype=int)
    max_dev = 0.0
    for step in range(1, 800):
        err = obs[:, OBSERVATION.slices(n)["error"]]
        action = amplitude * np.sin(0.05 * step + 10.0 * err)
        obs, rew, term, trunc, info = venv.step(action)
        tobs, trew, tterm, ttrunc, tinfo = (x.cpu() if hasattr(x, "cpu") else
                                            {k: v.cpu() for k, v in x.items()}
                                            for x in env.step(torch.as_tensor(action)))
        y = venv.unwrapped._batch.rows.y
        live = alive.copy()
        dev = np.abs(env.y.cpu().numpy()[live] - y[live]) / np.maximum(np.abs(y[live]), 1e-3)
        max_dev = max(max_dev, float(dev.max(initial=0.0)))
        np.testing.assert_allclose(trew.numpy()[live], rew[live], rtol=1e-9, atol=1e-12)
        np.testing.assert_array_equal(tterm.numpy()[live], term[live])
        np.testing.assert_array_equal(ttrunc.numpy()[live], trunc[live])
        done = live & (term | trunc)
        ended_at[done] = step
        codes[done] = tinfo["failure"].numpy()[done]
        alive &= ~(term | trunc)
        if not alive.any():
            break
    assert max_dev < 1e-9, max_dev
    assert not alive.any()
    assert (ended_at == 754).sum() >= 2 and (ended_at < 754).sum() >= 2  # both kinds of end
    assert set(codes[ended_at < 754]) - {0}


def test_start_from_the_same_draws_equals_numba():
    """The reset of a row from numpy's draws (same order) is the native env's reset."""
    kwargs = {**TRAINING, "obs_noise": 1e-3}
    venv, obs = _native(kwargs, seed=11)
    env = TorchTetherVecEnv(B, device=DEVICE, seed=0, backend=BACKEND, **kwargs)
    n = 2
    draws = {"ecc": [], "scale": [], "unit": [], "gauss": []}
    for i in range(B):  # the vector env seeds sub-env i with seed + i
        rng = np.random.default_rng(11 + i)
        draws["ecc"].append(rng.uniform(0.0, 0.35))
        draws["scale"].append(rng.uniform(0.75, 1.25, n))
        draws["unit"].append(rng.uniform(-1.0, 1.0, 3 * n))
        draws["gauss"].append(rng.standard_normal(4 * n))
    s = env.start({k: torch.as_tensor(np.array(v), dtype=torch.float64, device=env.device)
                   for k, v in draws.items()})
    s = {k: v.cpu() for k, v in s.items()}
    r = venv.unwrapped._batch.rows
    assert s["ok"].all()
    for key, want in (("y", r.y), ("par", r.par), ("noise", r.noise), ("u", r.command),
                      ("tension", r.tension), ("derivative", r.derivative)):
        np.testing.assert_allclose(s[key].numpy(), want, rtol=1e-12, atol=1e-15, err_msg=key)
    np.testing.assert_allclose(s["obs"].numpy(), obs, rtol=2.0**-23, atol=1e-12)


def test_autoreset_next_step_and_same_step():
    kwargs = {**TRAINING}
    for mode in ("next_step", "same_step"):
        env = TorchTetherVecEnv(8, device=DEVICE, seed=5, autoreset_mode=mode, backend=BACKEND,
                                **kwargs)
        env.reset()
        wild = torch.ones((8, 2), dtype=torch.float64, device=env.device)  # ends early
        for _ in range(2000):
            obs, rew, term, trunc, info = env.step(wild)
            if term.any():
                break
        assert term.any() and not trunc[term].any()
        row = int(torch.nonzero(term)[0])
        if mode == "same_step":
            assert info["final_failure"][row] != 0
            assert env.steps[row] == 0  # already reset, its last observation kept apart
            assert not torch.equal(info["final_obs"][row], obs[row])
        else:
            assert info["failure"][row] != 0
            obs2, rew2, term2, trunc2, _ = env.step(wild)
            assert rew2[row] == 0.0 and not term2[row] and not trunc2[row]
            assert env.steps[row] == 0


@pytest.mark.parametrize("mode", ["next_step", "same_step"])
def test_without_full_info_a_step_returns_the_same_and_less_info(mode):
    """``full_info=False`` (what ``train.py gpu`` asks for) steps the same episodes, episode
    ends included, and its ``info`` holds only the costs and the same-step entries."""
    envs = [TorchTetherVecEnv(8, device=DEVICE, seed=5, autoreset_mode=mode, backend=BACKEND,
                              full_info=full, **TRAINING) for full in (True, False)]
    for env in envs:
        env.reset()
    g = torch.Generator().manual_seed(2)
    ended = 0
    for _ in range(300):
        action = (torch.rand((8, 2), generator=g, dtype=torch.float64) * 2.4 - 1.2).to(DEVICE)
        (*full, info_full), (*lean, info_lean) = (env.step(action) for env in envs)
        assert all(torch.equal(x, y) for x, y in zip(full, lean, strict=True))
        for key, value in info_lean.items():
            assert torch.equal(value, info_full[key]), key
        ended += int((full[2] | full[3]).sum())
    same_step = {"final_obs", "final_failure"} if mode == "same_step" else set()
    assert set(info_lean) == {"cost", "cost_slack", "cost_length", "cost_tumble"} | same_step
    assert ended > 0 and len(info_full) > len(info_lean)


@pytest.mark.parametrize("mode", ["next_step", "same_step"])
def test_every_tensor_stays_in_its_storage(mode):
    """What CUDA graphs of the env's parts need (tether_gym_agents.accel.graphs): after
    steps, episode ends and resets, every tensor of the env is still the one it was
    made as, at the same address, updated in place."""
    env = TorchTetherVecEnv(8, device=DEVICE, seed=5, autoreset_mode=mode, backend=BACKEND,
                            **{**TRAINING, "orbits_per_episode": 0.02})
    env.reset()

    def tensors():
        out = {k: v for k, v in vars(env).items() if isinstance(v, torch.Tensor)}
        out.update({f"outputs.{k}": v for k, v in env.outputs._asdict().items()})
        return {k: (v, v.data_ptr()) for k, v in out.items()}

    before = tensors()
    assert {"nu", "y", "obs", "steps", "failure", "_pending", "outputs.final_obs"} <= set(before)
    g = torch.Generator().manual_seed(2)
    ended = 0
    for _ in range(20):
        _, _, term, trunc, _ = env.step(torch.rand((8, 2), generator=g).to(DEVICE) * 2 - 1)
        ended += int((term | trunc).sum())
    assert ended >= 8
    after = tensors()
    assert set(after) == set(before)
    for key, (tensor, address) in before.items():
        assert after[key][0] is tensor and after[key][1] == address, key


def _failing_starts(env, rows, monkeypatch, draws=3):
    """Make every start draw of ``rows`` fail, and allow ``draws`` draws per reset."""
    from tether_gym_agents.accel import vec_env

    monkeypatch.setattr(vec_env, "MAX_RESET_DRAWS", draws)
    real = env._start_result

    def failing(inp, out):
        s = real(inp, out)
        return {**s, "ok": s["ok"] & ~rows}

    env._start_result = failing


@pytest.mark.parametrize("mode", ["next_step", "same_step"])
def test_a_row_whose_every_start_draw_fails_starts_failed(mode, monkeypatch):
    """As the numba env: a row whose every draw fails (3 here) starts failed, with the
    reason in ``info["failure"]`` from its reset on, and terminates at its first step
    with reward 0 and that code; the other rows start and step as usual, and the
    failed rows' later resets fail again."""
    from tether_gym.tasks.termination import Failure

    env = TorchTetherVecEnv(6, device=DEVICE, seed=4, autoreset_mode=mode, backend=BACKEND,
                            **TRAINING)
    bad = torch.tensor([False, True, False, False, True, False], device=DEVICE)
    _failing_starts(env, bad, monkeypatch)
    _, info = env.reset()
    assert torch.equal(env._start_failed, bad)
    assert (info["failure"][bad] == int(Failure.LENGTH)).all()
    assert (info["failure"][~bad] == 0).all()
    _, rew, term, trunc, info = env.step(torch.zeros((6, 2), device=DEVICE))
    assert torch.equal(term, bad) and not trunc.any() and (rew[bad] == 0).all()
    code = info["final_failure"] if mode == "same_step" else info["failure"]
    assert (code[bad] == int(Failure.LENGTH)).all() and (code[~bad] == 0).all()
    if mode == "next_step":  # the next step resets them, and their draws fail again
        env.step(torch.zeros((6, 2), device=DEVICE))
    assert torch.equal(env._start_failed, bad)


def test_bad_input_is_refused():
    with pytest.raises(TypeError, match="full_info"):
        TorchTetherVecEnv(2, full_info="no")
    env = TorchTetherVecEnv(4, device="cpu")
    with pytest.raises(RuntimeError, match="reset"):
        env.step(torch.zeros(4, 2))
    env.reset(seed=1)
    with pytest.raises(ValueError, match="shape"):
        env.step(torch.zeros(4, 3))
    with pytest.raises(ValueError, match="finite"):
        env.step(torch.full((4, 2), float("nan")))
    with pytest.raises(TypeError, match="real"):
        env.step(torch.zeros((4, 2), dtype=torch.bool))
    with pytest.raises(ValueError, match="num_envs"):
        TorchTetherVecEnv(0)
    with pytest.raises(ValueError, match=r"num_envs=4194305 must be in \[1, 4194304\]"):
        TorchTetherVecEnv(4194305)
    # before: None and meta tensors were RuntimeError/NotImplementedError tracebacks from
    # torch; seeds -1 and 1.5 were taken (1.5 as 1), 2**80 was "Overflow when unpacking
    # long long", "a" "invalid literal for int()"; check_actions="no" meant True
    for bad in (None, torch.zeros(4, 2, device="meta")):
        with pytest.raises(TypeError, match=r"actions must be an array of real numbers of "
                                            r"shape \(4, 2\)"):
            env.step(bad)
    for seed in (-1, 1.5, 2**80, "a", True):
        with pytest.raises(ValueError, match=r"seed=.* must be None or an integer in "
                                             r"\[0, 9223372036854775807\]"):
            env.reset(seed=seed)
        with pytest.raises(ValueError, match=r"seed=.* must be None or an integer"):
            TorchTetherVecEnv(2, seed=seed)
    with pytest.raises(TypeError, match="check_actions must be True or False, got 'no'"):
        TorchTetherVecEnv(2, check_actions="no")
    with pytest.raises(ValueError, match="unknown argument"):
        TorchTetherVecEnv(2, eccentricty=0.1)
    if not torch.cuda.is_available():
        with pytest.raises(ValueError, match="pip install"):
            TorchTetherVecEnv(2, device="cuda")


@pytest.mark.slow
@pytest.mark.parametrize("mode", ["next_step", "same_step", "same_step_sync_free"])
def test_compiled_step_equals_the_eager_step(mode):
    """``compile=True`` fuses the torch backend's step, its outputs and its reset
    attempts (torch.compile): over 40 steps of 6-step episodes with disturbance and
    noise (rows ending and reset in about every step, out of step with each other),
    the same trajectory to 1e-12, the same flags, and the same draws (the generator);
    and the pieces ran compiled."""
    from torch._dynamo.utils import counters

    torch._dynamo.reset()
    before = counters["stats"]["unique_graphs"]
    kwargs = {**TRAINING, "disturbance": 0.1, "obs_noise": 1e-3, "orbits_per_episode": 0.02}
    envs = [TorchTetherVecEnv(16, device="cpu", seed=4, compile=c, autoreset_mode=mode,
                              **kwargs) for c in (False, True)]
    for env in envs:
        env.reset()
        env.nu[::2] += env._plan.episode_length / 2  # half the rows half an episode ahead
    action = torch.as_tensor(np.random.default_rng(0).uniform(-1, 1, (40, 16, 2)))
    ended = 0
    for a in action:
        (o0, r0, t0, u0, i0), (o1, r1, t1, u1, i1) = (env.step(a) for env in envs)
        for name in ("nu", "y", "u", "tension", "derivative", "par", "noise"):
            np.testing.assert_allclose(getattr(envs[1], name).numpy(),
                                       getattr(envs[0], name).numpy(), rtol=1e-12,
                                       atol=1e-15, err_msg=name)
        np.testing.assert_allclose(r1.numpy(), r0.numpy(), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(o1.numpy(), o0.numpy(), rtol=2.0**-23, atol=1e-7)
        assert torch.equal(t0, t1) and torch.equal(u0, u1)
        assert torch.equal(i0["failure"], i1["failure"])
        assert torch.equal(envs[0].steps, envs[1].steps)
        ended += int((t0 | u0).sum())
    assert torch.equal(envs[0].generator.get_state(), envs[1].generator.get_state())
    assert ended >= 40
    # the step, the reset attempt, and with a same-step mode the step's outputs
    assert counters["stats"]["unique_graphs"] - before >= (2 if mode == "next_step" else 3)
