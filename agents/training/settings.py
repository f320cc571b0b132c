"""The settings of a training run: the command line as a typed record, resolved once.

:class:`TrainOptions` is ``train.py``'s command line, typed and checked without reading
any file. :func:`resolve_settings` reads the hyperparameter file (or, for ``--resume``,
the run folder's ``config.yml``), resolves the env kwargs and checks them by building
the env once, and returns a :class:`TrainSettings`: the frozen record that
:func:`tether_gym_agents.training.run.train` trains from. The fan-out and the sweep
derive the record of each seed with :meth:`TrainSettings.for_seed`
(``dataclasses.replace``), so nothing is parsed or resolved twice. Every problem is a
:class:`~tether_gym_agents.training.config.ConfigError` whose message names the
option or the file line and the valid values.
"""

from __future__ import annotations

import shlex
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import tether_gym

from ..common.algorithms import algorithm
from ..common.features import FeatureSpec
from ..common.ranges import MAX_TORCH_THREADS
from ..files.run_folder import (
    ARGS_FILE,
    BEST_MODEL_FILE,
    COMMAND_FILE,
    CONFIG_FILE,
    EVALUATIONS_FILE,
    FINAL_MODEL_FILE,
    LEARNING_CURVE_FILE,
    REPLAY_BUFFER_FILE,
    TRAIN_INFO_FILE,
    VECNORMALIZE_FILE,
    check_fresh_run_folder,
    check_writable_folder,
    read_config,
)
from ..files.safe_format import ALGOS
from ..hybrids.residual_spec import ResidualSpec
from .bc_term import BC_KEY, BCTermSpec, bc_term_spec
from .config import (
    CONFIG_DIR,
    MAX_TIMESTEPS,
    RUN_KEYS,
    ConfigError,
    check_algo_params,
    check_counts,
    check_env,
    check_env_id,
    feature_spec,
    fit_rollout,
    load_hyperparams,
    parse_env_kwargs,
    rate_mode_for,
    residual_spec,
    resolve_env_kwargs,
)
from .hyperparams import check_n_envs, check_rollout
from .warm_start import INIT_KEY, check_init_policy

__all__ = ["ALGOS", "SEED_MAX", "ConfigError", "TrainOptions", "TrainSettings",
           "resolve_settings", "check_ray_address", "RAY_ADDRESS_FORMS"]

SEED_MAX = 2**31 - 1
RAY_ADDRESS_FORMS = "'auto', 'local', HOST:PORT or ray://HOST:PORT (PORT in 1 ... 65535)"
_AT_LEAST_ONE = ("n_envs", "timesteps", "eval_freq", "checkpoint_freq", "eval_episodes",
                 "torch_threads", "seeds")
_AT_MOST = {"timesteps": MAX_TIMESTEPS, "eval_episodes": 10_000, "seeds": 1000,
            "torch_threads": MAX_TORCH_THREADS}
"""Upper bounds of options that would otherwise run without end (1e30 steps, 1e9
episodes per evaluation, 1e9 Ray tasks) or crash (100,000 torch threads)."""
_WHY = {"timesteps": "env steps to train; the shipped runs train 3e6",
        "eval_episodes": "episodes per evaluation", "seeds": "training runs",
        "torch_threads": "torch threads per training process"}
_PATHS = ("config", "out", "sweep")
"""Options that name files: made absolute in :meth:`TrainOptions.argv` (other nodes)."""


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


