"""One GPU PPO run: S seeds trained at once on one device, each written as a seed run folder.

Per seed ``OUT/seed_K/`` holds what ``python evaluate.py OUT`` reads (``agent.json`` +
``policy.safetensors``: the agent at the last step), its checkpoints
(``checkpoints/agent_<N>_steps/``, each recording its env steps and the wall time then,
for ``python evaluate.py curves OUT``), ``train_info.json`` (steps, wall time, device),
``config.yml`` and ``command.txt``. Wall times count from the start of the call
(process start-up, imports and compilation included, as the issue's targets count
them), and the training rollouts' episode statistics go into ``train_log.json``.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

import tether_gym

from ..files.run_folder import (
    CHECKPOINT_AGENT_PREFIX,
    CHECKPOINT_DIR,
    COMMAND_FILE,
    CONFIG_FILE,
    ITERATION_LOG_FILE,
    TRAIN_INFO_FILE,
    append_command,
    check_fresh_run_folder,
    check_writable_folder,
    seed_dir,
    write_config,
    write_text_atomic,
    write_train_info,
)
from ..files.safe_format import AGENT_FILE, WEIGHTS_FILE, ObsNormalization, save_agent
from .graphs import GraphedCall, GraphedUpdate, RolloutStep
from .minibatch import (
    ADAM_EPS,
    CompiledSteps,
    PerSeedAdam,
    adapt_rates,
    minibatch_loss,
    minibatches,
    take,
)
from .ppo import MultiSeedPolicy, PPOSettings, learning_rate_at
from .rollout import Rollout, RolloutBatch, normalize
from .vec_env import TorchTetherVecEnv

__all__ = ["train_seeds", "GpuRun", "progress_remaining", "check_out"]

WRITTEN_FILES = (AGENT_FILE, WEIGHTS_FILE, TRAIN_INFO_FILE, CONFIG_FILE, COMMAND_FILE,
                 ITERATION_LOG_FILE)
"""The files each ``OUT/seed_K/`` gets at its top (besides ``checkpoints/``)."""


def check_out(out: Path, seeds: list[int]) -> None:
    """Refuse an ``--out`` that the run could not write, or that holds an earlier run.

    ``out`` must be a folder (or not exist yet), and every ``out/seed_K`` a fresh run
    folder (:func:`check_fresh_run_folder`): this learner has no resume, so its
    checkpoints would land beside an earlier run's and ``evaluate.py curves`` would read
    both. Called before any work starts; it makes the folders.

    Raises
    ------
    ValueError
        Naming the folder and what is wrong.
    """
    out = Path(out)
    try:
        check_writable_folder(out, ())
    except ValueError as exc:
        raise ValueError(f"--out {str(out)!r}: {exc}") from None
    for folder in (seed_dir(out, k) for k in seeds):
        try:
            check_fresh_run_folder(folder, WRITTEN_FILES, "give a new --out, or remove "
                                   "that folder first (this learner has no --resume)")
        except ValueError as exc:
            raise ValueError(f"--out {str(out)!r}: {folder}: {exc}") from None


def _sb3_policy(policy: MultiSeedPolicy, s: int, env: TorchTetherVecEnv, settings: PPOSettings):
    """Seed s's weights in a stable-baselines3 ``ActorCriticPolicy`` (for save_agent)."""
    from stable_baselines3.common.policies import ActorCriticPolicy

    sb3 = ActorCriticPolicy(env.single_observation_space, env.single_action_space,
                            lambda _: 0.0, net_arch=list(settings.net_arch),
                            log_std_init=settings.log_std_init)
    sb3.load_state_dict(policy.sb3_state_dict(s), strict=True)
    return sb3


def _write_agents(runs, policy, stats, env, settings, env_kwargs, training, folder):
    """Save every seed's agent into ``run / folder`` (the run's top for ``"."``)."""
    for s, run in enumerate(runs):
        norm = ObsNormalization(stats.mean[s].cpu().numpy(), stats.var[s].cpu().numpy(),
                                float(stats.count[s]), settings.clip_obs, settings.norm_epsilon)
        save_agent(run / folder, _sb3_policy(policy, s, env, settings), "ppo", norm,
                   env_id=tether_gym.ENV_ID, env_kwargs=env_kwargs,
                   training={**training[s], "seed": policy.seeds[s]})


