"""Train PPO or SAC on a tether_gym environment: the code behind ``train.py``.

A run folder (``--out``) keeps everything needed to reproduce, evaluate and resume
the run:

* ``config.yml`` (resolved hyperparameters, algorithm, env id and the resolved env
  kwargs), ``args.yml`` (parsed arguments), ``command.txt`` (every command line);
* ``agent.json`` + ``policy.safetensors``: the best agent (the evaluations' best) in the
  safe format of :mod:`tether_gym_agents.files.agent_files`, which is what ``evaluate.py
  RUN`` loads; ``final_agent/``: the agent at the last step, in the same format;
* ``eval/evaluations.npz`` and ``learning_curve.png`` (the learning curve; every run
  ends with an evaluation, whatever its budget), ``tb/`` (TensorBoard);
* ``train_info.json`` (steps, wall time including interrupted parts, seed; rewritten
  every ``PROGRESS_EVERY_S`` seconds while training);
* for ``--resume`` only, stable-baselines3's own pickled files, which this package
  writes and reads back itself: ``final_model.zip``, ``best_model.zip``,
  ``vecnormalize.pkl``, ``final_replay_buffer.pkl`` (SAC) and ``checkpoints/``.
"""

from __future__ import annotations

import argparse
import difflib
import inspect
import json
import math
import shlex
import sys
import time
import zipfile
from pathlib import Path

import gymnasium as gym

import tether_gym

from ..common.env_kwargs import parse_env_kwargs as _parse_env_kwargs
from ..common.features import FeatureSpec
from ..common.jsonio import to_jsonable
from ..files.agent_files import save_agent, seed_runs
from ..hybrids.residual_spec import ResidualSpec

__all__ = ["main", "load_hyperparams", "parse_env_kwargs", "resolve_env_kwargs",
           "residual_spec", "feature_spec", "plot_learning_curve", "plot_seed_learning_curves",
           "ConfigError", "CONFIG_DIR"]

CONFIG_DIR = Path(__file__).resolve().parents[1] / "configs"
RUN_KEYS = ("policy", "n_envs", "n_timesteps", "normalize", "env_kwargs", "eval_freq",
            "checkpoint_freq", "residual", "features")
NORMALIZE_KEYS = ("norm_obs", "norm_reward", "clip_obs", "clip_reward", "gamma", "epsilon")
SEED_MAX = 2**31 - 1
PROGRESS_EVERY_S = 30.0
"""Seconds between rewrites of ``train_info.json`` while training (wall time survives
a kill up to this much)."""

# A fixed value the user types clears the config's random range of the same quantity.
RANGE_OF = {"eccentricity": ("eccentricity_range",), "masses": ("mass_range",),
            "initial_theta": ("init_theta_range",), "initial_lengths": ("init_length_range",)}
# Per-tether lists: a config's list with equal entries applies to any number of bodies.
PER_TETHER = ("masses", "initial_lengths", "initial_theta")


class ConfigError(ValueError):
    """A hyperparameter file, command-line value or env kwarg is invalid."""


SCHEDULE_KEYS = ("learning_rate", "clip_range")
"""Hyperparameters that may be written ``lin_<start>`` (rl-baselines3-zoo's notation)."""


def _linear(start: float):
    """SB3 schedule falling linearly from ``start`` to 0 over the run (progress 1 -> 0)."""
    def schedule(progress_remaining: float) -> float:
        return progress_remaining * start

    return schedule


def _lin_start(value: str) -> float:
    """The start of a ``lin_<start>`` value; NaN when it is not one."""
    try:
        return float(value[4:]) if value.startswith("lin_") else math.nan
    except ValueError:
        return math.nan


def _check_schedule(key: str, value, source: str) -> None:
    """Raise ConfigError unless a ``lin_<start>`` value has a positive number after ``lin_``."""
    if isinstance(value, str):
        start = _lin_start(value)
        if not start > 0.0 or not math.isfinite(start):
            raise ConfigError(f"{source}: {key}: {value!r} must be a number or 'lin_<start>' "
                              "with a start > 0 (falls linearly to 0 over the run)")


def with_schedules(params: dict) -> dict:
    """``params`` with every ``lin_<start>`` value of :data:`SCHEDULE_KEYS` made a schedule."""
    return {k: (_linear(_lin_start(v)) if k in SCHEDULE_KEYS and isinstance(v, str) else v)
            for k, v in params.items()}