@dataclass(frozen=True)
class TrainOptions:
    """``train.py``'s command line, typed; checked on creation (no file is read).

    The fields are the options of ``train.py --help`` with their defaults; None means
    "the config's value". Creating one (also through ``dataclasses.replace``) raises
    ConfigError for a value out of range, naming the option and the valid range.
    """

    algo: str = "ppo"
    env_id: str = tether_gym.ENV_ID
    env_kwargs: tuple[str, ...] = ()
    n_envs: int | None = None
    timesteps: int | None = None
    seed: int = 0
    config: str | None = None
    out: str | None = None
    resume: bool = False
    allow_pickle: bool = False
    eval_freq: int | None = None
    eval_episodes: int = 5
    checkpoint_freq: int | None = None
    torch_threads: int = 1
    no_progress: bool = False
    verbose: int = 0
    seeds: int | None = None
    ray_address: str | None = None
    sweep: Path | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "env_kwargs", tuple(self.env_kwargs))
        if self.algo not in ALGOS:
            raise ConfigError(f"--algo {self.algo!r}: must be one of {list(ALGOS)}")
        for name in _AT_LEAST_ONE:
            value = getattr(self, name)
            high = _AT_MOST.get(name)
            if value is not None and value < 1:
                raise ConfigError(f"{_flag(name)} {value}: must be an integer >= 1")
            if value is not None and high is not None and value > high:
                raise ConfigError(f"{_flag(name)} {value}: must be an integer in [1, {high}] "
                                  f"({_WHY[name]})")
        if not 0 <= self.seed <= SEED_MAX:
            raise ConfigError(f"--seed {self.seed}: must be an integer in [0, {SEED_MAX}]")
        if self.config is not None:
            if not self.config.strip():
                raise ConfigError(f"--config {self.config!r}: must be the path of a YAML file")
            if Path(self.config).is_dir():
                raise ConfigError(f"--config {self.config!r}: is a folder; give a YAML file")
        if self.out is not None and not self.out.strip():
            raise ConfigError(f"--out {self.out!r}: must be the path of a folder")
        self._check_many_runs()
        check_env_id(self.env_id)
        parse_env_kwargs(list(self.env_kwargs))  # malformed entries fail here

    def _check_many_runs(self) -> None:
        """The options of ``--seeds``, ``--sweep`` and ``--ray-address`` fit together."""
        many = self.seeds is not None or self.sweep is not None
        if self.resume and many:
            raise ConfigError("--resume cannot be combined with --seeds or --sweep: re-running "
                              "the same command resumes the interrupted seeds and skips "
                              "finished ones")
        if self.ray_address is not None:
            check_ray_address(self.ray_address, "--ray-address")
            if not many:
                raise ConfigError(f"--ray-address {self.ray_address} needs --seeds N or "
                                  "--sweep FILE.yml")

    @classmethod
    def from_namespace(cls, args) -> TrainOptions:
        """From ``train.py``'s parsed arguments (an ``argparse.Namespace``)."""
        return cls(**{f.name: getattr(args, f.name) for f in fields(cls)})

    @property
    def config_path(self) -> Path:
        """The hyperparameter file: ``--config``, else the packaged ``configs/<algo>.yml``."""
        return Path(self.config) if self.config else CONFIG_DIR / f"{self.algo}.yml"

    @property
    def user_env_kwargs(self) -> dict:
        """``--env-kwargs`` as a dict of Python literals."""
        return parse_env_kwargs(list(self.env_kwargs))

    def argv(self, keep: tuple[str, ...] = ()) -> tuple[str, ...]:
        """The ``train.py`` arguments of these options.

        Those that differ from their default, and the fields named in ``keep`` even at
        their default, in ``--help`` order, paths made absolute (the line runs on any
        node of a cluster).
        """
        out: list[str] = []
        for f in fields(self):
            value = getattr(self, f.name)
            if value == f.default and f.name not in keep:
                continue
            if isinstance(value, bool):
                out.append(_flag(f.name))
                continue
            items = value if isinstance(value, tuple) else (value,)
            out.append(_flag(f.name))
            out.extend(str(Path(v).absolute()) if f.name in _PATHS else str(v) for v in items)
        return tuple(out)

    def seed_run(self, seed: int, out: Path, **changes) -> TrainOptions:
        """The options of one seed of a fan-out or a sweep, run in a task.

        A single run of ``seed`` into ``out``, without a progress bar, with
        ``--verbose`` at least 1 (the task's log shows SB3's tables) and the paths
        absolute; ``changes`` set further fields (``timesteps``, ``config``).
        """
        config = str(Path(self.config).absolute()) if self.config else None
        return replace(self, **{"seed": seed, "out": str(Path(out).absolute()),
                                "config": config, "seeds": None, "sweep": None,
                                "ray_address": None, "no_progress": True,
                                "verbose": max(self.verbose, 1), **changes})

    def as_dict(self) -> dict:
        """The options as plain data (what ``args.yml`` records)."""
        return asdict(self)