@dataclass(frozen=True)
class GpuRun:
    """What one ``train.py gpu`` call trains and where (besides the PPO settings).

    ``seeds``: trained at once; ``timesteps``: env steps per seed; ``max_seconds``: stop
    after the first update that ends later than this wall time [s] (counted from
    ``clock_start``), the runs then record the steps they reached, and a linear learning
    rate falls to 0 there (:func:`progress_remaining`); ``checkpoints``:
    agent snapshots per run; ``eval_episodes``: the final check's episodes per seed;
    ``compile``: the env's torch arithmetic through ``torch.compile``; ``backend``: the
    env's step backend (:class:`TorchTetherVecEnv`, both; the final check runs it too,
    eager);
    ``cuda_graphs``: the rollout's pieces and the minibatch step captured as CUDA graphs
    and replayed (:mod:`.graphs`; CUDA devices, or the CPU through
    :class:`~.graphs.RecordingCapture` in the tests); ``compile_update``: the minibatch
    steps' arithmetic fused by ``torch.compile`` (:mod:`.minibatch`: the loss's forward and
    backward graphs, and the clipping, Adam and per-seed rates in one function);
    ``compile_rollout``: the rollout's arithmetic fused by ``torch.compile`` (the policy's
    half of a step after its eager draws, the learner's half and the advantages:
    :class:`~.rollout.Rollout` with ``compiled``); ``sync_free``: the env's autoreset
    without host syncs (:class:`TorchTetherVecEnv`'s ``"same_step_sync_free"``: one
    reset attempt every step, a failed start starts failed), so that the host queues
    the rollout's steps without waiting for the device.
    """

    seeds: list[int]
    timesteps: int
    env_kwargs: dict
    out: Path
    device: torch.device
    checkpoints: int = 10
    command: str = ""
    clock_start: float | None = None
    max_seconds: float = math.inf
    eval_episodes: int = 64
    compile: bool = False
    backend: str = "torch"
    cuda_graphs: bool = False
    compile_update: bool = False
    compile_rollout: bool = False
    sync_free: bool = False


