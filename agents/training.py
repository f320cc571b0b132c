"""Train PPO or SAC on a tether_gym environment: the code behind ``train.py``.

A run folder (``--out``) keeps everything needed to reproduce and resume the run:
``config.yml`` (resolved hyperparameters, algorithm, env id and kwargs),
``args.yml`` (parsed arguments), ``command.txt`` (the command line),
``vecnormalize.pkl`` (normalisation statistics), ``best_model.zip`` (the evaluation
callback's best), ``final_model.zip``, ``checkpoints/``, ``eval/evaluations.npz``
(the learning curve), ``tb/`` (tensorboard) and ``train_info.json`` (steps, wall
time, seed).
"""

from __future__ import annotations

import argparse
import ast
import difflib
import inspect
import json
import shlex
import sys
import time
from pathlib import Path

import gymnasium as gym

import tether_gym

__all__ = ["main", "load_hyperparams", "parse_env_kwargs", "plot_learning_curve", "ConfigError",
           "CONFIG_DIR"]

CONFIG_DIR = Path(__file__).resolve().parent / "configs"
RUN_KEYS = ("policy", "n_envs", "n_timesteps", "normalize", "env_kwargs", "eval_freq",
            "checkpoint_freq")
NORMALIZE_KEYS = ("norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon")


class ConfigError(ValueError):
    """A hyperparameter file or value is invalid."""


def _algo_class(algo: str):
    from stable_baselines3 import PPO, SAC

    return {"ppo": PPO, "sac": SAC}[algo]


def load_hyperparams(path: Path, algo: str, env_id: str) -> dict:
    """Hyperparameters for ``env_id`` from a YAML file keyed by env id with a ``default`` block.

    Raises
    ------
    ConfigError
        On a missing file, a malformed document or an unknown key (the message lists
        the valid keys).
    """
    import yaml

    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"config file {str(path)!r} does not exist")
    with open(path) as fh:
        try:
            doc = yaml.safe_load(fh) or {}
        except yaml.YAMLError as exc:
            raise ConfigError(f"{path} is not valid YAML: {exc}") from exc
    if not isinstance(doc, dict):
        raise ConfigError(f"{path} must map env ids (and 'default') to hyperparameters")
    params = dict(doc.get("default") or {})
    params.update(doc.get(env_id) or {})
    valid_algo = set(inspect.signature(_algo_class(algo).__init__).parameters) - {
        "self", "env", "policy", "_init_setup_model", "tensorboard_log", "verbose", "seed",
        "device"}
    valid = set(RUN_KEYS) | valid_algo
    unknown = sorted(set(params) - valid)
    if unknown:
        raise ConfigError(f"unknown key(s) {unknown} in {path} for {algo.upper()}; valid keys: "
                          f"{sorted(valid)}")
    norm = params.get("normalize", False)
    if isinstance(norm, dict):
        bad = sorted(set(norm) - set(NORMALIZE_KEYS))
        if bad:
            raise ConfigError(f"unknown normalize key(s) {bad}; valid: {list(NORMALIZE_KEYS)}")
    elif not isinstance(norm, bool):
        raise ConfigError(f"normalize must be true, false or a dict, got {norm!r}")
    return params


def parse_env_kwargs(items: list[str]) -> dict:
    """Parse ``key=value`` strings; values are Python literals (no code is evaluated)."""
    out = {}
    for item in items or []:
        if "=" not in item:
            raise ConfigError(f"--env-kwargs entry {item!r} must look like key=value")
        key, text = item.split("=", 1)
        key = key.strip()
        if not key.isidentifier():
            raise ConfigError(f"--env-kwargs key {key!r} is not a valid name")
        try:
            value = ast.literal_eval(text)
        except (ValueError, SyntaxError):
            value = {"None": None, "none": None, "true": True, "false": False}.get(text, text)
        out[key] = value
    return out


