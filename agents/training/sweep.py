"""Hyperparameter sweeps with several seeds per trial: the code behind ``train.py --sweep``.

``python train.py --algo ppo --sweep sweep.yml --out runs/sweep`` trains every
configuration ("trial") of the sweep with ``seeds_per_trial`` seeds, each seed a
normal run folder ``runs/sweep/trial_003/seed_K/`` trained like ``train.py --seeds``
(Ray tasks, one CPU each; finished runs are skipped and interrupted ones resumed when
the command is run again). Configurations are ranked by the **median over seeds of
the final evaluation return** (the mean return of the last evaluation in each run's
``eval/evaluations.npz``); a trial whose seed has no evaluation ranks last. The table
goes to ``sweep_results.md`` and ``sweep_results.csv`` in ``--out`` and to the screen.

Ranking on one seed per trial picks lucky seeds, not good settings (the trap of
rl-baselines3-zoo's tuner, its issues #204 and #151): ``seeds_per_trial`` is at least 2.

Sweep file (YAML, read with ``common.yamlio.load_yaml_file``: a regular file of at most
256 KiB, no anchors or aliases; unknown keys are rejected)::

    search: grid            # grid (every combination) | random | optuna
    seeds_per_trial: 3      # seeds --seed ... --seed+n-1 per trial, 2 .. 100 (default 3)
    num_samples: 8          # random and optuna: number of trials, <= 10000 (default 8)
    sample_seed: 0          # random and optuna: seed of the draws (a rerun draws the same)
    timesteps: 200000       # env steps per run (default: --timesteps, else n_timesteps)
    params:                 # any key of the hyperparameter file; dots reach into mappings
      learning_rate: [1.0e-4, 3.0e-4]           # a list: the values to try
      gamma: {values: [0.99, 0.995]}            # the same, spelt out
      ent_coef: {uniform: [0.0, 0.01]}          # random/optuna: uniform in [low, high]
      clip_range: {loguniform: [0.05, 0.3]}     # random/optuna: log-uniform, low > 0
      n_epochs: {randint: [5, 20]}              # random/optuna: integer in [low, high]
      policy_kwargs.net_arch: [[64, 64], [256, 256]]
      env_kwargs.disturbance: [0.0, 0.1]
    asha:                   # optuna only: ASHA early stopping over training chunks
      chunks: 4             # each run reports after target/chunks, 2*target/chunks, ... steps
      grace_period: 1       # chunks every trial trains before it can be stopped
      reduction_factor: 2

The hyperparameters of a trial are the base config (``--config`` or the packaged
``configs/<algo>.yml``) with the trial's values set; they are written to
``trial_NNN/hyperparams.yml``; the settings of a trial are resolved from that file
once (:func:`~tether_gym_agents.training.settings.resolve_settings`), and each seed's
record is derived from them (:meth:`~tether_gym_agents.training.settings.TrainSettings.for_seed`)
and trained by :func:`tether_gym_agents.training.run.train` in a Ray task, so every seed
folder is a single run that ``train.py --config trial_NNN/hyperparams.yml --seed K
--out trial_NNN/seed_K`` reproduces (its ``command.txt``). ``--seeds N`` on the
command line overrides ``seeds_per_trial``.

``search: optuna`` runs the trials as Ray Tune trials with Optuna's sampler
(``pip install optuna``) and ASHA: every trial trains its seeds one after the other,
chunk by chunk (resuming each run), and reports the median over its seeds after
every chunk; ASHA stops the trials whose median falls behind, and the table lists
them after the complete ones, with the step at which they stopped. Its trial folders
are named by Tune's trial id (``trial_1a2b3c4d``) and Tune keeps its own experiment
state in ``<out>/tune`` (its ``storage_path``); unlike grid and random sweeps, a
rerun of an Optuna sweep starts new trials.
"""

from __future__ import annotations

import csv
import itertools
import json
import math
import statistics
import sys
import time
from dataclasses import dataclass, replace
from enum import Enum
from pathlib import Path

