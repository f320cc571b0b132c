"""The callbacks of a training run: evaluations with the best agent, checkpoints, progress.

* :class:`RunEvalCallback` evaluates every ``eval_freq`` env steps and once more at the
  end, after the last update (an evaluation due during the final rollout waits for
  it, so every run ends with an evaluation of its final weights), writes
  ``eval/evaluations.npz`` (any mix of episode counts) and, on a new best, the best
  agent in the safe format (``agent.json`` + ``policy.safetensors``) and
  ``best_model.zip``;
* :class:`RunCheckpointCallback` writes ``checkpoints/`` for ``--resume`` (statistics
  and buffer first, the model last);
* :class:`ProgressCallback` rewrites ``train_info.json`` every
  :data:`PROGRESS_EVERY_S` seconds through a :class:`RunClock`, so the wall time
  survives a kill.

Every file is written atomically (:func:`~tether_gym_agents.files.run_folder.atomic_target`).
"""

from __future__ import annotations

import math
import os
import shutil
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback, EvalCallback

from ..common.algorithms import algorithm
from ..files.run_folder import (
    BEST_MODEL_FILE,
    CHECKPOINT_AGENT_PREFIX,
    CHECKPOINT_DIR,
    CHECKPOINT_PREFIX,
    EVAL_DIR,
    atomic_target,
    evaluation_arrays,
    prune_checkpoint_buffers,
    write_evaluations,
    write_train_info,
)
from ..files.safe_format import ObsNormalization, save_agent
from .checkpoint import safe_companion, save_buffer_npz, save_stats_npz
from .settings import TrainSettings

__all__ = ["PROGRESS_EVERY_S", "RunCallbacks", "RunEvalCallback", "RunCheckpointCallback",
           "RunClock", "ProgressCallback", "make_callbacks", "save_safe_agent", "save_model",
           "save_stats", "save_buffer"]

PROGRESS_EVERY_S = 30.0
"""Seconds between rewrites of ``train_info.json`` while training (the time after the
last one is recovered on resume from the newest file the killed call wrote)."""


def save_model(model, path: Path) -> None:
    """``model.save`` to ``path`` (a ``.zip``), atomically."""
    with atomic_target(Path(path)) as tmp:
        model.save(tmp)


def save_stats(vec_normalize, path: Path) -> None:
    """``VecNormalize.save`` to ``path`` and its arrays beside it (``.npz``), atomically.

    ``--resume`` reads the ``.npz`` (:mod:`.checkpoint`); the pickled ``.pkl`` is kept
    for the opt-in readers (``evaluate.py --allow-pickle``, ``convert``).
    """
    save_stats_npz(vec_normalize, safe_companion(Path(path)))
    with atomic_target(Path(path)) as tmp:
        vec_normalize.save(str(tmp))


def save_buffer(model, path: Path) -> None:
    """``model.save_replay_buffer`` to ``path`` (a ``.pkl``) and its arrays (``.npz``)."""
    save_buffer_npz(model, safe_companion(Path(path)))
    with atomic_target(Path(path)) as tmp:
        model.save_replay_buffer(tmp)


def save_safe_agent(settings: TrainSettings, model, env, folder: str,
                    wall_time_s: float | None = None) -> None:
    """Write the model's policy and ``env``'s observation statistics as a safe agent.

    ``folder`` is relative to the run folder (``"."``: the best agent at its top,
    ``"final_agent"``: the agent at the last step, ``checkpoints/agent_<N>_steps``). The
    files are written into a hidden temporary folder beside it and each renamed into
    place (a kill leaves every file whole). ``wall_time_s``, the run's wall time at
    this point [s] (all its calls), goes into the ``training`` record when given.
    """
    training = {"seed": settings.seed, "command": settings.command_line,
                "num_timesteps": int(model.num_timesteps)}
    if wall_time_s is not None:
        training["wall_time_s"] = round(float(wall_time_s), 1)
    target = (settings.out / folder).resolve()
    target.mkdir(parents=True, exist_ok=True)
    tmp = target / f".tmp-agent-{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        save_agent(tmp, model.policy, settings.algo, ObsNormalization.of_vec_normalize(env),
                   env_id=settings.env_id, env_kwargs=settings.env_kwargs, training=training,
                   hybrid=settings.residual.to_dict() if settings.residual is not None else None,
                   features=(settings.features.to_dict() if settings.features is not None
                             else None))
        # the policy before agent.json, which names it
        for path in sorted(tmp.iterdir(), key=lambda p: p.suffix == ".json"):
            os.replace(path, target / path.name)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