def plot_learning_curve(run_dir: Path) -> Path | None:
    """Write ``learning_curve.png`` from ``eval/evaluations.npz``; None without matplotlib.

    Mean evaluation return (with min-max band) and mean episode length against env
    steps, as recorded by the evaluation callback.
    """
    import numpy as np

    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return None
    data = np.load(Path(run_dir) / "eval" / "evaluations.npz")
    steps, returns, lengths = data["timesteps"], data["results"], data["ep_lengths"]
    fig = Figure(figsize=(7, 4.5), layout="constrained")
    FigureCanvasAgg(fig)
    ax, ax_len = fig.subplots(2, 1, sharex=True, height_ratios=(2, 1))
    ax.plot(steps, returns.mean(axis=1), label="mean")
    ax.fill_between(steps, returns.min(axis=1), returns.max(axis=1), alpha=0.3, label="min-max")
    ax.set_ylabel("evaluation return")
    ax.set_title(f"{Path(run_dir).name}: deterministic evaluation episodes")
    ax.legend()
    ax_len.plot(steps, lengths.mean(axis=1))
    ax_len.set_ylabel("episode length")
    ax_len.set_xlabel("env steps")
    out = Path(run_dir) / "learning_curve.png"
    fig.savefig(out, dpi=100)
    return out


def _check_env_id(env_id: str) -> None:
    ids = [i for i in gym.registry if i.startswith("tether_gym/")]
    if env_id not in gym.registry:
        close = difflib.get_close_matches(env_id, ids or list(gym.registry), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ConfigError(f"unknown env id {env_id!r}{hint}; tether_gym ids: {ids}")


def _build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="train.py", description="Train PPO or SAC on tether_gym.")
    p.add_argument("--algo", choices=("ppo", "sac"), default="ppo")
    p.add_argument("--env-id", default=tether_gym.ENV_ID)
    p.add_argument("--env-kwargs", nargs="*", default=[], metavar="KEY=VALUE",
                   help="env arguments as Python literals, e.g. eccentricity=0.3 "
                        "masses=(1,2); they override the config's env_kwargs")
    p.add_argument("--n-envs", type=int, default=None, help="parallel envs (default: config)")
    p.add_argument("--timesteps", type=int, default=None,
                   help="env steps to train in this call (default: config n_timesteps)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--config", type=Path, default=None,
                   help="hyperparameter YAML (default: the packaged configs/<algo>.yml)")
    p.add_argument("--out", type=Path, default=None, help="run folder (default runs/<algo>)")
    p.add_argument("--resume", action="store_true",
                   help="continue the run in --out from its latest checkpoint or final model; "
                        "the step counter continues")
    p.add_argument("--eval-freq", type=int, default=None, help="env steps between evaluations")
    p.add_argument("--eval-episodes", type=int, default=5)
    p.add_argument("--checkpoint-freq", type=int, default=None,
                   help="env steps between checkpoints")
    p.add_argument("--torch-threads", type=int, default=1,
                   help="torch threads (default 1: two threads were measured up to 30x slower "
                        "on 2-core machines under load)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--verbose", type=int, default=0)
    fan = p.add_argument_group("many runs on Ray (pip install \"tether_gym[ray]\")")
    fan.add_argument("--seeds", type=int, default=None, metavar="N",
                     help="train seeds --seed ... --seed+N-1 into <out>/seed_K/, one Ray task "
                          "each; re-running skips finished seeds and resumes interrupted ones")
    fan.add_argument("--ray-address", default=None, metavar="auto|HOST:PORT",
                     help="existing Ray cluster (default: $RAY_ADDRESS, else a local instance "
                          "with one CPU per run)")
    fan.add_argument("--sweep", type=Path, default=None, metavar="FILE.yml",
                     help="search config keys x several seeds per trial, rank by the median "
                          "final evaluation return (file format: tether_gym_agents.sweep)")
    return p


def _latest_checkpoint(run_dir: Path) -> tuple[Path, Path | None]:
    """Most advanced saved model in a run folder and its VecNormalize statistics."""
    ckpts = sorted((run_dir / "checkpoints").glob("model_*_steps.zip"),
                   key=lambda p: int(p.stem.split("_")[-2]))
    candidates = []
    if ckpts:
        steps = int(ckpts[-1].stem.split("_")[-2])
        stats = run_dir / "checkpoints" / f"model_vecnormalize_{steps}_steps.pkl"
        candidates.append((steps, ckpts[-1], stats if stats.is_file() else None))
    final = run_dir / "final_model.zip"
    if final.is_file():
        info = run_dir / "train_info.json"
        steps = json.loads(info.read_text())["num_timesteps"] if info.is_file() else -1
        stats = run_dir / "vecnormalize.pkl"
        candidates.append((steps, final, stats if stats.is_file() else None))
    if not candidates:
        raise ConfigError(f"--resume: no checkpoint or final_model.zip in {run_dir}")
    _, model, stats = max(candidates, key=lambda c: c[0])
    return model, stats


