"""The learner's pieces as CUDA graphs (``train.py gpu --cuda-graphs``), checked on the CPU.

A capture needs pieces free of host syncs and sorts (the minibatch step also of random
draws), fed through fixed inputs. The first is counted here with a dispatch mode. The
second is checked by capturing and replaying through :class:`RecordingCapture`, which
replays the recorded aten operations on the recorded tensors without running the
Python again, as a CUDA graph does: the results must be the eager ones, bitwise, for
the update, the rollout's pieces, the env's step and a whole ``train_seeds`` run. CUDA's
capture itself is run where torch sees a GPU (the device-parametrised tests and
``test_train_gpu_with_cuda_graphs_runs_on_a_gpu``), and skipped elsewhere (CI has none).
"""

from __future__ import annotations

from collections import Counter

import pytest

torch = pytest.importorskip("torch")

from torch.utils._python_dispatch import TorchDispatchMode  # noqa: E402

from tether_gym_agents.accel.graphs import (  # noqa: E402
    WARMUP_STEPS,
    CudaCapture,
    GraphedCall,
    GraphedUpdate,
    RecordingCapture,
)
from tether_gym_agents.accel.ppo import MultiSeedPolicy, PPOSettings  # noqa: E402
from tether_gym_agents.accel.rollout import Rollout, RolloutBatch  # noqa: E402
from tether_gym_agents.accel.trainer import (  # noqa: E402
    _minibatch_step,
    _minibatch_steps,
    _permutations,
    _update,
)

SYNCS = {"_local_scalar_dense", "item", "is_nonzero", "equal", "nonzero", "unique",
         "masked_select"}
"""aten operations that read a device tensor back to the host."""
DRAWS = {"rand", "randn", "normal", "uniform", "bernoulli", "random", "multinomial",
         "randint", "randperm", "sort", "argsort"}
"""Random draws and sorts (a capture keeps neither out of trouble: the orders come first)."""


class _Ops(TorchDispatchMode):
    """Counts aten operations by name while ``on``."""

    def __init__(self):
        super().__init__()
        self.on, self.ops = True, Counter()

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        if self.on:
            self.ops[func.overloadpacket.__name__.rstrip("_")] += 1
        return func(*args, **(kwargs or {}))


DEVICES = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
"""The CPU, through RecordingCapture; a GPU, where there is one, through CUDA's capture."""


def _capture(device):
    return RecordingCapture() if device == "cpu" else CudaCapture()


def _same(x, y, device) -> bool:
    """Bitwise on the CPU; on a GPU to float32 rounding (its kernels may sum in another
    order from run to run)."""
    if device == "cpu":
        return torch.equal(x, y)
    return bool(torch.allclose(x, y, rtol=1e-5, atol=1e-7))


def _learner(schedule="linear", seeds=(3, 4), obs_dim=6, act_dim=2, fused=False,
             device="cpu"):
    """Settings, policy, Adam and rates; ``fused``: the fused Adam, which on the CPU keeps
    its step count on the device as CUDA's capturable Adam does (the CPU's default one
    reads it back to the host); on a GPU the capturable fused Adam."""
    settings = PPOSettings(n_envs=8, n_steps=4, batch_size=8, n_epochs=2, lr_schedule=schedule,
                           net_arch=(16, 16), log_std_init=-1.0)
    policy = MultiSeedPolicy(list(seeds), obs_dim, act_dim, settings, device)
    opt = torch.optim.Adam(policy.parameters(), lr=1.0, eps=1e-5, fused=fused,
                           capturable=device != "cpu")
    lr = torch.full((len(seeds),), 3e-3, device=device)
    return settings, policy, opt, lr


def _rollout(g, T, S, N, d, a, device="cpu"):
    """Random rollout buffers (T, S, N, ...) as the trainer fills them."""
    return tuple(x.to(device) for x in (
        torch.randn((T, S, N, d), generator=g), torch.randn((T, S, N, a), generator=g),
        torch.randn((T, S, N), generator=g) - 2.0, torch.randn((T, S, N), generator=g),
        torch.randn((T, S, N), generator=g)))