def _algo_class(algo: str):
    from stable_baselines3 import PPO, SAC

    return {"ppo": PPO, "sac": SAC}[algo]


def load_hyperparams(path: Path, algo: str, env_id: str) -> dict:
    """Hyperparameters for ``env_id`` from a YAML file keyed by env id with a ``default`` block.

    The env id's block overrides ``default``. (rl-baselines3-zoo reads only the env
    id's block, so the shipped files keep that block complete and put only
    ``train.py``'s own keys, ``eval_freq`` and ``checkpoint_freq``, in ``default``.)

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
    if not isinstance(doc, dict) or not all(isinstance(v, (dict, type(None)))
                                            for v in doc.values()):
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
    for key in ("n_envs", "n_timesteps", "eval_freq", "checkpoint_freq"):
        if key in params:
            value = params[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value < 1 \
                    or value != int(value):
                raise ConfigError(f"{path}: {key}: {value!r} must be a whole number >= 1")
    if not isinstance(params.get("env_kwargs") or {}, dict):
        raise ConfigError(f"{path}: env_kwargs must be a mapping, got {params['env_kwargs']!r}")
    for key in SCHEDULE_KEYS:
        if key in params:
            _check_schedule(key, params[key], str(path))
    if "residual" in params:
        residual_spec(params["residual"], str(path))
    if "features" in params:
        feature_spec(params["features"], str(path))
    return params


def residual_spec(value, source: str) -> ResidualSpec | None:
    """The validated ``residual`` key of a config (None: no hybrid).

    ``residual: {base: smc, scale: 0.2, filter: true}`` trains the residual of the
    hybrid u = filter(clip(u_smc + scale * a, -1, 1))
    (:mod:`tether_gym_agents.training.residual_env`).

    Raises
    ------
    ConfigError
        On an unknown key or value (the message names the valid ones).
    """
    return _config_spec(ResidualSpec, value, f"{source}: residual")


def feature_spec(value, source: str) -> FeatureSpec | None:
    """The validated ``features`` key of a config (None: the observation alone).

    ``features: {name: symlog_errors, scale: 0.001}`` makes the policy's network see
    symlog(e / S) and symlog(e' / S) beside the observation
    (:mod:`tether_gym_agents.common.features`).
    """
    return _config_spec(FeatureSpec, value, f"{source}: features")


def _config_spec(cls, value, what: str):
    """``cls.from_dict(value)``, None for None; a bad value is a ConfigError."""
    if value is None:
        return None
    try:
        return cls.from_dict(value, what)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def _rate_mode_for(spec: ResidualSpec | None, env_kwargs: dict, source: str,
                   notes: list[str]) -> dict:
    """``env_kwargs`` with ``action_mode="rate"`` when a residual hybrid is trained."""
    if spec is None:
        return env_kwargs
    mode = env_kwargs.get("action_mode")
    if mode is None:
        notes.append(f"{source}'s residual sets action_mode='rate' (the hybrid commands reel "
                     "rates)")
        return {**env_kwargs, "action_mode": "rate"}
    if mode != "rate":
        raise ConfigError(f"{source}: residual needs action_mode 'rate' (the hybrid commands "
                          f"reel rates), but env kwargs give action_mode={mode!r}; remove it "
                          "or set it to 'rate'")
    return env_kwargs


def parse_env_kwargs(items: list[str]) -> dict:
    """``--env-kwargs key=value ...`` as a dict (:mod:`tether_gym_agents.common.env_kwargs`).

    Raises
    ------
    ConfigError
        On a malformed entry or a value that is not a Python literal (no code is
        evaluated); the message names the flag and the entry.
    """
    try:
        return _parse_env_kwargs(items, flag="--env-kwargs")
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def resolve_env_kwargs(config_kwargs: dict, user_kwargs: dict, source: str,
                       default_n_bodies: int = 3) -> tuple[dict, list[str]]:
    """Env kwargs of a run: the user's values win over the config's.

    * A fixed value typed by the user clears the config's random range of the same
      quantity (``eccentricity`` clears ``eccentricity_range``, ``masses`` clears
      ``mass_range``, ``initial_theta`` clears ``init_theta_range``,
      ``initial_lengths`` clears ``init_length_range``), unless the user typed the
      range too.
    * A per-tether list of the config (``masses``, ``initial_lengths``,
      ``initial_theta``) whose entries are all equal applies to any ``n_bodies``; an
      unequal one of the wrong length is an error naming the config line.

    Returns
    -------
    kwargs : dict
        The resolved env kwargs (plain lists, no tuples).
    notes : list of str
        What was changed, to print.
    """
    config_kwargs = dict(config_kwargs or {})
    notes = []
    for key in user_kwargs:
        for range_key in RANGE_OF.get(key, ()):
            if range_key in config_kwargs and range_key not in user_kwargs:
                notes.append(f"--env-kwargs {key}={user_kwargs[key]!r} clears {source}'s "
                             f"{range_key}: {config_kwargs[range_key]!r}")
                del config_kwargs[range_key]
    kwargs = to_jsonable({**config_kwargs, **user_kwargs})
    n_bodies = kwargs.get("n_bodies", default_n_bodies)
    if isinstance(n_bodies, int) and not isinstance(n_bodies, bool) and n_bodies >= 2:
        n = n_bodies - 1
        for key in PER_TETHER:
            value = kwargs.get(key)
            if key in user_kwargs or not isinstance(value, list) or len(value) == n:
                continue
            if value and all(v == value[0] for v in value):
                kwargs[key] = [value[0]] * n
                notes.append(f"{source}'s {key}: {value!r} applied to n_bodies={n_bodies} as "
                             f"{kwargs[key]!r}")
            else:
                raise ConfigError(f"{source}: env_kwargs {key}: {value!r} has {len(value)} "
                                  f"entries, but n_bodies={n_bodies} needs {n}; give {key} in "
                                  "--env-kwargs or edit that line")
    return kwargs, notes


def _check_env(env_id: str, kwargs: dict, items: list[str], source: str) -> None:
    """Build the env once with the resolved kwargs: bad values fail here, before training."""
    try:
        env = gym.make(env_id, **kwargs)
    except (ValueError, TypeError) as exc:
        typed = f"--env-kwargs {' '.join(items)}" if items else "no --env-kwargs"
        raise ConfigError(f"invalid env kwargs ({typed}; {source}): {exc}") from None
    env.close()


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


def plot_seed_learning_curves(folder: Path) -> Path | None:
    """Write ``learning_curves.png`` for a folder of ``seed_K`` runs; None if none plots.

    Each seed's mean evaluation return against env steps (thin lines), and the
    interquartile mean over the seeds with its min-max band on the steps every seed
    has reached (evaluations at the same step counts, as the fan-out's runs have).
    None without matplotlib or without two runs holding ``eval/evaluations.npz``.
    """
    import numpy as np
    from scipy.stats import trim_mean

    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return None
    curves = {}
    for run in seed_runs(folder):
        path = run / "eval" / "evaluations.npz"
        if path.is_file():
            data = np.load(path)
            curves[run.name] = (data["timesteps"], data["results"].mean(axis=1))
    if len(curves) < 2:
        return None
    common = sorted(set.intersection(*(set(t.tolist()) for t, _ in curves.values())))
    fig = Figure(figsize=(7, 4), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.subplots()
    for steps, ret in curves.values():
        ax.plot(steps, ret, lw=0.7, alpha=0.5, label=None)
    if common:
        table = np.array([[ret[steps.tolist().index(t)] for t in common]
                          for steps, ret in curves.values()])
        ax.plot(common, trim_mean(table, 0.25, axis=0), color="k", lw=2,
                label=f"IQM over {len(curves)} seeds")
        ax.fill_between(common, table.min(axis=0), table.max(axis=0), color="k", alpha=0.1,
                        label="min-max over seeds")
        ax.legend()
    ax.set_xlabel("env steps")
    ax.set_ylabel("mean evaluation return")
    ax.set_title(f"{Path(folder).name}: deterministic evaluation episodes, every seed")
    out = Path(folder) / "learning_curves.png"
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
                        "masses=(1,2); they win over the config's env_kwargs (a fixed value "
                        "clears the config's random range of the same quantity)")
    p.add_argument("--n-envs", type=int, default=None,
                   help="parallel envs, >= 1 (default: config)")
    p.add_argument("--timesteps", type=int, default=None,
                   help="env steps to train in this call, >= 1 (default: config n_timesteps)")
    p.add_argument("--seed", type=int, default=0, help=f"seed in [0, {SEED_MAX}] (default 0)")
    p.add_argument("--config", type=str, default=None,
                   help="hyperparameter YAML (default: the packaged configs/<algo>.yml)")
    p.add_argument("--out", type=str, default=None, help="run folder (default runs/<algo>)")
    p.add_argument("--resume", action="store_true",
                   help="continue the run in --out from its latest good checkpoint or final "
                        "model; the step counter continues")
    p.add_argument("--eval-freq", type=int, default=None,
                   help="env steps between evaluations, >= 1 (default: config); a run always "
                        "ends with one")
    p.add_argument("--eval-episodes", type=int, default=5,
                   help="episodes per evaluation, >= 1 (default 5)")
    p.add_argument("--checkpoint-freq", type=int, default=None,
                   help="env steps between checkpoints, >= 1 (default: config)")
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
                          "final evaluation return (file format: tether_gym_agents.training.sweep)")
    return p


def _at_least(flag: str, value, low: int = 1) -> None:
    if value is not None and value < low:
        raise ConfigError(f"{flag} {value}: must be an integer >= {low}")


def _check_args(args) -> None:
    """Command-line values alone (before the config is read)."""
    _at_least("--n-envs", args.n_envs)
    _at_least("--timesteps", args.timesteps)
    _at_least("--eval-freq", args.eval_freq)
    _at_least("--checkpoint-freq", args.checkpoint_freq)
    _at_least("--eval-episodes", args.eval_episodes)
    _at_least("--torch-threads", args.torch_threads)
    if not 0 <= args.seed <= SEED_MAX:
        raise ConfigError(f"--seed {args.seed}: must be an integer in [0, {SEED_MAX}]")
    if args.config is not None:
        if not args.config.strip():
            raise ConfigError(f"--config {args.config!r}: must be the path of a YAML file")
        if Path(args.config).is_dir():
            raise ConfigError(f"--config {args.config!r}: is a folder; give a YAML file")
    if args.out is not None and not args.out.strip():
        raise ConfigError(f"--out {args.out!r}: must be the path of a folder")


def _check_out(out: Path) -> None:
    """The run folder exists or can be made, and a file can be written in it."""
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {str(out)!r}: is a file; give a folder (new or a run folder)")
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write_test"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        raise ConfigError(f"--out {str(out)!r}: cannot write there ({exc.strerror or exc})") \
            from None


def _yaml_dump(data) -> str:
    """YAML without anchors/aliases (``&id001``), tuples as lists."""
    import yaml

    class _NoAliases(yaml.SafeDumper):
        def ignore_aliases(self, data):
            return True

    return yaml.dump(to_jsonable(data), Dumper=_NoAliases, sort_keys=False)


# ---------------------------------------------------------------------- resume
def _zip_timesteps(path: Path) -> int | None:
    """``num_timesteps`` from a model zip's plain-JSON ``data`` (nothing is unpickled)."""
    try:
        with zipfile.ZipFile(path) as zf:
            return int(json.loads(zf.read("data"))["num_timesteps"])
    except (zipfile.BadZipFile, KeyError, ValueError, TypeError, OSError, EOFError):
        return None


def _resume_candidates(run_dir: Path) -> list[tuple[int, Path, Path, Path]]:
    """(steps, model, normalisation stats, replay buffer) of every saved model, newest first.

    The final model comes before a checkpoint of the same step.
    """
    found = []
    final = run_dir / "final_model.zip"
    if final.is_file():
        found.append((_zip_timesteps(final), 1, final, run_dir / "vecnormalize.pkl",
                      run_dir / "final_replay_buffer.pkl"))
    for ckpt in (run_dir / "checkpoints").glob("model_*_steps.zip"):
        tag = ckpt.stem.split("_")[-2]
        if not tag.isdigit():
            continue
        steps = _zip_timesteps(ckpt)
        found.append((steps if steps is not None else int(tag),
                      0, ckpt, ckpt.parent / f"model_vecnormalize_{tag}_steps.pkl",
                      ckpt.parent / f"model_replay_buffer_{tag}_steps.pkl"))
    found = [(s if s is not None else -1, pri, m, st, b) for s, pri, m, st, b in found]
    found.sort(key=lambda c: (c[0], c[1]), reverse=True)
    return [(int(s or 0), m, st, b) for s, _, m, st, b in found]


def _load_resume_point(run_dir, algo_cls, venv, eval_env, normalize: bool, tb_log: str):
    """Load the newest good saved model; a truncated or incomplete one is skipped.

    Returns (model, venv, eval_env, model_path, buffer_loaded).
    """
    from stable_baselines3.common.vec_env import VecNormalize

    candidates = _resume_candidates(run_dir)
    if not candidates:
        raise ConfigError(f"--resume: no checkpoint or final_model.zip in {run_dir}")
    for steps, model_path, stats, buffer in candidates:
        try:
            if normalize:
                if not stats.is_file():
                    raise FileNotFoundError(f"its normalisation statistics {stats.name} are "
                                            "missing")
                train_env = VecNormalize.load(str(stats), venv)
                test_env = VecNormalize.load(str(stats), eval_env)
                test_env.training = False
                test_env.norm_reward = False
            else:
                train_env, test_env = venv, eval_env
            model = algo_cls.load(model_path, env=train_env, device="cpu", tensorboard_log=tb_log)
            loaded = False
            if hasattr(model, "replay_buffer"):
                if buffer.is_file():
                    model.load_replay_buffer(buffer)
                    loaded = True
                else:
                    print(f"warning: {model_path.name} has no replay buffer beside it "
                          f"({buffer.name}); SAC continues with an empty buffer")
        except Exception as exc:  # noqa: BLE001 - truncated files fail in many ways
            print(f"warning: skipping {model_path} (step {steps}): {type(exc).__name__}: "
                  f"{exc}", file=sys.stderr)
            continue
        return model, train_env, test_env, model_path, loaded
    raise ConfigError(f"--resume: no loadable model in {run_dir} (all "
                      f"{len(candidates)} saved models are truncated or incomplete)")


def _continue_eval_history(callback, path: Path, last_step: int) -> int:
    """Seed an EvalCallback with the evaluations up to ``last_step``; drop later ones.

    Evaluations after the resume point were made by the interrupted part of the run,
    which the resumed run repeats; the file is rewritten without them. Returns the
    number dropped.
    """
    import numpy as np

    with np.load(path) as data:
        arrays = {k: data[k] for k in data.files}
    keep = arrays["timesteps"] <= last_step
    dropped = int((~keep).sum())
    if dropped:
        np.savez(path, **{k: v[keep] for k, v in arrays.items()})
    callback.evaluations_timesteps = [int(t) for t in arrays["timesteps"][keep]]
    callback.evaluations_results = [list(r) for r in arrays["results"][keep]]
    callback.evaluations_length = [list(r) for r in arrays["ep_lengths"][keep]]
    if "successes" in arrays:
        callback.evaluations_successes = [list(r) for r in arrays["successes"][keep]]
    # best_model.zip may come from a dropped evaluation: keep its score as the bar
    returns = [float(np.mean(r)) for r in arrays["results"]]
    if returns:
        callback.best_mean_reward = max(returns)
    return dropped


def _truncate_tensorboard(tb_dir: Path, last_step: int) -> int:
    """Remove TensorBoard events after ``last_step`` (the part a resumed run repeats).

    Returns the number of events removed.
    """
    if not tb_dir.is_dir():
        return 0
    from tensorboard.backend.event_processing.event_file_loader import EventFileLoader
    from tensorboard.summary.writer.record_writer import RecordWriter

    removed = 0
    for path in sorted(tb_dir.rglob("events.out.tfevents.*")):
        try:
            events = list(EventFileLoader(str(path)).Load())
        except Exception:  # noqa: BLE001 - a truncated last record: keep what was read
            events = []
        keep = [e for e in events if e.step <= last_step]
        if len(keep) == len(events):
            continue
        removed += len(events) - len(keep)
        tmp = path.with_name(path.name + ".tmp")
        with open(tmp, "wb") as fh:
            writer = RecordWriter(fh)
            for event in keep:
                writer.write(event.SerializeToString())
            writer.flush()
        tmp.replace(path)
    return removed


# ---------------------------------------------------------------------- callbacks
def _callbacks(eval_env, out: Path, args, eval_freq: int, ckpt_freq: int, n_envs: int,
               agent_meta: dict, info_base: dict, previous_wall: float, off_policy: bool):
    from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback, EvalCallback
    from stable_baselines3.common.vec_env import VecNormalize

    def save_safe(model, env, folder: str) -> None:
        norm = env if isinstance(env, VecNormalize) and env.norm_obs else None
        save_agent(out / folder, model.policy, agent_meta["algo"],
                   obs_rms=norm.obs_rms if norm is not None else None,
                   clip_obs=norm.clip_obs if norm is not None else 10.0,
                   epsilon=norm.epsilon if norm is not None else 1e-8,
                   env_id=agent_meta["env_id"], env_kwargs=agent_meta["env_kwargs"],
                   training={**agent_meta["training"], "num_timesteps": int(model.num_timesteps)},
                   hybrid=agent_meta["hybrid"], features=agent_meta["features"])

    class RunEvalCallback(EvalCallback):
        """EvalCallback that also writes the best agent (safe format).

        It evaluates at the very end too, whatever the budget.
        """

        def _on_step(self) -> bool:
            best = self.best_mean_reward
            result = super()._on_step()
            if self.best_mean_reward > best:
                save_safe(self.model, self.eval_env, ".")
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
        """Rewrites ``train_info.json`` every ``PROGRESS_EVERY_S`` s (wall time survives a kill)."""

        def _on_training_start(self) -> None:
            self.t0 = time.perf_counter()
            self.last = -math.inf
            self.write("running")

        def _on_step(self) -> bool:
            if time.perf_counter() - self.last >= PROGRESS_EVERY_S:
                self.write("running")
            return True

        def write(self, status: str) -> float:
            now = time.perf_counter()
            self.last = now
            wall = previous_wall + (now - self.t0)
            _write_info(out, {**info_base, "status": status,
                              "num_timesteps": int(self.model.num_timesteps),
                              "wall_time_s": round(wall, 1)})
            return wall

    evaluator = RunEvalCallback(eval_env, n_eval_episodes=args.eval_episodes,
                                eval_freq=max(eval_freq // n_envs, 1),
                                log_path=str(out / "eval"), best_model_save_path=str(out),
                                deterministic=True, verbose=args.verbose)
    checkpoints = CheckpointCallback(save_freq=max(ckpt_freq // n_envs, 1),
                                     save_path=str(out / "checkpoints"), name_prefix="model",
                                     save_vecnormalize=True, save_replay_buffer=off_policy)
    progress = ProgressCallback()
    return evaluator, checkpoints, progress, save_safe


def _write_info(out: Path, info: dict) -> None:
    tmp = out / "train_info.json.tmp"
    tmp.write_text(json.dumps(info, indent=2))
    tmp.replace(out / "train_info.json")


def _make_venv(env_id, n_envs, seed, env_kwargs, residual: ResidualSpec | None = None,
               features: FeatureSpec | None = None):
    """The (monitored) training or evaluation vec env; the hybrid's when ``residual``.

    The residual wrapper sits below ``VecNormalize`` (added by the caller): its base
    law and filter read raw observations. The policy's input ``features`` are appended
    above it, also below ``VecNormalize``.
    """
    from stable_baselines3.common.vec_env import VecEnv, VecMonitor

    from .vec_env import make_sb3_vec_env

    venv: VecEnv
    if env_id == tether_gym.ENV_ID:
        venv = make_sb3_vec_env(n_envs, seed=seed, env_kwargs=env_kwargs)
    else:  # any other registered id: SB3's generic path
        from stable_baselines3.common.env_util import make_vec_env

        venv = make_vec_env(env_id, n_envs=n_envs, seed=seed, env_kwargs=env_kwargs)
    if residual is not None:
        from .residual_env import ResidualVecEnv

        venv = ResidualVecEnv.from_spec(venv, residual)
    if features is not None:
        from .vec_env import FeatureVecEnv

        venv = FeatureVecEnv(venv, features)
    return VecMonitor(venv)


# ---------------------------------------------------------------------- main
def main(argv=None) -> int:
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


def _resolve(args) -> dict:
    """Every setting of one run, validated before any work starts (raises ConfigError)."""
    import yaml

    _check_args(args)
    _check_env_id(args.env_id)
    user_kwargs = parse_env_kwargs(args.env_kwargs)
    out = Path(args.out) if args.out is not None else Path("runs") / args.algo
    if args.resume:
        resolved = out / "config.yml"
        if not resolved.is_file():
            raise ConfigError(f"--resume: {resolved} not found (is {out} a run folder?)")
        saved = yaml.safe_load(resolved.read_text()) or {}
        if saved.get("algo") not in (None, args.algo):
            raise ConfigError(f"--resume: {out} is a {saved['algo'].upper()} run; pass "
                              f"--algo {saved['algo']}")
        params = dict(saved["hyperparams"])
        source = str(resolved)
    else:
        config_path = Path(args.config) if args.config is not None else (
            CONFIG_DIR / f"{args.algo}.yml")
        params = load_hyperparams(config_path, args.algo, args.env_id)
        source = str(config_path)
    run = {k: params.pop(k) for k in RUN_KEYS if k in params}
    if "policy_kwargs" in params and not isinstance(params["policy_kwargs"], dict):
        raise ConfigError(f"{source}: policy_kwargs must be a mapping, not "
                          f"{params['policy_kwargs']!r} (no code is evaluated)")
    env_kwargs, notes = resolve_env_kwargs(run.get("env_kwargs") or {}, user_kwargs, source)
    residual = residual_spec(run.get("residual"), source)
    if residual is not None and args.env_id != tether_gym.ENV_ID:
        raise ConfigError(f"{source}: residual needs --env-id {tether_gym.ENV_ID} (the base law "
                          f"and filter are built for it), got {args.env_id!r}")
    features = feature_spec(run.get("features"), source)
    if features is not None and args.env_id != tether_gym.ENV_ID:
        raise ConfigError(f"{source}: features need --env-id {tether_gym.ENV_ID} (they read "
                          f"its observation), got {args.env_id!r}")
    env_kwargs = _rate_mode_for(residual, env_kwargs, source, notes)
    _check_env(args.env_id, env_kwargs, args.env_kwargs, source)
    n_envs = args.n_envs if args.n_envs is not None else int(run.get("n_envs", 1))
    timesteps = args.timesteps if args.timesteps is not None else int(run.get("n_timesteps",
                                                                              100_000))
    eval_freq = args.eval_freq if args.eval_freq is not None else int(run.get("eval_freq",
                                                                              10_000))
    ckpt_freq = (args.checkpoint_freq if args.checkpoint_freq is not None
                 else int(run.get("checkpoint_freq", 100_000)))
    _check_out(out)
    if residual is not None:
        run["residual"] = residual.to_dict()
    if features is not None:
        run["features"] = features.to_dict()
    return {"out": out, "params": params, "run": run, "env_kwargs": env_kwargs, "notes": notes,
            "residual": residual, "features": features, "n_envs": n_envs, "timesteps": timesteps,
            "eval_freq": eval_freq, "ckpt_freq": ckpt_freq, "source": source}


def _train(args, argv) -> int:
    """Train one run folder (``args.out``) with the settings of ``args``."""
    cfg = _resolve(args)
    import torch
    from stable_baselines3.common.vec_env import VecNormalize

    torch.set_num_threads(args.torch_threads)
    out, params, run = cfg["out"], cfg["params"], cfg["run"]
    env_kwargs, n_envs = cfg["env_kwargs"], cfg["n_envs"]
    print(f"env {args.env_id} with env kwargs {json.dumps(env_kwargs)}")
    for note in cfg["notes"]:
        print(f"  note: {note}")
    norm = run.get("normalize", False)
    norm_kwargs = norm if isinstance(norm, dict) else {}
    gamma = params.get("gamma", 0.99)
    tb_log = str(out / "tb")

    residual, features = cfg["residual"], cfg["features"]
    venv = _make_venv(args.env_id, n_envs, args.seed, env_kwargs, residual, features)
    eval_env = _make_venv(args.env_id, 1, args.seed + 10_000, env_kwargs, residual, features)
    if residual is not None:
        print(f"  residual hybrid: {json.dumps(residual.to_dict())}: the agent learns a in "
              "u = filter(clip(u_smc + scale * a, -1, 1))")
    algo_cls = _algo_class(args.algo)
    info_path = out / "train_info.json"
    previous = json.loads(info_path.read_text()) if (args.resume and info_path.is_file()) else {}
    if args.resume:
        model, venv, eval_env, model_path, buffer_loaded = _load_resume_point(
            out, algo_cls, venv, eval_env, norm is not False, tb_log)
        start = int(model.num_timesteps)
        removed = _truncate_tensorboard(out / "tb", start)
        print(f"resuming from {model_path} at step {start}"
              + (f" with its replay buffer "
                 f"({model.replay_buffer.size() * model.replay_buffer.n_envs} transitions)"
                 if buffer_loaded else "")
              + (f"; {removed} TensorBoard events after step {start} removed" if removed else ""))
    else:
        if norm is not False:
            venv = VecNormalize(venv, gamma=gamma, **norm_kwargs)
            eval_env = VecNormalize(eval_env, gamma=gamma, training=False,
                                    norm_obs=norm_kwargs.get("norm_obs", True), norm_reward=False,
                                    clip_obs=norm_kwargs.get("clip_obs", 10.0))
        model = algo_cls(run.get("policy", "MlpPolicy"), venv, seed=args.seed, device="cpu",
                         tensorboard_log=tb_log, verbose=args.verbose, **with_schedules(params))
    resolved_config = {"algo": args.algo, "env_id": args.env_id, "env_kwargs": env_kwargs,
                       "n_envs": n_envs, "seed": args.seed,
                       "hyperparams": {**params, **run, "env_kwargs": env_kwargs,
                                       "n_envs": n_envs, "eval_freq": cfg["eval_freq"],
                                       "checkpoint_freq": cfg["ckpt_freq"]}}
    (out / "config.yml").write_text(_yaml_dump(resolved_config))
    (out / "args.yml").write_text(_yaml_dump(vars(args)))
    command = "python train.py " + " ".join(shlex.quote(a) for a in
                                             (sys.argv[1:] if argv is None else argv))
    with open(out / "command.txt", "a") as fh:
        fh.write(command + "\n")
    info_base = {"algo": args.algo, "env_id": args.env_id, "seed": args.seed,
                 "torch_threads": args.torch_threads, "command": command,
                 "tether_gym": tether_gym.__version__}
    agent_meta = {"algo": args.algo, "env_id": args.env_id, "env_kwargs": env_kwargs,
                  "training": {"seed": args.seed, "command": command},
                  "hybrid": residual.to_dict() if residual is not None else None,
                  "features": features.to_dict() if features is not None else None}
    evaluator, checkpoints, progress, save_safe = _callbacks(
        eval_env, out, args, cfg["eval_freq"], cfg["ckpt_freq"], n_envs, agent_meta, info_base,
        float(previous.get("wall_time_s", 0.0)), hasattr(model, "replay_buffer"))
    history = out / "eval" / "evaluations.npz"
    if args.resume and history.is_file():  # the learning curve continues, not restarts
        dropped = _continue_eval_history(evaluator, history, int(model.num_timesteps))
        if dropped:
            print(f"  dropped {dropped} evaluation(s) after step {model.num_timesteps} from "
                  f"{history} (the resumed run repeats those steps)")
    t0 = time.perf_counter()
    model.learn(cfg["timesteps"], callback=[evaluator, checkpoints, progress],
                progress_bar=not args.no_progress, reset_num_timesteps=not args.resume,
                tb_log_name=args.algo)
    wall = time.perf_counter() - t0
    model.save(out / "final_model.zip")
    env = model.get_env()
    if isinstance(env, VecNormalize):
        env.save(str(out / "vecnormalize.pkl"))
    if hasattr(model, "replay_buffer"):
        model.save_replay_buffer(out / "final_replay_buffer.pkl")
    save_safe(model, env, "final_agent")
    total_wall = progress.write("finished")
    plot_learning_curve(out)
    venv.close()
    eval_env.close()
    print(f"trained {args.algo.upper()} to step {model.num_timesteps} in {wall:.0f} s "
          f"({total_wall:.0f} s in all calls); run folder {out}; evaluate with "
          f"`python evaluate.py {out}`")
    return 0