def train_seeds(settings: PPOSettings, run: GpuRun, log=print) -> dict:
    """Train ``len(run.seeds)`` PPO seeds for ``run.timesteps`` env steps each; write them.

    Returns a summary (steps, wall time, env steps per second, the checkpoints' episode
    statistics, the final check on the training distribution).
    """
    seeds, timesteps, env_kwargs, out, device = (run.seeds, run.timesteps, run.env_kwargs,
                                                 run.out, run.device)
    checkpoints, command, clock_start = run.checkpoints, run.command, run.clock_start
    max_seconds, eval_episodes = run.max_seconds, run.eval_episodes
    t0 = time.perf_counter() if clock_start is None else clock_start
    S, N, T = len(seeds), settings.n_envs, settings.n_steps
    torch.manual_seed(int(seeds[0]))
    autoreset = "same_step_sync_free" if run.sync_free else "same_step"
    env = TorchTetherVecEnv(S * N, device=device, seed=int(seeds[0]) * 7919 + S,
                            autoreset_mode=autoreset, check_actions=False,
                            compile=run.compile, backend=run.backend, full_info=False,
                            **env_kwargs)
    d, a = env.observation_dim, env.n
    policy = MultiSeedPolicy(seeds, d, a, settings, device)
    # lr 1: each seed's rate scales its Adam step instead (see _minibatch_step), so that the
    # seeds of one optimizer can have their own (adaptive) learning rates
    opt: torch.optim.Adam | PerSeedAdam
    if run.compile_update:  # clipping, Adam and the rates in one compiled function
        opt = PerSeedAdam(policy.parameters(), settings.max_grad_norm)
    else:
        opt = torch.optim.Adam(policy.parameters(), lr=1.0, eps=ADAM_EPS,
                               fused=device.type == "cuda",
                               capturable=run.cuda_graphs and device.type == "cuda")
    rollout = Rollout(policy, settings, d, a, device, compiled=run.compile_rollout)
    obs_stats = rollout.obs_stats
    runs = [seed_dir(out, k) for k in seeds]
    for folder in runs:
        folder.mkdir(parents=True, exist_ok=True)
        write_config(folder, {"algo": "ppo_gpu", "env_id": tether_gym.ENV_ID,
                              "hyperparams": {**asdict(settings),
                                              "net_arch": list(settings.net_arch),
                                              "n_timesteps": timesteps},
                              "env_kwargs": env_kwargs})
        if command:
            append_command(folder, command)
    raw, _ = env.reset()
    rollout.start(raw)
    collect = _collector(rollout, env, T, run.cuda_graphs)
    minibatch_steps: Callable[..., None] = (CompiledSteps() if run.compile_update
                                            else _minibatch_steps)
    if run.cuda_graphs:  # captured after its warm-up calls, then replayed
        minibatch_steps = GraphedUpdate(minibatch_steps)
    per_rollout = T * N
    n_updates = max(1, math.ceil(timesteps / per_rollout))
    marks = sorted({max(1, round(n_updates * (i + 1) / checkpoints))
                    for i in range(max(1, checkpoints))})
    history: list[dict[str, Any]] = []
    steps = 0
    lr = torch.full((S,), settings.learning_rate, device=device)  # adaptive: per seed
    startup = math.nan  # [s] from t0 to the end of the first update (compiles, captures)
    for update in range(1, n_updates + 1):
        progress = progress_remaining(steps / (n_updates * per_rollout),
                                      time.perf_counter() - t0, max_seconds, startup)
        if settings.lr_schedule != "adaptive":
            lr.fill_(learning_rate_at(settings, progress))
        with torch.no_grad():
            collect()
        steps += per_rollout
        _update(policy, opt, lr, settings, rollout.batch, minibatch_steps)
        if update == 1:
            startup = time.perf_counter() - t0
        out_of_time = time.perf_counter() - t0 > max_seconds
        if update in marks or out_of_time:
            wall = time.perf_counter() - t0
            eps = rollout.done_eps
            record: dict[str, Any] = {"steps": steps, "wall_time_s": round(wall, 2),
                      "episodes": eps.tolist(), "failed": rollout.done_fail.tolist(),
                      "mean_return": (rollout.done_ret / eps.clamp(min=1)).tolist()}
            history.append(record)
            rollout.clear_counts()
            training = [{"command": command, "num_timesteps": steps,
                         "wall_time_s": round(wall, 1), "device": str(device)}] * S
            _write_agents(runs, policy, obs_stats, env, settings, env_kwargs, training,
                          f"{CHECKPOINT_DIR}/{CHECKPOINT_AGENT_PREFIX}_{steps}_steps")
            if log:
                rate = steps * S / max(wall, 1e-9)
                log(f"  {steps} steps per seed, {wall:.1f} s ({rate:,.0f} env steps/s over "
                    f"{S} seeds); training episodes ended {int(sum(record['episodes']))}, "
                    f"failed {int(sum(record['failed']))}, mean return "
                    f"{np.mean(record['mean_return']):.1f}")
        if out_of_time:
            if log:
                log(f"  stopped at {steps} steps per seed: --max-seconds {max_seconds:g} reached")
            break
    wall = time.perf_counter() - t0
    training = [{"command": command, "num_timesteps": steps, "wall_time_s": round(wall, 1),
                 "device": str(device)}] * S
    final = evaluate_on_device(policy, obs_stats, settings, env_kwargs, device,
                               episodes=eval_episodes, seed=int(seeds[0]) + 10_000,
                               backend=run.backend)
    _write_agents(runs, policy, obs_stats, env, settings, env_kwargs, training, ".")
    device_name = (torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu")
    for s, folder in enumerate(runs):
        write_train_info(folder, {"algo": "ppo_gpu", "env_id": tether_gym.ENV_ID,
                               "seed": seeds[s], "seeds_in_process": S, "device": device_name,
                               "backend": run.backend, "command": command,
                               "tether_gym": tether_gym.__version__,
                               "torch": torch.__version__, "status": "finished",
                               "num_timesteps": steps, "wall_time_s": round(wall, 1),
                               "final_training_distribution": {
                                   k: v[s] for k, v in final.items()}})
        write_text_atomic(folder / ITERATION_LOG_FILE, json.dumps(
            [{**h, "episodes": h["episodes"][s], "failed": h["failed"][s],
              "mean_return": h["mean_return"][s]} for h in history], indent=1))
    return {"steps_per_seed": steps, "seeds": S, "wall_time_s": wall,
            "env_steps_per_s": steps * S / wall, "history": history, "final": final}


def evaluate_on_device(policy, obs_stats, settings, env_kwargs, device, episodes: int,
                       seed: int, backend: str = "torch") -> dict[str, list[float]]:
    """Each seed's deterministic policy over ``episodes`` whole episodes, on the device.

    :func:`deterministic_episodes` with the seeds' normalised mean actions, on the env
    ``backend`` (the training run's).
    """
    def act(raw: torch.Tensor) -> torch.Tensor:
        return policy.mean_action(normalize(raw, obs_stats, settings))

    return deterministic_episodes(act, len(policy.seeds), env_kwargs, device, episodes, seed,
                                  backend=backend)


def deterministic_episodes(act, groups: int, env_kwargs, device, episodes: int,
                           seed: int, backend: str = "torch") -> dict[str, list[float]]:
    """``groups`` policies over ``episodes`` whole episodes each, on the device.

    ``act(raw_obs)`` maps the raw observations (groups, episodes, obs_dim) to actions
    (groups, episodes, n), clipped to [-1, 1] here. The training distribution
    (``env_kwargs``), not a benchmark suite: a check of a run itself. Returns per group
    the mean episode return, the fraction of episodes that survive and the RMS of
    theta - theta_d over the survivors' steps after orbit 1. The env steps on
    ``backend`` (:class:`TorchTetherVecEnv`'s, eager): a numba backend's step is one
    kernel call where the torch port's is hundreds of operations (on a GPU, as many
    launches); the backends are equal to 1e-12 per step.
    """
    S = groups
    env = TorchTetherVecEnv(S * episodes, device=device, seed=seed, check_actions=False,
                            backend=backend, **env_kwargs)
    d, a = env.observation_dim, env.n
    raw, _ = env.reset()
    alive = torch.ones((S, episodes), dtype=torch.bool, device=device)
    survived = torch.ones_like(alive)
    ret = torch.zeros((S, episodes), dtype=torch.float64, device=device)
    sq = torch.zeros_like(ret)
    count = torch.zeros_like(ret)
    per_orbit = env.config.max_episode_steps / env.config.orbits_per_episode
    with torch.no_grad():
        for t in range(env.config.max_episode_steps):
            action = torch.clamp(act(raw.view(S, episodes, d)), -1.0, 1.0).to(torch.float64)
            raw, rew, term, trunc, info = env.step(action.reshape(S * episodes, a))
            rew, term, trunc = (x.view(S, episodes) for x in (rew, term, trunc))
            ret += torch.where(alive, rew, torch.zeros_like(rew))
            if t >= per_orbit:
                err = (info["theta"] - info["theta_ref"][:, None]).view(S, episodes, a)
                sq += torch.where(alive, err.square().mean(-1), torch.zeros_like(ret))
                count += alive.double()
            survived &= ~(term & alive)
            alive &= ~(term | trunc)
    ok = survived.double()
    steps = (count * ok).sum(1)
    rms = torch.sqrt((sq * ok).sum(1) / steps.clamp(min=1))
    return {"mean_return": ret.mean(1).tolist(), "survived": ok.mean(1).tolist(),
            # None: no episode survived past orbit 1 (no figure, rather than a fake 0)
            "tracking_rms": [float(r) if n > 0 else None for r, n in zip(rms, steps,
                                                                       strict=True)]}


def _collector(rollout: Rollout, env: TorchTetherVecEnv, T: int,
               graphs: bool) -> Callable[[], None]:
    """A rollout's ``T`` steps, the env's included, and its advantages, as one call.

    With ``graphs``: where one graph can hold a whole step
    (``env.whole_step_graph``: ``--sync-free`` on the torch backend or on numba-cuda),
    the whole rollout is one :class:`~.graphs.GraphedCall` (one launch per iteration);
    otherwise each step's pieces (:class:`~.graphs.RolloutStep`) and the advantages
    are graphs of their own, and the host launches them step by step.
    """
    whole = graphs and env.whole_step_graph
    step = RolloutStep(rollout, env, graphs=graphs and not whole)  # the env's step included
    finish: Callable[[], None] = rollout.finish
    if graphs and not whole:
        finish = GraphedCall(finish)

    def rollout_steps() -> None:
        for _ in range(T):
            step()
        finish()

    if whole:  # the env's draws and the actions' (torch's default generator) inside
        return GraphedCall(rollout_steps, generators=(env.generator,))
    return rollout_steps


def progress_remaining(step_fraction: float, elapsed: float, max_seconds: float,
                       startup: float) -> float:
    """What is left of the linear learning-rate schedule [-], 1 at the start, 0 at the end.

    It falls to 0 at the step budget (``step_fraction`` [-] of it done) or at the time
    budget ``max_seconds`` [s], whichever comes first. The time budget's share counts
    from the end of the first update, ``startup`` [s] after the clock's start (NaN
    before it ends): the first update holds the start-up's one-off costs (compiling,
    capturing CUDA graphs, warm-ups), which on a GPU can be a large part of a budget of
    a minute, and would otherwise leave the learning rate its start value only while
    nothing learns. ``elapsed`` [s] is the time since the clock's start. Without a time
    budget (``max_seconds`` inf) this is SB3's ``1 - step_fraction``.
    """
    time_fraction = 0.0
    if math.isfinite(max_seconds) and not math.isnan(startup):
        left = max_seconds - startup
        time_fraction = 1.0 if left <= 0 else (elapsed - startup) / left
    return min(1.0, max(0.0, 1.0 - max(step_fraction, time_fraction)))


def _permutations(epochs: int, S: int, M: int, device) -> torch.Tensor:
    """Each epoch's minibatch order per seed (epochs, S, M), drawn before the minibatch steps.

    One ``argsort(rand)`` per epoch, in epoch order: the same draws as one per epoch
    between the steps (the steps draw nothing), and no sort inside a captured CUDA graph.
    """
    return torch.stack([torch.argsort(torch.rand((S, M), device=device), dim=1)
                        for _ in range(epochs)])


def _minibatch_step(policy, opt, lr, settings: PPOSettings, batch: tuple, idx) -> None:
    """One clipped-surrogate update of every seed on its samples ``idx`` (S, b) of ``batch``.

    Free of host syncs and random draws, with fixed shapes, so that a CUDA graph can
    capture it (:mod:`.graphs`). Adam runs with lr 1 and each seed's step is scaled by its
    own rate ``lr`` (S,) afterwards: Adam's step is linear in lr, so this is Adam with a
    per-seed rate.
    """
    params = list(policy.parameters())
    o, ac, lp0, ad, rt = (take(x, idx) for x in batch)
    loss, lp = minibatch_loss(policy, settings, o, ac, lp0, ad, rt)
    opt.zero_grad(set_to_none=True)
    loss.backward()
    policy.per_seed_grad_clip(settings.max_grad_norm)
    before = [p.detach().clone() for p in params]
    opt.step()
    with torch.no_grad():
        for p, b in zip(params, before, strict=True):
            p.copy_(b + (p - b) * lr.view(-1, *([1] * (p.dim() - 1))))
    if settings.lr_schedule == "adaptive":
        adapt_rates(lr, lp0, lp, settings)


def _minibatch_steps(policy, opt, lr, settings: PPOSettings, batch: tuple,
                     orders: torch.Tensor) -> None:
    """Every minibatch step of an update: a pass over ``batch`` per epoch, in ``orders``.

    ``orders`` (epochs, S, M) holds each epoch's minibatch order per seed
    (:func:`_permutations`); minibatches of ``batch_size`` rows (the last one shorter
    when M is not a multiple of it). No host sync and no random draw: a CUDA graph can
    capture it whole (:class:`~.graphs.GraphedUpdate`).
    """
    for idx in minibatches(orders, settings.batch_size):
        _minibatch_step(policy, opt, lr, settings, batch, idx)


def _update(policy, opt, lr, settings: PPOSettings, batch: RolloutBatch,
            steps=_minibatch_steps) -> None:
    """``n_epochs`` passes of minibatch steps over ``batch``, per seed independent.

    The epochs' minibatch orders are drawn first (:func:`_permutations`), then ``steps``
    (:func:`_minibatch_steps` or its captured CUDA graph, :class:`~.graphs.GraphedUpdate`,
    same arguments) runs them.
    """
    S, M = batch.logp.shape
    orders = _permutations(settings.n_epochs, S, M, batch.logp.device)
    steps(policy, opt, lr, settings, batch.tensors(), orders)