@pytest.mark.parametrize("schedule", ["linear", "adaptive"])
def test_the_minibatch_step_needs_no_host_sync_and_draws_nothing(schedule):
    """The step's own operations (the CPU's Adam aside: CUDA's capturable Adam is
    another) include no read-back to the host, no random draw and no sort."""
    settings, policy, opt, lr = _learner(schedule)
    batch = RolloutBatch(4, 2, 8, 6, 2, "cpu")
    batch.fill(*_rollout(torch.Generator().manual_seed(0), 4, 2, 8, 6, 2))
    idx = _permutations(1, 2, 32, "cpu")[0, :, :8]
    counter = _Ops()
    real_step = opt.step

    def uncounted_step(*args, **kwargs):
        counter.on = False
        try:
            return real_step(*args, **kwargs)
        finally:
            counter.on = True

    opt.step = uncounted_step
    with counter:
        _minibatch_step(policy, opt, lr, settings, batch.tensors(), idx)
    assert counter.ops["bmm"] > 0 and counter.ops["tanh_backward"] > 0  # it saw the step
    assert not {k: n for k, n in counter.ops.items() if k in SYNCS | DRAWS}


def test_rollout_batch_is_the_flattened_rollout():
    """fill() writes (T, S, N, ...) seed-major in (time, env) order, in the same storage."""
    T, S, N, d, a = 3, 2, 5, 4, 2
    batch = RolloutBatch(T, S, N, d, a, "cpu")
    where = [t.data_ptr() for t in batch.tensors()]
    for k in range(2):
        rollout = _rollout(torch.Generator().manual_seed(k), T, S, N, d, a)
        batch.fill(*rollout)
        for got, src in zip(batch.tensors(), rollout, strict=True):
            assert torch.equal(got, src.transpose(0, 1).reshape(S, T * N, *src.shape[3:]))
        assert [t.data_ptr() for t in batch.tensors()] == where
    assert torch.equal(batch.obs[1, 2 * N + 3], rollout[0][2, 1, 3])


def test_permutations_are_one_argsort_of_rand_per_epoch():
    """The orders drawn up front are the draws of one ``argsort(rand)`` per epoch."""
    torch.manual_seed(5)
    perms = _permutations(3, 2, 7, "cpu")
    torch.manual_seed(5)
    for e in range(3):
        assert torch.equal(perms[e], torch.argsort(torch.rand((2, 7)), dim=1))
        assert torch.equal(perms[e].sort(dim=1).values, torch.arange(7).expand(2, 7))


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize(("N", "schedule"), [(8, "linear"), (9, "adaptive")])
def test_a_replayed_update_is_the_eager_update(N, schedule, device):
    """Six iterations of ``_update`` on fresh rollouts, the last three by replays of the
    graphed update (its 8 or 10 minibatch steps in one graph): the weights, Adam's
    moments and the rates end as with the eager update (bitwise on the CPU). With 9
    envs x 4 steps the last minibatch of an epoch is 4 rows, not 8."""
    T, S, d, a = 4, 2, 6, 2
    results = []
    for graphed in (False, True):
        settings, policy, opt, lr = _learner(schedule, fused=True, device=device)
        steps = GraphedUpdate(_minibatch_steps, _capture(device)) if graphed \
            else _minibatch_steps
        batch = RolloutBatch(T, S, N, d, a, device)
        g = torch.Generator().manual_seed(11)
        torch.manual_seed(7)
        for _ in range(WARMUP_STEPS + 3):
            batch.fill(*_rollout(g, T, S, N, d, a, device))
            _update(policy, opt, lr, settings, batch, steps)
        if graphed:
            assert steps.captured == 1
        moments = [opt.state[p][k] for p in policy.parameters() for k in ("exp_avg",
                                                                             "exp_avg_sq")]
        results.append([*(p.detach() for p in policy.parameters()), *moments, lr])
    eager, replayed = results
    assert all(_same(x, y, device) for x, y in zip(eager, replayed, strict=True))
    assert not torch.equal(eager[0].cpu(), _learner(schedule)[1].pi_w[0])  # it trained