class RunEvalCallback(EvalCallback):
    """EvalCallback that writes its files atomically, and the best agent (safe format).

    It evaluates at the very end too, after the last update, whatever the budget; an
    evaluation due during the final rollout (``num_timesteps`` at or past the target)
    waits for it. Evaluations may have different episode counts (a resumed run with
    another ``--eval-episodes``).
    """

    def __init__(self, eval_env, settings: TrainSettings):
        super().__init__(eval_env, n_eval_episodes=settings.options.eval_episodes,
                         eval_freq=max(settings.eval_freq // settings.n_envs, 1),
                         log_path=str(settings.out / EVAL_DIR),
                         best_model_save_path=str(settings.out), deterministic=True,
                         verbose=settings.options.verbose)
        self.settings = settings

    def _on_step(self) -> bool:
        if self.eval_freq <= 0 or self.n_calls % self.eval_freq != 0:
            return True
        if self.num_timesteps >= self.model._total_timesteps:
            return True  # the final rollout: its update follows; the end evaluates
        return self._evaluate()

    def _on_training_end(self) -> None:
        done = self.evaluations_timesteps[-1] if self.evaluations_timesteps else -1
        if done < self.num_timesteps:  # a run always ends with an evaluation
            self._evaluate()

    def _evaluate(self) -> bool:
        """Evaluate now; record it (atomically), log it, keep a new best."""
        from stable_baselines3.common.evaluation import evaluate_policy
        from stable_baselines3.common.vec_env import sync_envs_normalization

        if self.model.get_vec_normalize_env() is not None:
            sync_envs_normalization(self.training_env, self.eval_env)
        self._is_success_buffer = []
        rewards, lengths = evaluate_policy(
            self.model, self.eval_env, n_eval_episodes=self.n_eval_episodes,
            deterministic=self.deterministic, return_episode_rewards=True, warn=self.warn,
            callback=self._log_success_callback)
        assert isinstance(rewards, list) and isinstance(lengths, list)
        self.evaluations_timesteps.append(self.num_timesteps)
        self.evaluations_results.append([float(r) for r in rewards])
        self.evaluations_length.append([int(n) for n in lengths])
        if self._is_success_buffer:
            self.evaluations_successes.append(list(self._is_success_buffer))
        write_evaluations(self.settings.out, evaluation_arrays(
            self.evaluations_timesteps, self.evaluations_results, self.evaluations_length,
            self.evaluations_successes))
        mean = float(np.mean(rewards))
        self.last_mean_reward = mean
        if self.verbose >= 1:
            print(f"Eval num_timesteps={self.num_timesteps}, episode_reward={mean:.2f} "
                  f"+/- {np.std(rewards):.2f}")
        self.logger.record("eval/mean_reward", mean)
        self.logger.record("eval/mean_ep_length", float(np.mean(lengths)))
        if self._is_success_buffer:
            self.logger.record("eval/success_rate", float(np.mean(self._is_success_buffer)))
        self.logger.record("time/total_timesteps", self.num_timesteps, exclude="tensorboard")
        self.logger.dump(self.num_timesteps)
        if mean > self.best_mean_reward:
            self.best_mean_reward = mean
            save_model(self.model, self.settings.out / BEST_MODEL_FILE)
            save_safe_agent(self.settings, self.model, self.eval_env, ".")
        return True


class RunCheckpointCallback(CheckpointCallback):
    """CheckpointCallback whose files are written atomically, the model last.

    A checkpoint's model file exists only once its statistics and buffer do, so a
    kill during a save leaves the previous checkpoint as the newest complete one. Once
    a checkpoint is whole, the older checkpoints' replay buffers are deleted
    (:func:`~tether_gym_agents.files.run_folder.prune_checkpoint_buffers`).
    With ``settings`` and ``clock``, each checkpoint's policy is also written as a safe
    agent, ``checkpoints/agent_<N>_steps/``, recording the run's wall time then (what
    the learning curves against wall-clock time evaluate).
    """

    def __init__(self, *args, settings: TrainSettings | None = None,
                 clock: RunClock | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.settings = settings
        self.clock = clock

    def _on_step(self) -> bool:
        if self.n_calls % self.save_freq != 0:
            return True
        stats = self.model.get_vec_normalize_env()
        if self.save_vecnormalize and stats is not None:
            save_stats(stats, Path(self._checkpoint_path("vecnormalize_", extension="pkl")))
        buffer = self.save_replay_buffer and getattr(self.model, "replay_buffer", None) is not None
        if buffer:
            save_buffer(self.model, Path(self._checkpoint_path("replay_buffer_", extension="pkl")))
        save_model(self.model, Path(self._checkpoint_path(extension="zip")))
        if buffer:  # this checkpoint is whole: the older ones' buffers go
            prune_checkpoint_buffers(Path(self.save_path).parent, self.num_timesteps)
        if self.settings is not None and self.clock is not None:
            folder = f"{CHECKPOINT_DIR}/{CHECKPOINT_AGENT_PREFIX}_{self.num_timesteps}_steps"
            save_safe_agent(self.settings, self.model,
                            stats if stats is not None else self.training_env, folder,
                            wall_time_s=self.clock.elapsed())
            # train_info.json at least as far as the newest checkpoint (ProgressCallback
            # writes only every PROGRESS_EVERY_S s: it said 0 steps beside checkpoints)
            self.clock.write("running", self.num_timesteps)
        return True


class RunClock:
    """The wall time of a run across its calls, and its ``train_info.json`` records.

    Parameters
    ----------
    settings : TrainSettings
        The run (folder, algorithm, seed, command).
    previous_wall : float
        Wall time of the earlier calls of a resumed run, killed ones included [s].

    The clock starts on creation (the start of a call, before envs and model are
    built).
    """

    def __init__(self, settings: TrainSettings, previous_wall: float = 0.0):
        self.t0 = time.perf_counter()
        self.settings = settings
        self.previous_wall = previous_wall
        self.info_base = {"algo": settings.algo, "env_id": settings.env_id,
                          "seed": settings.seed, "torch_threads": settings.options.torch_threads,
                          "command": settings.command_line,
                          "tether_gym": _tether_gym_version()}

    def elapsed(self) -> float:
        """The run's wall time so far, earlier calls included [s]."""
        return self.previous_wall + (time.perf_counter() - self.t0)

    def write(self, status: str, num_timesteps: int) -> float:
        """Write ``train_info.json`` with ``status``; return the run's wall time [s]."""
        wall = self.elapsed()
        write_train_info(self.settings.out, {**self.info_base, "status": status,
                                             "num_timesteps": int(num_timesteps),
                                             "wall_time_s": round(wall, 1),
                                             "updated_at": round(time.time(), 3)})
        return wall


class ProgressCallback(BaseCallback):
    """Rewrites ``train_info.json`` every ``PROGRESS_EVERY_S`` s (wall time survives a kill).

    Parameters
    ----------
    clock : RunClock
        The run's clock (started when the call started).
    """

    def __init__(self, clock: RunClock):
        super().__init__()
        self.clock = clock

    def _on_training_start(self) -> None:
        self.last = -math.inf
        self.write("running")

    def _on_step(self) -> bool:
        if time.perf_counter() - self.last >= PROGRESS_EVERY_S:
            self.write("running")
        return True

    def write(self, status: str) -> float:
        """Write ``train_info.json`` with ``status``; return the run's wall time [s]."""
        self.last = time.perf_counter()
        return self.clock.write(status, self.model.num_timesteps)


def _tether_gym_version() -> str:
    import tether_gym

    return tether_gym.__version__


class RunCallbacks(NamedTuple):
    """The callbacks of one run, in the order ``model.learn`` gets them."""

    evaluator: RunEvalCallback
    checkpoints: RunCheckpointCallback
    progress: ProgressCallback


def make_callbacks(settings: TrainSettings, eval_env, clock: RunClock) -> RunCallbacks:
    """The evaluation, checkpoint and progress callbacks of a run.

    ``clock`` keeps the run's wall time; an off-policy algorithm (its row of
    :mod:`tether_gym_agents.common.algorithms`) saves its replay buffer with each
    checkpoint.
    """
    off_policy = not algorithm(settings.algo).on_policy
    checkpoints = RunCheckpointCallback(
        save_freq=max(settings.checkpoint_freq // settings.n_envs, 1),
        save_path=str(settings.out / CHECKPOINT_DIR), name_prefix=CHECKPOINT_PREFIX,
        save_vecnormalize=True, save_replay_buffer=off_policy, settings=settings, clock=clock)
    return RunCallbacks(RunEvalCallback(eval_env, settings), checkpoints,
                        ProgressCallback(clock))
