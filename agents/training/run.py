"""One training run: :func:`train` takes a :class:`~.settings.TrainSettings` and trains.

It reads as the run goes: settings -> envs -> model (new, or the resume point) -> the
records (``config.yml``, ``args.yml``, ``command.txt``) -> callbacks -> learn -> the
saved model, the final agent and ``train_info.json``. The folder it fills is described
in :mod:`tether_gym_agents.files.run_folder`.
"""

from __future__ import annotations

import copy
import json
import shlex
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import tether_gym

from ..common.algorithms import algorithm
from ..files.run_folder import (
    FINAL_AGENT_DIR,
    FINAL_MODEL_FILE,
    REPLAY_BUFFER_FILE,
    TB_DIR,
    TRAIN_INFO_FILE,
    VECNORMALIZE_FILE,
    DamagedFileError,
    append_command,
    evaluations_path,
    last_write_time,
    read_train_info,
    write_args,
    write_config,
)
from .bc_term import BCTermCallback
from .config import action_noise, algo_class, with_schedules
from .settings import TrainSettings
from .warm_start import INIT_KEY, freeze_obs_stats, init_path, warm_start

__all__ = ["RunSummary", "train", "make_venv", "evaluate_command"]


@dataclass(frozen=True)
class RunSummary:
    """What a call of :func:`train` did.

    Attributes
    ----------
    out : Path
        The run folder.
    num_timesteps : int
        Env steps the model has trained in all calls [-].
    wall_s : float
        Wall time of this call's training [s].
    total_wall_s : float
        Wall time of every call of the run, killed ones included [s].
    """

    out: Path
    num_timesteps: int
    wall_s: float
    total_wall_s: float


def make_venv(settings: TrainSettings, n_envs: int, seed: int):
    """The (monitored) training or evaluation vec env; the hybrid's with a residual.

    The residual wrapper sits below ``VecNormalize`` (added by the caller): its base
    law and filter read raw observations. The policy's input features are appended
    above it, also below ``VecNormalize``.
    """
    from stable_baselines3.common.vec_env import VecEnv, VecMonitor

    from .vec_env import make_sb3_vec_env

    if settings.env_id != tether_gym.ENV_ID:
        # any other registered id: SB3's generic path (no residual or features there);
        # its Monitor around each env reports the episodes, so no VecMonitor on top
        from stable_baselines3.common.env_util import make_vec_env

        return make_vec_env(settings.env_id, n_envs=n_envs, seed=seed,
                            env_kwargs=settings.env_kwargs)
    venv: VecEnv = make_sb3_vec_env(n_envs, seed=seed, env_kwargs=settings.env_kwargs)
    if settings.residual is not None:
        from .residual_env import ResidualVecEnv

        venv = ResidualVecEnv.from_spec(venv, settings.residual)
    if settings.features is not None:
        from .vec_env import FeatureVecEnv

        venv = FeatureVecEnv(venv, settings.features)
    return VecMonitor(venv)