@pytest.mark.parametrize("device", DEVICES)
def test_the_rollouts_pieces_replay_as_called(device):
    """Five rollouts of 6 steps on made-up env steps (episodes ending, some truncated):
    with ``act``, ``observe`` and ``finish`` graphed, everything that does not depend on
    the sampled actions (statistics, normalised observations, values, scaled and
    bootstrapped rewards, advantages, returns, episode counts) is as when they are
    called, and what does (the actions, their log-probabilities) is consistent with the
    recorded observations at every step."""
    S, N, T, d, a = 2, 5, 6, 4, 2
    settings = PPOSettings(n_envs=N, n_steps=T, net_arch=(8, 8), log_std_init=-1.0)
    g = torch.Generator().manual_seed(3)
    steps = [(torch.randn((S * N, d), generator=g, dtype=torch.float64) * 2.0 + 1.0,
              torch.randn(S * N, generator=g, dtype=torch.float64),
              torch.rand(S * N, generator=g) < 0.1, torch.rand(S * N, generator=g) < 0.15,
              torch.randn((S * N, d), generator=g, dtype=torch.float64))
             for _ in range(5 * T + 1)]
    out = []
    for graphed in (False, True):
        torch.manual_seed(0)
        policy = MultiSeedPolicy([1, 2], d, a, settings, device)
        rollout = Rollout(policy, settings, d, a, device)
        rollout.start(steps[0][0].to(device))
        pieces = [rollout.act, rollout.observe, rollout.finish]
        if graphed:
            pieces = [GraphedCall(f, _capture(device)) for f in pieces]
        act, observe, finish = pieces
        actions = []
        with torch.no_grad():
            for k in range(5):  # finish() is captured at its call 4
                for t in range(T):
                    act()
                    actions.append(rollout.action.clone())
                    rollout.take(*(x.to(device) for x in steps[1 + k * T + t]))
                    observe()
                finish()
                logp = policy.distribution(rollout.batch.obs).log_prob(
                    rollout.batch.act).sum(-1)   # all steps at once: not bitwise
                assert torch.allclose(logp, rollout.batch.logp, rtol=1e-5, atol=1e-6)
                assert _same(torch.stack(actions[-T:]).transpose(0, 1).reshape(S, T * N, a),
                             rollout.batch.act.clamp(-1.0, 1.0), device)
        if graphed:
            assert all(piece.captured for piece in pieces)
        out.append([rollout.obs_stats.mean, rollout.obs_stats.var, rollout.ret_stats.var,
                    rollout.obs, rollout.buf_val, rollout.buf_rew, rollout.batch.adv,
                    rollout.batch.ret, rollout.done_eps, rollout.done_ret, rollout.t])
    assert all(_same(x, y, device) for x, y in zip(*out, strict=True))
    assert out[0][8].sum() > 0 and int(out[0][10]) == 0


def _env_backends(device):
    if device == "cpu":
        return ["torch", "numba"]
    from tether_gym_agents.accel import numba_cuda

    try:
        numba_cuda.load_cuda()
    except ImportError:
        return ["torch"]
    return ["torch", "numba-cuda"]


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("failing", [False, True])
def test_the_envs_step_parts_replay_as_its_step(device, failing, monkeypatch):
    """The env's same-step autoreset step as :class:`RolloutStep` runs it (a graph
    before the kernel, one after it with a numba backend; the autoreset's attempts the
    same way, its host syncs eager): 60 steps of 6-step episodes with disturbance and
    noise drawn, half the rows out of step with the others (20 resets, the last 17 run
    by replays), give the observations, rewards, flags, costs, last observations and
    failure codes of ``env.step`` (bitwise on the CPU), and the same generator state.
    ``failing``: every start of row 1 fails, and a start of row 4 whenever its first
    angle is drawn positive, with 3 draws per reset: attempts repeated, rows starting
    failed. On a GPU, through CUDA's capture: the draws inside a graph should be the
    eager ones there too (a replay starts from the generator's offset and adds each
    draw's increment in order, as eager code does), and this checks it."""
    from tether_gym_agents.accel import vec_env
    from tether_gym_agents.accel.vec_env import TorchTetherVecEnv

    kwargs = {"increment_gain": 0.5, "orbits_per_episode": 0.02, "disturbance": 0.1,
              "obs_noise": 0.001, "init_theta_range": 0.15}
    if failing:
        monkeypatch.setattr(vec_env, "MAX_RESET_DRAWS", 3)
    g = torch.Generator().manual_seed(5)
    actions = [torch.rand((6, 2), generator=g) * 2.0 - 1.0 for _ in range(60)]
    for backend in _env_backends(device):
        runs = []
        for graphed in (False, True):
            env = TorchTetherVecEnv(6, device=device, seed=11, autoreset_mode="same_step",
                                    check_actions=False, backend=backend, full_info=False,
                                    **kwargs)
            if failing:
                real = env._start_result
                rows = torch.arange(6, device=device)

                def start_result(inp, out, real=real, rows=rows):
                    s = real(inp, out)
                    bad = (rows == 1) | ((rows == 4) & (inp["y"][:, 0] > 0.0))
                    return {**s, "ok": s["ok"] & ~bad}

                env._start_result = start_result
            env.reset()
            # half the rows half an episode ahead: each reset is of other rows than the last
            env.nu[::2] += env._plan.episode_length / 2
            draws = (env.generator,)
            begin = GraphedCall(env.step_begin, _capture(device), draws)
            end = GraphedCall(env.step_end, _capture(device))
            reset_begin = GraphedCall(env.reset_begin, _capture(device), draws)
            reset_end = GraphedCall(env.reset_end, _capture(device))
            seen = []
            for a in actions:
                if graphed:
                    env.action_in.copy_(a.to(device))
                    begin()
                    env.step_kernel()
                    if backend != "torch":
                        end()
                    env.step_autoreset(reset_begin, reset_end)
                    o = env.outputs
                    out = (env.obs, o.reward, o.terminated, o.truncated, o.cost,
                           o.final_obs, o.final_failure)
                else:
                    obs, rew, term, trunc, info = env.step(a.to(device))
                    cost = torch.stack([info[k] for k in ("cost", "cost_slack",
                                                          "cost_length", "cost_tumble")], 1)
                    out = (obs, rew, term, trunc, cost, info["final_obs"],
                           info["final_failure"])
                seen.append([x.clone() for x in out])
            if graphed:
                assert begin.captured and reset_begin.captured
                assert (end.captured and reset_end.captured) or backend == "torch"
            runs.append((seen, env.generator.get_state()))
        (eager, state_e), (graph, state_g) = runs
        ends = [step[2] | step[3] for step in eager]
        assert sum(int(e.any()) for e in ends) >= 3 * WARMUP_STEPS
        assert any(e.any() and not e.all() for e in ends[2 * WARMUP_STEPS:])
        for step_e, step_g in zip(eager, graph, strict=True):
            for x, y in zip(step_e, step_g, strict=True):
                assert x.dtype == y.dtype and _same(x, y, device)
        if device == "cpu":
            assert torch.equal(state_e, state_g)