@dataclass(frozen=True, kw_only=True)
class TrainSettings:
    """Everything one training run needs, resolved from the options and the config.

    Built by keyword only (a field inserted in the record cannot shift the others).

    Attributes
    ----------
    options : TrainOptions
        The command line of this run (recorded in ``args.yml``).
    out : Path
        The run folder.
    hyperparams : dict
        The algorithm's keyword arguments (``lin_<start>`` schedules as written).
    run : dict
        ``train.py``'s own keys of the config (:data:`~.config.RUN_KEYS`: policy,
        normalize, ...; ``residual`` and ``features`` as checked dicts).
    env_kwargs : dict
        The resolved env kwargs (plain data).
    residual : ResidualSpec or None
        The hybrid whose residual is trained (None: a policy that acts alone).
    features : FeatureSpec or None
        Input features appended to the policy's observation.
    bc_term : BCTermSpec or None
        Supervised steps on stored mpc labels between PPO's updates (None: none).
    n_envs, timesteps, eval_freq, checkpoint_freq : int
        Parallel envs, env steps to train in this call, env steps between evaluations
        and between checkpoints [-].
    source : str
        The file the hyperparameters came from.
    notes : tuple of str
        What the resolution changed, to print.
    command : tuple of str
        The ``train.py`` arguments recorded in ``command.txt``.
    """

    options: TrainOptions
    out: Path
    hyperparams: dict[str, Any]
    run: dict[str, Any]
    env_kwargs: dict[str, Any]
    residual: ResidualSpec | None
    features: FeatureSpec | None
    bc_term: BCTermSpec | None
    n_envs: int
    timesteps: int
    eval_freq: int
    checkpoint_freq: int
    source: str
    notes: tuple[str, ...] = ()
    command: tuple[str, ...] = field(default=())

    def __post_init__(self) -> None:
        for name in ("n_envs", "timesteps", "eval_freq", "checkpoint_freq"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ConfigError(f"{name} {value!r}: must be an integer >= 1")
        object.__setattr__(self, "out", Path(self.out))
        object.__setattr__(self, "notes", tuple(self.notes))
        object.__setattr__(self, "command", tuple(self.command))

    @property
    def algo(self) -> str:
        """The learning algorithm: a name of :data:`~..common.algorithms.ALGORITHMS`."""
        return self.options.algo

    @property
    def env_id(self) -> str:
        """The registered env id."""
        return self.options.env_id

    @property
    def seed(self) -> int:
        """The seed of the model and the training envs (evaluation: ``seed + 10000``)."""
        return self.options.seed

    @property
    def resume(self) -> bool:
        """Continue the run in :attr:`out` from its latest good saved model."""
        return self.options.resume

    @property
    def normalize(self) -> bool | dict:
        """The config's ``normalize``: False, True or VecNormalize's keyword arguments."""
        return self.run.get("normalize", False)

    @property
    def command_line(self) -> str:
        """``python train.py ...`` with :attr:`command` (a line of ``command.txt``)."""
        return "python train.py " + " ".join(shlex.quote(a) for a in self.command)

    def resolved_config(self) -> dict:
        """What ``config.yml`` records: algorithm, env, seed and every hyperparameter."""
        return {"algo": self.algo, "env_id": self.env_id, "env_kwargs": self.env_kwargs,
                "n_envs": self.n_envs, "seed": self.seed,
                "hyperparams": {**self.hyperparams, **self.run, "env_kwargs": self.env_kwargs,
                                "n_envs": self.n_envs, "eval_freq": self.eval_freq,
                                "checkpoint_freq": self.checkpoint_freq}}

    def for_seed(self, seed: int, out: Path, timesteps: int | None = None) -> TrainSettings:
        """These settings for one seed of a fan-out or a sweep, trained into ``out``.

        The record is copied with ``dataclasses.replace``: the same hyperparameters
        and env, the options of :meth:`TrainOptions.seed_run`, and the command line that
        reproduces the seed as a single run (``command.txt``; ``--seed`` is written for
        seed 0 too, so that every seed folder names its seed).
        """
        changes = {} if timesteps is None else {"timesteps": timesteps}
        options = self.options.seed_run(seed, out, **changes)
        return replace(self, options=options, out=Path(options.out or out),
                       timesteps=timesteps or self.timesteps,
                       command=options.argv(keep=("seed",)))


def resolve_settings(options: TrainOptions, command: tuple[str, ...] | None = None
                     ) -> TrainSettings:
    """Read the config, resolve and check everything a run needs, before any training.

    Parameters
    ----------
    options : TrainOptions
        The command line (``--resume`` reads the hyperparameters from the run
        folder's ``config.yml`` instead of the config file).
    command : tuple of str or None
        The arguments to record in ``command.txt`` (default: ``options.argv()``).

    Raises
    ------
    ConfigError
        For anything that would make the run fail or differ from what was asked; the
        run folder is made (and checked writable) only when everything else is valid.
    """
    if options.algo == "ppo_lag" and options.env_id != tether_gym.ENV_ID:
        raise ConfigError(f"--algo ppo_lag needs --env-id {tether_gym.ENV_ID} (its info holds "
                          f"the constraint cost the algorithm learns from), got "
                          f"{options.env_id!r}")
    out = Path(options.out) if options.out is not None else Path("runs") / options.algo
    params, source = _read_params(options, out)
    check_algo_params(params, options.algo, source)
    check_counts(params, source)  # a run's config.yml too: int(nan) below would raise
    run = {k: params.pop(k) for k in RUN_KEYS if k in params}
    if "policy_kwargs" in params and not isinstance(params["policy_kwargs"], dict):
        raise ConfigError(f"{source}: policy_kwargs must be a mapping, not "
                          f"{params['policy_kwargs']!r} (no code is evaluated)")
    env_kwargs, notes = resolve_env_kwargs(run.get("env_kwargs") or {}, options.user_env_kwargs,
                                           source)
    residual = residual_spec(run.get("residual"), source)
    if residual is not None and options.env_id != tether_gym.ENV_ID:
        raise ConfigError(f"{source}: residual needs --env-id {tether_gym.ENV_ID} (the base law "
                          f"and filter are built for it), got {options.env_id!r}")
    features = feature_spec(run.get("features"), source)
    if features is not None and options.env_id != tether_gym.ENV_ID:
        raise ConfigError(f"{source}: features need --env-id {tether_gym.ENV_ID} (they read "
                          f"its observation), got {options.env_id!r}")
    env_kwargs = rate_mode_for(residual, env_kwargs, source, notes)
    check_env(options.env_id, env_kwargs, list(options.env_kwargs), source)
    if INIT_KEY in run and not options.resume:  # a resumed run starts from its checkpoint
        run[INIT_KEY] = check_init_policy(run[INIT_KEY], source, options.algo, features,
                                          env_kwargs, run.get("normalize", False),
                                          options.seed)
    bc_term = bc_term_spec(run.get(BC_KEY), source, options.algo)

    def pick(given, key, default):
        return given if given is not None else int(run.get(key, default))

    counts = {"n_envs": pick(options.n_envs, "n_envs", 1),
              "timesteps": pick(options.timesteps, "n_timesteps", 100_000),
              "eval_freq": pick(options.eval_freq, "eval_freq", 10_000),
              "checkpoint_freq": pick(options.checkpoint_freq, "checkpoint_freq", 100_000)}
    if not options.resume:
        params, fitted = fit_rollout(params, options.algo, counts["n_envs"],
                                     counts["timesteps"])
        notes += [fitted] if fitted else []
    _check_sizes(params, options, counts["n_envs"], source)
    _check_out(out, options.resume)
    if residual is not None:
        run["residual"] = residual.to_dict()
    if features is not None:
        run["features"] = features.to_dict()
    if bc_term is not None:
        run[BC_KEY] = bc_term.to_dict()
    return TrainSettings(options=options, out=out, hyperparams=params, run=run,
                         env_kwargs=env_kwargs, residual=residual, features=features,
                         bc_term=bc_term,
                         **counts, source=source, notes=tuple(notes),
                         command=options.argv() if command is None else tuple(command))


def check_ray_address(address, source: str = "--ray-address") -> str:
    """``address`` if it has the form of a Ray address, else a ConfigError naming ``source``.

    The forms: ``auto`` (the cluster ``ray start`` runs on this machine), ``local`` (a new
    local instance), ``HOST:PORT`` and ``ray://HOST:PORT`` (Ray Client), HOST a host name,
    an IPv4 address or a bracketed IPv6 address. Nothing is contacted here.
    """
    import ipaddress
    import re

    text = str(address).strip()
    if text in ("auto", "local"):
        return text
    host, sep, port = text.removeprefix("ray://").rpartition(":")
    ok = bool(sep) and port.isascii() and port.isdigit() and 1 <= int(port) <= 65535
    if ok and host.startswith("[") and host.endswith("]"):
        try:
            ipaddress.IPv6Address(host[1:-1])
        except ValueError:
            ok = False
    elif ok:
        ok = re.fullmatch(r"\w[\w-]{0,62}(\.\w[\w-]{0,62})*", host, re.ASCII,
) is not None
    if not ok:
        raise ConfigError(f"{source} {str(address)!r} is not a Ray address; give "
                          f"{RAY_ADDRESS_FORMS}")
    return text


def _read_params(options: TrainOptions, out: Path) -> tuple[dict, str]:
    """The hyperparameters of a run and the file they came from."""
    if not options.resume:
        path = options.config_path
        return load_hyperparams(path, options.algo, options.env_id), str(path)
    resolved = out / CONFIG_FILE
    try:
        saved = read_config(out)
    except FileNotFoundError:
        raise ConfigError(f"--resume: {resolved} not found (is {out} a run folder?)") from None
    except (OSError, ValueError, RecursionError) as exc:  # a FIFO, a link out, bad YAML
        message = " ".join(str(exc).split())
        raise ConfigError(f"--resume: {resolved} cannot be read: {message}") from None
    if not isinstance(saved, dict):
        raise ConfigError(f"--resume: {resolved} is not a mapping of run settings")
    if "algo" in saved:
        try:
            name = algorithm(saved["algo"]).name
        except (TypeError, ValueError):
            raise ConfigError(f"--resume: {resolved}: algo: {saved['algo']!r} must be one of "
                              f"{list(ALGOS)}") from None
        if name != options.algo:
            raise ConfigError(f"--resume: {out} is a {name.upper()} run; pass --algo {name}")
    if not isinstance(saved.get("hyperparams"), dict):
        raise ConfigError(f"--resume: {resolved} records no hyperparams")
    return dict(saved["hyperparams"]), str(resolved)


def _check_sizes(params: dict, options: TrainOptions, n_envs: int, source: str) -> None:
    """``n_envs`` and the rollout or batch a run uses, within bounds before any allocation.

    The config's ``n_envs`` was checked with its file; ``--n-envs`` is checked here, and
    the rollout ``n_steps x n_envs`` (PPO, after :func:`~.config.fit_rollout`) or the
    batch within the buffer (off-policy) with the ``n_envs`` the run uses.
    """
    try:
        check_n_envs(n_envs, "--n-envs" if options.n_envs is not None else f"{source}: n_envs")
        check_rollout(params, options.algo, n_envs, source)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


_WRITTEN_FILES = (CONFIG_FILE, ARGS_FILE, COMMAND_FILE, TRAIN_INFO_FILE, EVALUATIONS_FILE,
                  LEARNING_CURVE_FILE, BEST_MODEL_FILE, FINAL_MODEL_FILE, VECNORMALIZE_FILE,
                  REPLAY_BUFFER_FILE)
"""Files a run writes at the top of its folder (a folder in their place is refused)."""


def _check_out(out: Path, resume: bool) -> None:
    """The run folder can be written, and a fresh run there would not mix with an older one."""
    try:
        if resume:
            check_writable_folder(out, _WRITTEN_FILES)
        else:
            check_fresh_run_folder(out, _WRITTEN_FILES, "continue it with --resume, or give "
                                   "a new folder (or remove this one first)")
    except ValueError as exc:
        raise ConfigError(f"--out {str(out)!r}: {exc}") from None