def train(settings: TrainSettings) -> RunSummary:
    """Train one run into ``settings.out`` (a new run, or ``settings.resume``).

    Raises
    ------
    ConfigError
        When a resumed run has no loadable saved model.
    """
    import torch
    from stable_baselines3.common.vec_env import VecNormalize

    from .callbacks import (
        RunClock,
        make_callbacks,
        save_buffer,
        save_model,
        save_safe_agent,
        save_stats,
    )
    from .curves import plot_learning_curve
    from .resume import check_run_files

    # SB3 may add entries to the hyperparameters' mappings (SAC: policy_kwargs.use_sde):
    # this run's own copy takes them, and config.yml records them, as it always did
    settings = replace(settings, hyperparams=copy.deepcopy(settings.hyperparams))
    torch.set_num_threads(settings.options.torch_threads)
    out = settings.out
    if settings.resume:  # every refusal before the first write (train_info.json below)
        check_run_files(out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"env {settings.env_id} with env kwargs {json.dumps(settings.env_kwargs)}")
    for note in settings.notes:
        print(f"  note: {note}")
    previous = _previous_info(out) if settings.resume else {}
    clock = RunClock(settings, _previous_wall(out, previous))
    if settings.resume:
        _remove_temporaries(out)
    clock.write("running", int(previous.get("num_timesteps", 0)))
    model, venv, eval_env = _model(settings)
    _write_records(settings)
    callbacks = make_callbacks(settings, eval_env, clock)
    if settings.resume:  # the learning curve continues, not restarts
        _continue_curve(callbacks.evaluator, out, int(model.num_timesteps))
    t0 = time.perf_counter()
    extra = ([] if settings.bc_term is None
             else [BCTermCallback(settings.bc_term, settings.features, settings.seed)])
    model.learn(settings.timesteps, callback=[*callbacks, *extra],
                progress_bar=not settings.options.no_progress,
                reset_num_timesteps=not settings.resume, tb_log_name=settings.algo)
    wall = time.perf_counter() - t0
    env = model.get_env()
    if isinstance(env, VecNormalize):
        save_stats(env, out / VECNORMALIZE_FILE)  # .pkl and the .npz that resume reads
    if not algorithm(settings.algo).on_policy:
        save_buffer(model, out / REPLAY_BUFFER_FILE)
    save_model(model, out / FINAL_MODEL_FILE)  # last: a final model has its other files
    save_safe_agent(settings, model, env, FINAL_AGENT_DIR, wall_time_s=clock.elapsed())
    total_wall = callbacks.progress.write("finished")
    plot_learning_curve(out)
    venv.close()
    eval_env.close()
    print(f"trained {settings.algo.upper()} to step {model.num_timesteps} in {wall:.0f} s "
          f"({total_wall:.0f} s in all calls); run folder {out}; evaluate it beside the "
          f"paper's law (on the env it was trained on) with {evaluate_command(out)}")
    return RunSummary(out, int(model.num_timesteps), wall, total_wall)


def evaluate_command(out: Path) -> str:
    """The evaluate command a finished run prints, quoted for a POSIX shell."""
    return "`" + shlex.join(["python", "evaluate.py", "smc", str(out)]) + "`"


UNRECORDED_MAX_S = 600.0
"""The most a killed call's time after its last record adds on resume [s] (a folder
copied without its modification times must not add the copy's age)."""


def _previous_info(out: Path) -> dict:
    """``train_info.json`` of the run being resumed; ``{}`` (with a warning) if damaged."""
    try:
        info = read_train_info(out)
        steps = info.get("num_timesteps", 0) if isinstance(info, dict) else 0
        if isinstance(steps, bool) or not isinstance(steps, int) or steps < 0:
            raise ValueError(f"num_timesteps {steps!r} is not a whole number >= 0")
    except ValueError as exc:
        print(f"warning: {out / TRAIN_INFO_FILE} is damaged ({exc}); the wall time of the "
              "earlier calls is lost, the run continues", file=sys.stderr)
        return {}
    return info if isinstance(info, dict) else {}


def _remove_temporaries(out: Path) -> None:
    """Remove the temporary files (``.tmp-*``) a killed call left mid-write."""
    import shutil

    for path in sorted(out.rglob(".tmp-*"), reverse=True):
        if path.is_dir() and not path.is_symlink():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)


def _previous_wall(out: Path, previous: dict) -> float:
    """Wall time of the earlier calls [s], with the killed part after the last record.

    A call that did not finish (``status`` not ``finished``) ran on until the newest
    file it wrote; that time since its last record (``updated_at``) counts too, up to
    :data:`UNRECORDED_MAX_S`.
    """
    try:
        wall = float(previous.get("wall_time_s", 0.0))
        if previous.get("status") != "finished" and "updated_at" in previous:
            unrecorded = last_write_time(out) - float(previous["updated_at"])
            wall += min(max(0.0, unrecorded), UNRECORDED_MAX_S)
    except (TypeError, ValueError):
        return 0.0
    return wall