def test_the_step_parts_need_same_step_autoreset():
    """The parts are the same-step autoreset step's; RolloutStep refuses another."""
    from tether_gym_agents.accel.graphs import RolloutStep
    from tether_gym_agents.accel.vec_env import TorchTetherVecEnv

    env = TorchTetherVecEnv(2)
    env.reset()
    with pytest.raises(RuntimeError, match="same_step"):
        env.step_begin()
    with pytest.raises(ValueError, match="same_step"):
        RolloutStep(None, env)


def test_a_replay_whose_inputs_moved_is_refused():
    """A rollout in new storage after the capture would be read stale by a replay."""
    settings, policy, opt, lr = _learner(fused=True)
    batch = RolloutBatch(4, 2, 8, 6, 2, "cpu")
    batch.fill(*_rollout(torch.Generator().manual_seed(0), 4, 2, 8, 6, 2))
    steps = GraphedUpdate(_minibatch_steps, RecordingCapture())
    orders = _permutations(1, 2, 32, "cpu")
    for _ in range(WARMUP_STEPS + 1):
        steps(policy, opt, lr, settings, batch.tensors(), orders)
    assert steps.captured == 1
    moved = tuple(t.clone() for t in batch.tensors())
    with pytest.raises(RuntimeError, match="moved since the capture"):
        steps(policy, opt, lr, settings, moved, orders)


def test_the_stand_in_keeps_a_graphs_rules():
    """RecordingCapture is a CUDA graph's rules, not a second call: its capture changes
    nothing, a replay reads the tensors the capture read (a tensor that Python rebinds
    afterwards is not seen; one refilled in place is), Python numbers stay as captured,
    and a host sync cannot be captured."""
    state = {"x": torch.ones(3), "k": 2.0}
    total = torch.zeros(3)

    def fn():
        total.add_(state["x"] * state["k"])

    replay = RecordingCapture().capture(fn)
    assert torch.equal(total, torch.zeros(3))       # capturing ran nothing
    replay()
    assert torch.equal(total, torch.full((3,), 2.0))
    state["x"].fill_(5.0)                            # refilled in place: seen
    state["k"] = 100.0                               # a Python number: fixed at capture
    replay()
    assert torch.equal(total, torch.full((3,), 12.0))
    state["x"] = torch.full((3,), 7.0)               # rebound: the replay reads the old one
    replay()
    assert torch.equal(total, torch.full((3,), 22.0))
    with pytest.raises(RuntimeError, match="host sync"):
        RecordingCapture().capture(lambda: float(total.sum()))