from ..common.jsonio import loads_json
from ..files.run_folder import (
    FANOUT_LOG_FILE,
    DamagedFileError,
    read_evaluations,
    seed_dir,
    write_text_atomic,
)
from .config import ConfigError, load_hyperparams
from .fanout import (
    INTERRUPTED,
    SeedJob,
    SeedStatus,
    init_ray,
    require_ray,
    run_jobs,
    shutdown_ray,
    train_seed,
)
from .settings import TrainOptions, TrainSettings, resolve_settings

__all__ = ["Search", "SweepSpec", "load_sweep", "expand_trials", "apply_overrides",
           "final_eval_return", "rank_trials", "write_table", "run_sweep", "MAX_TRIALS",
           "MAX_SEEDS_PER_TRIAL"]

FILE_KEYS = ("search", "seeds_per_trial", "num_samples", "sample_seed", "timesteps", "params",
             "asha")
DISTRIBUTIONS = ("values", "uniform", "loguniform", "randint")
ASHA_KEYS = ("chunks", "grace_period", "reduction_factor")
OPTUNA_PIP = "pip install optuna"
MAX_TRIALS = 10_000
"""Most trials of a sweep (a grid's product of value counts, or ``num_samples``); each
trial is a set of runs, so 10^4 trials is already months of training. Checked before
the grid is expanded (a grid of 10^12 trials ran out of memory)."""
MAX_SEEDS_PER_TRIAL = 100
"""Most seeds per trial (``seeds_per_trial`` or ``--seeds``): a median over 100 seeds is
as stable as a ranking needs (1e9 seeds hung while the jobs were listed)."""


class Search(Enum):
    """How trials are chosen."""

    GRID = "grid"
    RANDOM = "random"
    OPTUNA = "optuna"


@dataclass(frozen=True)
class SweepSpec:
    """A validated sweep file.

    Attributes
    ----------
    search : Search
    seeds_per_trial : int
    num_samples : int
    sample_seed : int
    timesteps : int or None
    params : dict
        Dotted key -> ``("values", list)`` or ``(kind, (low, high))``.
    asha : dict
        ``chunks``, ``grace_period``, ``reduction_factor``.
    """

    search: Search
    seeds_per_trial: int
    num_samples: int
    sample_seed: int
    timesteps: int | None
    params: dict
    asha: dict


def _int(doc, key, default, low, path, high=None):
    value = doc.get(key, default)
    if value is None and default is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or value < low \
            or (high is not None and value > high):
        allowed = f">= {low}" if high is None else f"in [{low}, {high}]"
        raise ConfigError(f"{path}: {key} must be an integer {allowed}, got {value!r}")
    return value


def load_sweep(path: Path) -> SweepSpec:
    """Read and validate a sweep file (:func:`~..common.yamlio.load_yaml_file`: no code is run).

    Raises
    ------
    ConfigError
        On a missing or malformed file, an unknown key, a bad distribution, a grid over
        a continuous distribution or ``seeds_per_trial < 2``.
    """
    from ..common.yamlio import YamlFileError, load_yaml_file

    path = Path(path)
    try:
        doc = load_yaml_file(path, what="--sweep file")
    except YamlFileError as exc:
        raise ConfigError(str(exc)) from None
    if not isinstance(doc, dict):
        raise ConfigError(f"--sweep {path} must be a mapping with keys {list(FILE_KEYS)}")
    unknown = sorted(set(doc) - set(FILE_KEYS))
    if unknown:
        raise ConfigError(f"{path}: unknown key(s) {unknown}; valid keys: {list(FILE_KEYS)}")
    try:
        search = Search(doc.get("search", "grid"))
    except ValueError:
        raise ConfigError(f"{path}: search must be one of {[s.value for s in Search]}, got "
                          f"{doc.get('search')!r}") from None
    seeds = _int(doc, "seeds_per_trial", 3, 1, path)
    if seeds > MAX_SEEDS_PER_TRIAL:
        raise ConfigError(f"{path}: seeds_per_trial must be an integer in [2, "
                          f"{MAX_SEEDS_PER_TRIAL}], got {seeds!r}")
    if seeds < 2:
        raise ConfigError(f"{path}: seeds_per_trial must be >= 2, got {seeds}: a ranking of "
                          "single-seed trials ranks lucky seeds (rl-baselines3-zoo #204, #151)")
    raw = doc.get("params")
    if not isinstance(raw, dict) or not raw:
        raise ConfigError(f"{path}: params must map config keys to values or distributions")
    params = {}
    for key, spec in raw.items():
        params[str(key)] = _parse_param(path, str(key), spec, search)
    asha = doc.get("asha") or {}
    if not isinstance(asha, dict) or set(asha) - set(ASHA_KEYS):
        raise ConfigError(f"{path}: asha must be a mapping with keys {list(ASHA_KEYS)}, got "
                          f"{asha!r}")
    asha = {"chunks": _int(asha, "chunks", 4, 1, path),
            "grace_period": _int(asha, "grace_period", 1, 1, path),
            "reduction_factor": _int(asha, "reduction_factor", 2, 2, path)}
    if search is Search.GRID:
        n_trials = math.prod(len(arg) for _, arg in params.values())
        if n_trials > MAX_TRIALS:
            counts = " x ".join(str(len(arg)) for _, arg in params.values())
            raise ConfigError(f"{path}: the grid has {counts} = {n_trials} trials; allowed: at "
                              f"most {MAX_TRIALS} (search: random draws num_samples of them)")
    return SweepSpec(search, seeds, _int(doc, "num_samples", 8, 1, path, MAX_TRIALS),
                     _int(doc, "sample_seed", 0, 0, path), _int(doc, "timesteps", None, 1, path),
                     params, asha)