def _model(settings: TrainSettings):
    """(model, training env, evaluation env): a new model, or the resume point's."""
    venv = make_venv(settings, settings.n_envs, settings.seed)
    eval_env = make_venv(settings, 1, settings.seed + 10_000)
    if settings.residual is not None:
        print(f"  residual hybrid: {json.dumps(settings.residual.to_dict())}: the agent learns "
              "a in u = filter(clip(u_smc + scale * a, -1, 1))")
    init = init_path(settings.run)
    if settings.resume:
        model, venv, eval_env = _resumed_model(settings, venv, eval_env)
    else:
        if settings.normalize is not False:
            venv, eval_env = _normalized(settings, venv, eval_env)
        model = _new_model(settings, venv)
        if init is not None:
            agent = warm_start(model, venv, init)
            print(f"  actor and observation statistics from {agent.path} ({INIT_KEY}), the "
                  "statistics fixed; critic and exploration noise new")
    if init is not None:  # a resumed run's too: they are the agent's, saved with the run
        freeze_obs_stats(model.get_env())
    return model, venv, eval_env


def _normalized(settings: TrainSettings, venv, eval_env):
    """Both envs wrapped in new ``VecNormalize`` (the config's ``normalize`` options)."""
    from stable_baselines3.common.vec_env import VecNormalize

    norm = settings.normalize
    norm_kwargs = norm if isinstance(norm, dict) else {}
    gamma = settings.hyperparams.get("gamma", 0.99)
    venv = VecNormalize(venv, gamma=gamma, **norm_kwargs)
    eval_env = VecNormalize(eval_env, gamma=gamma, training=False,
                            norm_obs=norm_kwargs.get("norm_obs", True), norm_reward=False,
                            clip_obs=norm_kwargs.get("clip_obs", 10.0))
    return venv, eval_env


def _new_model(settings: TrainSettings, venv):
    """A new model of the run's algorithm and hyperparameters on ``venv``.

    The config's ``noise_type``/``noise_std`` become the model's ``action_noise``.
    """
    params = with_schedules(settings.hyperparams)
    noise = action_noise(settings.run, int(venv.action_space.shape[0]))
    if noise is not None:
        params["action_noise"] = noise
    return algo_class(settings.algo)(
        settings.run.get("policy", "MlpPolicy"), venv, seed=settings.seed, device="cpu",
        tensorboard_log=str(settings.out / TB_DIR), verbose=settings.options.verbose,
        **params)


def _resumed_model(settings: TrainSettings, venv, eval_env):
    """The newest good saved model of the run, with its envs; TensorBoard cut to its step."""
    from .resume import ResumeBuild, load_resume_point, truncate_tensorboard

    build = ResumeBuild(
        new_model=lambda env: _new_model(settings, env),
        normalized=(None if settings.normalize is False
                    else lambda v, e: _normalized(settings, v, e)),
        algo_cls=algo_class(settings.algo), tb_log=str(settings.out / TB_DIR),
        allow_pickle=settings.options.allow_pickle, algo=settings.algo)
    model, venv, eval_env, model_path, buffer_loaded = load_resume_point(
        settings.out, build, venv, eval_env)
    start = int(model.num_timesteps)
    removed = truncate_tensorboard(settings.out / TB_DIR, start)
    print(f"resuming from {model_path} at step {start}"
          + (f" with its replay buffer "
             f"({model.replay_buffer.size() * model.replay_buffer.n_envs} transitions)"
             if buffer_loaded else "")
          + (f"; {removed} TensorBoard events after step {start} removed" if removed else ""))
    return model, venv, eval_env


def _write_records(settings: TrainSettings) -> None:
    """``config.yml``, ``args.yml`` and a line of ``command.txt``."""
    write_config(settings.out, settings.resolved_config())
    write_args(settings.out, settings.options.as_dict())
    append_command(settings.out, settings.command_line)


def _continue_curve(evaluator, out: Path, step: int) -> None:
    """Seed the evaluator with the run's evaluations up to ``step``; report dropped ones."""
    from .resume import continue_eval_history

    path = evaluations_path(out)
    if not path.is_file():
        return
    try:
        dropped = continue_eval_history(evaluator, out, step)
    except DamagedFileError as exc:
        aside = path.with_name(path.name + ".damaged")
        path.replace(aside)
        print(f"warning: {exc}; moved to {aside.name}, the evaluation history starts anew",
              file=sys.stderr)
        return
    if dropped:
        print(f"  dropped {dropped} evaluation(s) after step {step} from "
              f"{evaluations_path(out)} (the resumed run repeats those steps)")
