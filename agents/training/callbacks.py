"""The callbacks of a training run: evaluations with the best agent, checkpoints, progress.

* :class:`RunEvalCallback` evaluates every ``eval_freq`` env steps and once more at the
  end (whatever the budget), writes ``eval/evaluations.npz`` and, on a new best, the
  best agent in the safe format (``agent.json`` + ``policy.safetensors``) and
  ``best_model.zip``;
* stable-baselines3's ``CheckpointCallback`` writes ``checkpoints/`` for ``--resume``;
* :class:`ProgressCallback` rewrites ``train_info.json`` every
  :data:`PROGRESS_EVERY_S` seconds, so the wall time survives a kill.
"""

from __future__ import annotations

import math
import time
from typing import NamedTuple

from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback, EvalCallback

from ..files.run_folder import CHECKPOINT_DIR, CHECKPOINT_PREFIX, EVAL_DIR, write_train_info
from ..files.safe_format import ObsNormalization, save_agent
from .settings import TrainSettings

__all__ = ["PROGRESS_EVERY_S", "RunCallbacks", "RunEvalCallback", "ProgressCallback",
           "make_callbacks", "save_safe_agent"]

PROGRESS_EVERY_S = 30.0
"""Seconds between rewrites of ``train_info.json`` while training (wall time survives
a kill up to this much)."""


def save_safe_agent(settings: TrainSettings, model, env, folder: str) -> None:
    """Write the model's policy and ``env``'s observation statistics as a safe agent.

    ``folder`` is relative to the run folder (``"."``: the best agent at its top,
    ``"final_agent"``: the agent at the last step).
    """
    training = {"seed": settings.seed, "command": settings.command_line,
                "num_timesteps": int(model.num_timesteps)}
    save_agent(settings.out / folder, model.policy, settings.algo,
               ObsNormalization.of_vec_normalize(env), env_id=settings.env_id,
               env_kwargs=settings.env_kwargs, training=training,
               hybrid=settings.residual.to_dict() if settings.residual is not None else None,
               features=settings.features.to_dict() if settings.features is not None else None)


class RunEvalCallback(EvalCallback):
    """EvalCallback that also writes the best agent (safe format).

    It evaluates at the very end too, whatever the budget.
    """

    def __init__(self, eval_env, settings: TrainSettings):
        super().__init__(eval_env, n_eval_episodes=settings.options.eval_episodes,
                         eval_freq=max(settings.eval_freq // settings.n_envs, 1),
                         log_path=str(settings.out / EVAL_DIR),
                         best_model_save_path=str(settings.out), deterministic=True,
                         verbose=settings.options.verbose)
        self.settings = settings

    def _on_step(self) -> bool:
        best = self.best_mean_reward
        result = super()._on_step()
        if self.best_mean_reward > best:
            save_safe_agent(self.settings, self.model, self.eval_env, ".")
        return result

    def _on_training_end(self) -> None:
        done = self.evaluations_timesteps[-1] if self.evaluations_timesteps else -1
        if done < self.num_timesteps:  # a run always ends with an evaluation
            n_calls, self.n_calls = self.n_calls, self.eval_freq
            try:
                self._on_step()
            finally:
                self.n_calls = n_calls


class ProgressCallback(BaseCallback):
    """Rewrites ``train_info.json`` every ``PROGRESS_EVERY_S`` s (wall time survives a kill).

    Parameters
    ----------
    settings : TrainSettings
        The run (folder, algorithm, seed, command).
    previous_wall : float
        Wall time of the earlier calls of a resumed run [s].
    """

    def __init__(self, settings: TrainSettings, previous_wall: float = 0.0):
        super().__init__()
        self.settings = settings
        self.previous_wall = previous_wall
        self.info_base = {"algo": settings.algo, "env_id": settings.env_id,
                          "seed": settings.seed, "torch_threads": settings.options.torch_threads,
                          "command": settings.command_line,
                          "tether_gym": _tether_gym_version()}

    def _on_training_start(self) -> None:
        self.t0 = time.perf_counter()
        self.last = -math.inf
        self.write("running")

    def _on_step(self) -> bool:
        if time.perf_counter() - self.last >= PROGRESS_EVERY_S:
            self.write("running")
        return True

    def write(self, status: str) -> float:
        """Write ``train_info.json`` with ``status``; return the run's wall time [s]."""
        now = time.perf_counter()
        self.last = now
        wall = self.previous_wall + (now - self.t0)
        write_train_info(self.settings.out, {**self.info_base, "status": status,
                                             "num_timesteps": int(self.model.num_timesteps),
                                             "wall_time_s": round(wall, 1)})
        return wall


def _tether_gym_version() -> str:
    import tether_gym

    return tether_gym.__version__


class RunCallbacks(NamedTuple):
    """The callbacks of one run, in the order ``model.learn`` gets them."""

    evaluator: RunEvalCallback
    checkpoints: CheckpointCallback
    progress: ProgressCallback


def make_callbacks(settings: TrainSettings, eval_env, previous_wall: float,
                   off_policy: bool) -> RunCallbacks:
    """The evaluation, checkpoint and progress callbacks of a run.

    ``previous_wall`` is the wall time of a resumed run's earlier calls [s];
    ``off_policy`` saves the replay buffer with each checkpoint (SAC).
    """
    checkpoints = CheckpointCallback(
        save_freq=max(settings.checkpoint_freq // settings.n_envs, 1),
        save_path=str(settings.out / CHECKPOINT_DIR), name_prefix=CHECKPOINT_PREFIX,
        save_vecnormalize=True, save_replay_buffer=off_policy)
    return RunCallbacks(RunEvalCallback(eval_env, settings), checkpoints,
                        ProgressCallback(settings, previous_wall))