def _parse_param(path, key, spec, search):
    if isinstance(spec, list):
        spec = {"values": spec}
    if not isinstance(spec, dict) or len(spec) != 1 or next(iter(spec)) not in DISTRIBUTIONS:
        raise ConfigError(f"{path}: params.{key} must be a list of values or one of "
                          f"{{{', '.join(f'{d}: ...' for d in DISTRIBUTIONS)}}}, got {spec!r}")
    kind, arg = next(iter(spec.items()))
    if kind == "values":
        if not isinstance(arg, list) or not arg:
            raise ConfigError(f"{path}: params.{key}: values must be a non-empty list, "
                              f"got {arg!r}")
        return ("values", list(arg))
    if search is Search.GRID:
        raise ConfigError(f"{path}: params.{key} is a {kind} distribution, which a grid cannot "
                          f"enumerate: give a list of values or use search: random")
    ok = (isinstance(arg, list) and len(arg) == 2
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in arg)
          and arg[0] < arg[1])
    if ok and kind == "loguniform":
        ok = arg[0] > 0
    if ok and kind == "randint":
        ok = all(isinstance(v, int) for v in arg)
    if not ok:
        need = {"uniform": "[low, high] with low < high",
                "loguniform": "[low, high] with 0 < low < high",
                "randint": "[low, high], integers with low < high"}[kind]
        raise ConfigError(f"{path}: params.{key}: {kind} needs {need}, got {arg!r}")
    return (kind, tuple(arg))


def _draw(rng, kind, arg):
    if kind == "values":
        return arg[int(rng.integers(len(arg)))]
    if kind == "uniform":
        return float(rng.uniform(*arg))
    if kind == "loguniform":
        return float(math.exp(rng.uniform(math.log(arg[0]), math.log(arg[1]))))
    return int(rng.integers(arg[0], arg[1] + 1))


def expand_trials(spec: SweepSpec) -> list[dict]:
    """The trials of a grid or random sweep: one dict of dotted key -> value each.

    A grid is the product of the value lists in file order; a random search draws
    ``num_samples`` trials with ``numpy.random.default_rng(sample_seed)``.
    """
    import numpy as np

    keys = list(spec.params)
    if spec.search is Search.GRID:
        return [dict(zip(keys, combo, strict=True))
                for combo in itertools.product(*(spec.params[k][1] for k in keys))]
    rng = np.random.default_rng(spec.sample_seed)
    return [{k: _draw(rng, *spec.params[k]) for k in keys} for _ in range(spec.num_samples)]