def _continue_eval_history(callback, path: Path) -> None:
    """Seed an EvalCallback with the evaluations a previous run saved (it would overwrite)."""
    import numpy as np

    with np.load(path) as data:
        callback.evaluations_timesteps = list(data["timesteps"])
        callback.evaluations_results = [list(r) for r in data["results"]]
        callback.evaluations_length = [list(r) for r in data["ep_lengths"]]
        if "successes" in data:
            callback.evaluations_successes = [list(r) for r in data["successes"]]
    returns = [float(np.mean(r)) for r in callback.evaluations_results]
    if returns:
        callback.best_mean_reward = max(returns)


def _replay_buffer_beside(model_path: Path) -> Path | None:
    """The replay buffer CheckpointCallback saved with a checkpoint (off-policy only)."""
    if model_path.parent.name != "checkpoints":
        return None
    steps = model_path.stem.split("_")[-2]
    path = model_path.parent / f"model_replay_buffer_{steps}_steps.pkl"
    return path if path.is_file() else None


def _make_venv(env_id, n_envs, seed, env_kwargs):
    from stable_baselines3.common.vec_env import VecMonitor

    from .vec_env import make_sb3_vec_env

    if env_id == tether_gym.ENV_ID:
        venv = make_sb3_vec_env(n_envs, seed=seed, env_kwargs=env_kwargs)
    else:  # any other registered id: SB3's generic path
        from stable_baselines3.common.env_util import make_vec_env

        venv = make_vec_env(env_id, n_envs=n_envs, seed=seed, env_kwargs=env_kwargs)
    return VecMonitor(venv)


def main(argv=None) -> int:  # noqa: C901 - a linear script
    """Command line of ``train.py``; returns the exit code."""
    parser = _build_parser()
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    try:
        if args.seeds is not None or args.sweep is not None or args.ray_address is not None:
            from .fanout import run_from_args  # Ray is imported there only

            return run_from_args(args, parser)
        return _train(args, argv)
    except ConfigError as exc:
        print(f"train.py: error: {exc}", file=sys.stderr)
        return 2