def test_the_cpus_default_adam_cannot_be_captured():
    """The CPU's default Adam reads its step count back to the host, as CUDA's Adam does
    without ``capturable=True``: a capture of the step fails, where the trainer's
    ``--cuda-graphs`` asks for the capturable one."""
    settings, policy, opt, lr = _learner()
    batch = RolloutBatch(4, 2, 8, 6, 2, "cpu")
    batch.fill(*_rollout(torch.Generator().manual_seed(0), 4, 2, 8, 6, 2))
    steps = GraphedUpdate(_minibatch_steps, RecordingCapture())
    orders = _permutations(1, 2, 32, "cpu")
    for _ in range(WARMUP_STEPS):
        steps(policy, opt, lr, settings, batch.tensors(), orders)
    with pytest.raises(RuntimeError, match="host sync"):
        steps(policy, opt, lr, settings, batch.tensors(), orders)


@pytest.mark.parametrize("backend", ["numba", "torch"])
def test_a_graphed_run_trains_what_the_eager_run_trains(tmp_path, recorded_graphs, backend):
    """``train_seeds`` with every graph of ``--cuda-graphs`` (the rollout step, the env's
    step included: one graph before the env's kernel, with the numba backend one after
    it, one after the autoreset; the reset attempts; the advantages; the update),
    captured and replayed through RecordingCapture on the CPU: five iterations, each
    piece captured after its warm-up, episodes ending and reset between replays, end
    with bitwise the eager run's weights, statistics and episode counts. Both runs use
    the CPU's fused Adam, which keeps its step count on the device as CUDA's capturable
    Adam does."""
    from tether_gym_agents.accel.trainer import GpuRun, train_seeds
    from tether_gym_agents.files.safe_format import load_agent

    captures = recorded_graphs
    settings = PPOSettings(n_envs=4, n_steps=8, batch_size=16, n_epochs=2,
                           net_arch=(16, 16))
    summaries, weights = [], []
    for graphed in (False, True):
        out = tmp_path / ("graphed" if graphed else "eager")
        # episodes of 6 steps: truncations, bootstraps and restarts in the run (the resets
        # captured at their 4th attempt, replayed from the 5th); the disturbance and the
        # noise are drawn inside the first graph of the step
        env_kwargs = {"increment_gain": 0.5, "orbits_per_episode": 0.02, "disturbance": 0.1,
                      "obs_noise": 0.001}
        run = GpuRun([0, 1], 5 * 8 * 4, env_kwargs, out, torch.device("cpu"),
                     checkpoints=5, eval_episodes=2, backend=backend, cuda_graphs=graphed)
        summaries.append(train_seeds(settings, run, log=None))
        weights.append([load_agent(out / f"seed_{k}") for k in (0, 1)])
    # the step's 3 graphs and the reset's 2 (2 and 1 with the torch backend), finish,
    # the update
    assert len(captures) == (7 if backend == "numba" else 5)
    eager, graphed = summaries
    assert sum(sum(h["episodes"]) for h in eager["history"]) >= 10
    for key in ("episodes", "failed", "mean_return"):
        assert [h[key] for h in eager["history"]] == [h[key] for h in graphed["history"]]
    assert eager["final"] == graphed["final"]
    for (p_e, meta_e), (p_g, meta_g) in zip(*weights, strict=True):
        state_e, state_g = p_e.state_dict(), p_g.state_dict()
        assert all(torch.equal(state_e[k], state_g[k]) for k in state_e)
        norm_e, norm_g = meta_e["obs_normalization"], meta_g["obs_normalization"]
        assert all((norm_e[k] == norm_g[k]).all() for k in ("mean", "var"))
        assert norm_e["count"] == norm_g["count"] > 5 * 8 * 4


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
@pytest.mark.parametrize("flags", [[], ["--sync-free"],
                                   ["--sync-free", "--backend", "numba-cuda"]])
def test_train_gpu_with_cuda_graphs_runs_on_a_gpu(tmp_path, flags):
    """On a GPU: ``train.py gpu --cuda-graphs`` trains five iterations (every piece
    captured and replayed) and writes agents with finite weights; with ``--sync-free``
    the whole rollout is one graph, on numba-cuda its kernel launches included. (Its
    samples are drawn inside the graphs, so its weights are not the eager run's: the
    pieces' equality is the device-parametrised tests' above.)"""
    from tether_gym_agents.cli.train import main as train_main
    from tether_gym_agents.files.safe_format import load_agent

    if "numba-cuda" in flags:
        pytest.importorskip("numba_cuda")
    out = tmp_path / "graphs"
    assert train_main(["gpu", "--device", "cuda", "--out", str(out), "--n-envs", "16",
                       "--seeds", "2", "--timesteps", str(16 * 64 * 5), "--cuda-graphs",
                       *flags]) == 0
    for k in (0, 1):
        state = load_agent(out / f"seed_{k}")[0].state_dict()
        assert all(torch.isfinite(w).all() for w in state.values())