def apply_overrides(params: dict, overrides: dict) -> dict:
    """``params`` with dotted keys set (``policy_kwargs.net_arch`` sets a nested value)."""
    out = json.loads(json.dumps(params))  # a deep copy of plain YAML data
    for dotted, value in overrides.items():
        *parents, leaf = dotted.split(".")
        node = out
        for i, part in enumerate(parents):
            child = node.setdefault(part, {})
            if not isinstance(child, dict):
                raise ConfigError(f"sweep key {dotted!r}: {'.'.join(parents[:i + 1])} is "
                                  f"{child!r}, not a mapping")
            node = child
        node[leaf] = value
    return out


def final_eval_return(run_dir: Path) -> float:
    """Mean return of the last evaluation in ``run_dir/eval/evaluations.npz``; NaN if none.

    A damaged file counts as none, with a line on stderr naming it (the ranking of the
    other trials goes on).
    """
    import numpy as np

    try:
        data = read_evaluations(run_dir)
    except DamagedFileError as exc:
        print(f"{exc}; counted as no return", file=sys.stderr)
        return float("nan")
    if data is None or data["results"].shape[0] == 0:
        return float("nan")
    return float(np.nanmean(data["results"][-1]))  # rows of shorter evaluations are NaN-padded


def rank_trials(trials: list[dict]) -> list[dict]:
    """Rank trials by the median over seeds of ``returns`` (best first; NaN last).

    Each trial is a dict with ``name``, ``params`` and ``returns`` (one per seed),
    optionally ``stopped`` (stopped early by ASHA: ranked after the complete trials);
    the result adds ``median``, ``mean``, ``min``, ``max`` and ``rank``.
    """
    rows = []
    for trial in trials:
        returns = list(trial["returns"])
        complete = bool(returns) and not any(math.isnan(r) for r in returns)
        stats = ({"median": statistics.median(returns), "mean": statistics.fmean(returns),
                  "min": min(returns), "max": max(returns)} if complete else
                 dict.fromkeys(("median", "mean", "min", "max"), float("nan")))
        rows.append({**trial, **stats})
    rows.sort(key=lambda r: (math.isnan(r["median"]), bool(r.get("stopped")),
                             0.0 if math.isnan(r["median"]) else -r["median"]))
    for i, row in enumerate(rows, 1):
        row["rank"] = i
    return rows


def _fmt(value) -> str:
    if isinstance(value, float):
        return "nan" if math.isnan(value) else f"{value:.4g}"
    return json.dumps(value) if isinstance(value, (list, dict)) else str(value)


