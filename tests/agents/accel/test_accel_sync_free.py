"""``TorchTetherVecEnv(autoreset_mode="same_step_sync_free")`` and ``train.py gpu
--sync-free``: the same-step autoreset without host syncs (one reset attempt every
step)."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from torch.utils._python_dispatch import TorchDispatchMode  # noqa: E402

from tether_gym_agents.accel.vec_env import TorchTetherVecEnv  # noqa: E402

# 6-step episodes, with disturbance and noise drawn every step
SHORT = {"increment_gain": 0.5, "orbits_per_episode": 0.02, "disturbance": 0.1,
         "obs_noise": 0.001, "init_theta_range": 0.15, "eccentricity_range": (0.0, 0.3),
         "mass_range": 0.25}
B = 6


class _Syncs(TorchDispatchMode):
    """Counts the reads of a tensor back to the host (``_local_scalar_dense``)."""

    def __init__(self):
        super().__init__()
        self.count = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        if func.overloadpacket.__name__ == "_local_scalar_dense":
            self.count += 1
        return func(*args, **(kwargs or {}))


def _env(backend: str, sync_free: bool = True, **kwargs) -> TorchTetherVecEnv:
    mode = "same_step_sync_free" if sync_free else "same_step"
    env = TorchTetherVecEnv(B, seed=11, autoreset_mode=mode, check_actions=False,
                            backend=backend, full_info=False, **{**SHORT, **kwargs})
    env.reset()
    env.nu[::2] += env._plan.episode_length / 2  # half the rows half an episode ahead
    return env


def _actions(steps: int) -> list:
    g = torch.Generator().manual_seed(5)
    return [torch.rand((B, 2), generator=g, dtype=torch.float64) * 2.0 - 1.0
            for _ in range(steps)]


def _parts(env: TorchTetherVecEnv, a) -> None:
    """One step through its parts, as the learner's RolloutStep calls them."""
    env.action_in.copy_(a)
    env.step_in_place()


@pytest.mark.parametrize("backend", ["torch", "numba"])
def test_every_step_draws_one_start_per_row_and_resets_the_ended_rows(backend):
    """Over 40 steps (6-step episodes, rows out of step: some steps end no episode), each
    step draws its disturbance and noise, then one start for every row, whether or not
    a row ended: the generator ends each step where those draws leave it. The rows that
    ended hold the start ``env.start`` makes of that step's draws (state, parameters,
    noise, command, tensions, observation: bitwise); the other rows keep the step's own
    state (the observation is the step's last one)."""
    env = _env(backend)
    num, n = env.num_envs, env.n
    ended_steps = quiet_steps = 0
    for a in _actions(40):
        replay = torch.Generator().set_state(env.generator.get_state())
        obs, _, term, trunc, info = env.step(a)
        ended = term | trunc
        # the step's draws, then the reset attempt's, from the state before the step
        torch.rand((num, n), generator=replay, dtype=torch.float64)
        torch.randn((num, 4 * n), generator=replay, dtype=torch.float64)
        own = env.generator
        env.generator = replay
        try:
            starts = env.start(env.draws(num))
        finally:
            env.generator = own
        assert torch.equal(replay.get_state(), env.generator.get_state())
        for name, key in (("y", "y"), ("par", "par"), ("noise", "noise"), ("u", "u"),
                          ("tension", "tension"), ("derivative", "derivative")):
            assert torch.equal(getattr(env, name)[ended], starts[key][ended]), name
        assert torch.equal(obs[ended], starts["obs"][ended])
        assert torch.equal(obs[~ended], info["final_obs"][~ended])
        assert bool((env.steps[ended] == 0).all()) and bool((env.steps[~ended] > 0).all())
        ended_steps += bool(ended.any())
        quiet_steps += not bool(ended.any())
    assert ended_steps >= 10 and quiet_steps >= 5


@pytest.mark.parametrize("backend", ["torch", "numba"])
def test_the_step_reads_nothing_back(backend):
    """The step's parts with ``sync_free`` read no tensor back to the host over 30 steps
    with resets (the default autoreset reads at least one flag per step)."""
    counts = {}
    for sync_free in (False, True):
        env = _env(backend, sync_free)
        with _Syncs() as syncs:
            for a in _actions(30):
                _parts(env, a)
        counts[sync_free] = syncs.count
    assert counts[True] == 0 and counts[False] >= 30


def test_a_failed_start_starts_failed_and_is_drawn_again_at_its_first_step(monkeypatch):
    """Row 1's every start fails, row 4's whenever its first angle is drawn positive: the
    row starts failed (no second draw in the step), terminates at its next step with
    reward 0 and the failure code of its start, and is reset in that step; row 4 also
    gets good starts. The other rows run as usual."""
    env = _env("torch")
    real = env._start_result
    rows = torch.arange(B)

    def start_result(inp, out):
        s = real(inp, out)
        bad = (rows == 1) | ((rows == 4) & (inp["y"][:, 0] > 0.0))
        return {**s, "ok": s["ok"] & ~bad}

    env._start_result = start_result
    failed_before = torch.zeros(B, dtype=torch.bool)
    seen = {1: 0, 4: 0}
    good_four = 0
    for a in _actions(60):
        _, reward, term, trunc, info = env.step(a)
        ended = term | trunc
        # a row that started failed ends at its first step, with reward 0 and its code
        assert bool(term[failed_before].all())
        assert bool((reward[failed_before] == 0.0).all())
        assert bool((info["final_failure"][failed_before] > 0).all())
        for row in seen:
            seen[row] += int(failed_before[row])
        good_four += int(ended[4] & ~env._start_failed[4])
        failed_before = env._start_failed & ended
        assert bool(failed_before[1]) == bool(ended[1])  # row 1 never starts well
    assert seen[1] >= 20 and seen[4] >= 2 and good_four >= 2
    assert not bool(env._start_failed[[0, 2, 3, 5]].any())