def _train(args, argv) -> int:
    import torch
    import yaml
    from stable_baselines3.common.callbacks import CheckpointCallback, EvalCallback
    from stable_baselines3.common.vec_env import VecNormalize

    _check_env_id(args.env_id)
    if args.torch_threads < 1:
        raise ConfigError(f"--torch-threads must be >= 1, got {args.torch_threads}")
    torch.set_num_threads(args.torch_threads)
    out = args.out or Path("runs") / args.algo
    config_path = args.config or CONFIG_DIR / f"{args.algo}.yml"
    if args.resume:
        resolved = out / "config.yml"
        if not resolved.is_file():
            raise ConfigError(f"--resume: {resolved} not found (is {out} a run folder?)")
        params = yaml.safe_load(resolved.read_text())["hyperparams"]
    else:
        params = load_hyperparams(config_path, args.algo, args.env_id)
    params = dict(params)
    run = {k: params.pop(k) for k in RUN_KEYS if k in params}
    env_kwargs = {**(run.get("env_kwargs") or {}), **parse_env_kwargs(args.env_kwargs)}
    n_envs = args.n_envs or int(run.get("n_envs", 1))
    if n_envs < 1:
        raise ConfigError(f"--n-envs must be >= 1, got {n_envs}")
    timesteps = args.timesteps if args.timesteps is not None else int(run.get("n_timesteps", 1e5))
    if timesteps < 1:
        raise ConfigError(f"--timesteps must be >= 1, got {timesteps}")
    eval_freq = args.eval_freq or int(run.get("eval_freq", 10000))
    ckpt_freq = args.checkpoint_freq or int(run.get("checkpoint_freq", 100000))
    norm = run.get("normalize", False)
    norm_kwargs = norm if isinstance(norm, dict) else {}
    gamma = params.get("gamma", 0.99)
    if "policy_kwargs" in params and isinstance(params["policy_kwargs"], str):
        raise ConfigError("policy_kwargs must be a mapping, not a string (no code is evaluated)")
    out.mkdir(parents=True, exist_ok=True)

    venv = _make_venv(args.env_id, n_envs, args.seed, env_kwargs)
    eval_env = _make_venv(args.env_id, 1, args.seed + 10_000, env_kwargs)
    algo_cls = _algo_class(args.algo)
    if args.resume:
        model_path, stats = _latest_checkpoint(out)
        if norm is not False:
            if stats is None:
                raise ConfigError(f"--resume: normalisation statistics missing beside {model_path}")
            venv = VecNormalize.load(str(stats), venv)
            eval_env = VecNormalize.load(str(stats), eval_env)
            eval_env.training = False
            eval_env.norm_reward = False
        model = algo_cls.load(model_path, env=venv, device="cpu",
                              tensorboard_log=str(out / "tb"))
        buffer = _replay_buffer_beside(model_path)
        if buffer is not None and hasattr(model, "load_replay_buffer"):
            model.load_replay_buffer(buffer)
        print(f"resuming from {model_path} at step {model.num_timesteps}"
              + (f" with its replay buffer "
                 f"({model.replay_buffer.size() * model.replay_buffer.n_envs} transitions)"
                 if buffer is not None and hasattr(model, "replay_buffer") else ""))
    else:
        if norm is not False:
            venv = VecNormalize(venv, gamma=gamma, **norm_kwargs)
            eval_env = VecNormalize(eval_env, gamma=gamma, training=False,
                                    norm_obs=norm_kwargs.get("norm_obs", True), norm_reward=False,
                                    clip_obs=norm_kwargs.get("clip_obs", 10.0))
        model = algo_cls(run.get("policy", "MlpPolicy"), venv, seed=args.seed, device="cpu",
                         tensorboard_log=str(out / "tb"), verbose=args.verbose, **params)
    resolved_config = {"algo": args.algo, "env_id": args.env_id, "env_kwargs": env_kwargs,
                       "n_envs": n_envs, "seed": args.seed,
                       "hyperparams": {**params, **run, "env_kwargs": env_kwargs,
                                       "n_envs": n_envs}}
    (out / "config.yml").write_text(yaml.safe_dump(resolved_config, sort_keys=False))
    (out / "args.yml").write_text(yaml.safe_dump(
        {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        sort_keys=False))
    command = "python train.py " + " ".join(shlex.quote(a) for a in
                                             (sys.argv[1:] if argv is None else argv))
    with open(out / "command.txt", "a") as fh:
        fh.write(command + "\n")
    callbacks = [
        EvalCallback(eval_env, n_eval_episodes=args.eval_episodes,
                     eval_freq=max(eval_freq // n_envs, 1), log_path=str(out / "eval"),
                     best_model_save_path=str(out), deterministic=True, verbose=args.verbose),
        CheckpointCallback(save_freq=max(ckpt_freq // n_envs, 1),
                           save_path=str(out / "checkpoints"), name_prefix="model",
                           save_vecnormalize=True,
                           save_replay_buffer=hasattr(model, "replay_buffer")),
    ]
    history = out / "eval" / "evaluations.npz"
    if args.resume and history.is_file():  # the learning curve continues, not restarts
        _continue_eval_history(callbacks[0], history)
    t0 = time.perf_counter()
    model.learn(timesteps, callback=callbacks, progress_bar=not args.no_progress,
                reset_num_timesteps=not args.resume, tb_log_name=args.algo)
    wall = time.perf_counter() - t0
    model.save(out / "final_model.zip")
    if isinstance(model.get_env(), VecNormalize):
        model.get_env().save(str(out / "vecnormalize.pkl"))
    info_path = out / "train_info.json"
    previous = json.loads(info_path.read_text()) if (args.resume and info_path.is_file()) else {}
    info = {"algo": args.algo, "env_id": args.env_id, "seed": args.seed,
            "num_timesteps": int(model.num_timesteps),
            "wall_time_s": round(previous.get("wall_time_s", 0.0) + wall, 1),
            "torch_threads": args.torch_threads, "command": command,
            "tether_gym": tether_gym.__version__}
    info_path.write_text(json.dumps(info, indent=2))
    plot_learning_curve(out)
    venv.close()
    eval_env.close()
    print(f"trained {args.algo.upper()} to step {model.num_timesteps} in {wall:.0f} s; run "
          f"folder {out}")
    return 0