def write_table(rows: list[dict], out: Path, keys: list[str]) -> str:
    """Write ``sweep_results.md`` and ``sweep_results.csv`` in ``out``; return the markdown."""
    head = ["rank", "trial", *keys, "median return", "mean", "min", "max", "seeds",
            "returns per seed"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    with open(Path(out) / "sweep_results.csv", "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(head)
        for r in rows:
            cells = [r["rank"], r["name"], *(_fmt(r["params"][k]) for k in keys),
                     _fmt(r["median"]), _fmt(r["mean"]), _fmt(r["min"]), _fmt(r["max"]),
                     len(r["returns"]), " ".join(_fmt(x) for x in r["returns"])]
            writer.writerow(cells)
            lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    text = ("Ranked by the median over seeds of the final evaluation return (higher is "
            "better).\n\n" + "\n".join(lines) + "\n")
    (Path(out) / "sweep_results.md").write_text(text)
    return text


def _trial_config(base: dict, overrides: dict, trial_dir: Path, algo: str, env_id: str) -> Path:
    """Write a trial's hyperparameter file (checked like any config) and the trial record."""
    import yaml

    trial_dir.mkdir(parents=True, exist_ok=True)
    record = trial_dir / "trial.json"
    wanted = json.dumps({"params": overrides}, sort_keys=True)
    if record.is_file():
        try:  # a record cut short or forged: a traceback before (JSONDecodeError)
            recorded = json.dumps(loads_json(record.read_bytes(), record), sort_keys=True)
        except (OSError, ValueError) as exc:
            raise ConfigError(f"{exc}; the trial record is damaged: remove {trial_dir} to "
                              "train the trial again, or give a new --out") from None
        if recorded != wanted:
            raise ConfigError(f"{trial_dir} was trained with other values ({recorded}, now "
                              f"{wanted}): the sweep file changed; give a new --out")
    config = trial_dir / "hyperparams.yml"
    write_text_atomic(config, yaml.safe_dump({"default": apply_overrides(base, overrides)},
                                             sort_keys=False))
    load_hyperparams(config, algo, env_id)  # unknown keys fail before any training
    write_text_atomic(record, wanted)
    return config


def _trial_settings(options: TrainOptions, base: dict, overrides: dict, trial_dir: Path,
                    target: int) -> TrainSettings:
    """The settings of a trial (its seeds follow with ``for_seed``), resolved once.

    The trial's hyperparameter file is written first; the settings are those of
    ``train.py --config trial_dir/hyperparams.yml --timesteps target``.
    """
    config = _trial_config(base, overrides, trial_dir, options.algo, options.env_id)
    return resolve_settings(replace(options, config=str(config), out=str(trial_dir),
                                    timesteps=target, seeds=None, sweep=None,
                                    ray_address=None))


def run_sweep(options: TrainOptions) -> int:
    """``train.py --sweep FILE.yml``; returns the exit code.

    Raises
    ------
    ConfigError
        Before any training: a bad sweep file, a clash with ``--env-kwargs``, or a
        trial whose settings :func:`~.settings.resolve_settings` rejects.
    """
    if options.sweep is None:
        raise ConfigError("run_sweep needs --sweep FILE.yml")
    spec = load_sweep(options.sweep)
    if options.seeds is not None:
        if not 2 <= options.seeds <= MAX_SEEDS_PER_TRIAL:
            raise ConfigError(f"--seeds {options.seeds} with --sweep: seeds per trial must be "
                              f">= 2 and <= {MAX_SEEDS_PER_TRIAL}")
        spec = replace(spec, seeds_per_trial=options.seeds)
    typed = set(options.user_env_kwargs)
    clash = sorted(k for k in spec.params if k.startswith("env_kwargs.")
                   and k.split(".", 2)[1] in typed)
    if clash:
        raise ConfigError(f"--env-kwargs sets {clash}, which the sweep searches: remove them "
                          "from one of the two")
    out = Path(options.out or Path("runs") / f"{options.algo}_sweep").absolute()
    if out.exists() and not out.is_dir():
        raise ConfigError(f"--out {out} is a file; --sweep needs a folder")
    base = load_hyperparams(options.config_path, options.algo, options.env_id)
    target = spec.timesteps or options.timesteps or int(base.get("n_timesteps", 1e5))
    seeds = range(options.seed, options.seed + spec.seeds_per_trial)
    out.mkdir(parents=True, exist_ok=True)
    (out / "sweep.yml").write_text(Path(options.sweep).read_text())
    if spec.search is Search.OPTUNA:
        return _run_optuna(options, spec, base, target, seeds, out)
    trials = expand_trials(spec)
    settings = [_trial_settings(options, base, t, out / f"trial_{i:03d}", target)
                for i, t in enumerate(trials)]
    print(f"sweep: {len(trials)} trial(s) x {len(seeds)} seeds = {len(trials) * len(seeds)} runs "
          f"of {target} steps ({spec.search.value} search) in {out}", flush=True)
    jobs = [SeedJob(f"trial {i} seed {s}", trial.for_seed(s, seed_dir(trial.out, s)))
            for i, trial in enumerate(settings) for s in seeds]
    try:
        results = run_jobs(jobs, address=options.ray_address, threads=options.torch_threads,
                           summary_log=out / FANOUT_LOG_FILE)
    except KeyboardInterrupt:
        print(INTERRUPTED, file=sys.stderr)
        return 130
    ranked = rank_trials([
        {"name": trial.out.name, "params": t,
         "returns": [final_eval_return(seed_dir(trial.out, s)) for s in seeds]}
        for trial, t in zip(settings, trials, strict=True)])
    print(write_table(ranked, out, list(spec.params)))
    failed = [r for r in results if r.status is SeedStatus.FAILED]
    if failed:
        print(f"{len(failed)} run(s) failed; rerun the same command to resume them")
    return 1 if failed else 0


def _tune_space(spec: SweepSpec, tune) -> tuple[dict[str, str], dict]:
    """Tune's names of the swept keys (``p0``, ``p1``, ...) and its search space."""
    names = {f"p{i}": key for i, key in enumerate(spec.params)}  # Tune splits keys at "/"
    space = {}
    for name, key in names.items():
        kind, arg = spec.params[key]
        if kind == "values":
            space[name] = tune.choice([json.dumps(v) for v in arg])  # lists as JSON strings
        elif kind == "uniform":
            space[name] = tune.uniform(*arg)
        elif kind == "loguniform":
            space[name] = tune.loguniform(*arg)
        else:
            space[name] = tune.randint(arg[0], arg[1] + 1)
    return names, space


def _overrides_of(spec: SweepSpec, names: dict[str, str], config: dict) -> dict:
    """The dotted-key overrides of a Tune trial's config."""
    return {names[n]: json.loads(v) if spec.params[names[n]][0] == "values" else v
            for n, v in config.items()}


def _optuna_rows(results, spec: SweepSpec, names: dict[str, str], target: int) -> list[dict]:
    """The trials of a finished Tune run, as :func:`rank_trials` takes them."""
    trials = []
    for result in results:
        if result.config is None:
            continue
        metrics = result.metrics or {}
        name = f"trial_{metrics.get('trial_id', '?')}"
        stopped = metrics.get("steps", target) < target
        if stopped:
            name += f" (stopped by ASHA at {metrics['steps']} steps)"
        trials.append({"name": name, "params": _overrides_of(spec, names, result.config),
                       "returns": metrics.get("returns") or [float("nan")],
                       "stopped": stopped})
    return trials


def _run_optuna(options, spec, base, target, seeds, out) -> int:
    """Optuna's sampler and ASHA through Ray Tune; one Tune trial per configuration."""
    try:
        import optuna  # noqa: F401
    except ImportError:
        raise ConfigError(f"search: optuna needs Optuna, which is not installed: {OPTUNA_PIP} "
                          "(or use search: random)") from None
    require_ray()
    from ray import tune
    from ray.tune.schedulers import ASHAScheduler
    from ray.tune.search.optuna import OptunaSearch

    names, space = _tune_space(spec, tune)
    chunks = spec.asha["chunks"]

    def trial_fn(config):
        trial_dir = out / f"trial_{tune.get_context().get_trial_id()}"
        trial = _trial_settings(options, base, _overrides_of(spec, names, config), trial_dir,
                                target)
        for chunk in range(1, chunks + 1):
            steps = max(target * chunk // chunks, 1)
            returns = []
            for s in seeds:
                job = SeedJob(f"{trial_dir.name} seed {s}",
                              trial.for_seed(s, seed_dir(trial_dir, s), timesteps=steps))
                res = train_seed(job, options.torch_threads)
                returns.append(final_eval_return(job.run_dir)
                               if res.status is not SeedStatus.FAILED else float("nan"))
            median = statistics.median(returns)
            tune.report({"median_return": -1e30 if math.isnan(median) else median,
                         "returns": returns, "steps": steps})

    started = init_ray(options.ray_address)
    try:
        tuner = tune.Tuner(
            tune.with_resources(trial_fn, {"cpu": options.torch_threads}), param_space=space,
            tune_config=tune.TuneConfig(
                metric="median_return", mode="max", num_samples=spec.num_samples,
                search_alg=OptunaSearch(seed=spec.sample_seed),
                scheduler=ASHAScheduler(max_t=chunks, grace_period=spec.asha["grace_period"],
                                        reduction_factor=spec.asha["reduction_factor"])),
            run_config=tune.RunConfig(name="tune", storage_path=str(out), verbose=0))
        t0 = time.perf_counter()
        grid = tuner.fit()
    finally:
        if started:
            import ray

            shutdown_ray(ray)
    results = [grid[i] for i in range(len(grid))]
    trials = _optuna_rows(results, spec, names, target)
    print(write_table(rank_trials(trials), out, list(spec.params)))
    print(f"optuna sweep of {len(trials)} trial(s) in {time.perf_counter() - t0:.0f} s")
    return 1 if any(r.error for r in results) else 0