def test_the_modes_flags_and_refusals():
    """Each autoreset mode's flags; the step's parts and ``RolloutStep`` take both
    same-step modes and refuse ``"next_step"``; an unknown mode is refused."""
    from tether_gym_agents.accel.graphs import RolloutStep

    flags = {(mode, backend): (env.same_step, env.sync_free, env.whole_step_graph)
             for mode in ("next_step", "same_step", "same_step_sync_free")
             for backend in ("torch", "numba")
             for env in [TorchTetherVecEnv(2, autoreset_mode=mode, backend=backend)]}
    # one graph holds a whole step only without host syncs and without a host call (the
    # CPU's numba kernel); numba-cuda's on a GPU: test_accel_numba_cuda
    assert flags == {("next_step", "torch"): (False, False, False),
                     ("next_step", "numba"): (False, False, False),
                     ("same_step", "torch"): (True, False, False),
                     ("same_step", "numba"): (True, False, False),
                     ("same_step_sync_free", "torch"): (True, True, True),
                     ("same_step_sync_free", "numba"): (True, True, False)}
    env = TorchTetherVecEnv(2)
    env.reset()
    with pytest.raises(RuntimeError, match="need autoreset_mode='same_step' or "
                                           "'same_step_sync_free' \\(got 'next_step'\\)"):
        env.step_begin()
    with pytest.raises(ValueError, match="RolloutStep needs autoreset_mode='same_step' or "
                                         "'same_step_sync_free', got 'next_step'"):
        RolloutStep(None, env)
    with pytest.raises(ValueError, match="autoreset_mode='sync_free' must be one of"):
        TorchTetherVecEnv(2, autoreset_mode="sync_free")


@pytest.mark.parametrize("backend", ["torch", "numba"])
def test_a_graphed_sync_free_run_trains_what_the_eager_one_trains(tmp_path, monkeypatch,
                                                                  recorded_graphs,
                                                                  backend):
    """``train_seeds`` with ``sync_free`` and every graph of ``--cuda-graphs`` captured and
    replayed through RecordingCapture on the CPU: five iterations end with bitwise the
    eager sync-free run's weights and episode counts; and the sync-free run is not the
    default run (other draws). The torch backend's whole rollout (8 steps with their
    reset attempts, and the advantages) is one graph, so two are captured (with the
    update's), and a replay runs none of the env's Python; the numba backend's kernel
    is a host call, so its step's and reset attempt's pieces are graphs of their own
    (5), with the advantages' and the update's."""
    from tether_gym_agents.accel.ppo import PPOSettings
    from tether_gym_agents.accel.trainer import GpuRun, train_seeds
    from tether_gym_agents.files.safe_format import load_agent

    captures = recorded_graphs
    begins = [0]
    real_begin = TorchTetherVecEnv.step_begin

    def counted_begin(self):
        begins[0] += 1
        return real_begin(self)

    monkeypatch.setattr(TorchTetherVecEnv, "step_begin", counted_begin)
    settings = PPOSettings(n_envs=4, n_steps=8, batch_size=16, n_epochs=2,
                           net_arch=(16, 16))
    env_kwargs = {"increment_gain": 0.5, "orbits_per_episode": 0.02, "disturbance": 0.1,
                  "obs_noise": 0.001}
    out = {}
    for name, graphed, sync_free in (("default", False, False), ("eager", False, True),
                                     ("graphed", True, True)):
        run = GpuRun([0, 1], 5 * 8 * 4, env_kwargs, tmp_path / name, torch.device("cpu"),
                     checkpoints=5, eval_episodes=2, backend=backend, cuda_graphs=graphed,
                     sync_free=sync_free)
        begins[0] = 0
        summary = train_seeds(settings, run, log=None)
        if graphed and backend == "torch":
            assert len(captures) == 2
            assert begins[0] == 4 * 8  # 3 warm-up rollouts and the capture's, no replay's
        elif graphed:
            assert len(captures) == 7
            assert begins[0] == 3 + 1  # the step's first graph: 3 warm-up steps, the capture
        else:
            assert begins[0] == 5 * 8
        out[name] = (summary, [load_agent(tmp_path / name / f"seed_{k}")[0].state_dict()
                               for k in (0, 1)])
    (eager, w_eager), (graphed, w_graphed) = out["eager"], out["graphed"]
    assert sum(sum(h["episodes"]) for h in eager["history"]) >= 10
    for key in ("episodes", "failed", "mean_return"):
        assert [h[key] for h in eager["history"]] == [h[key] for h in graphed["history"]]
    for state_e, state_g in zip(w_eager, w_graphed, strict=True):
        assert all(torch.equal(state_e[k], state_g[k]) for k in state_e)
    w_default = out["default"][1]
    assert any(not torch.equal(w_default[0][k], w_eager[0][k]) for k in w_eager[0])
