"""Benchmark any mix of policies on a scenario suite through one evaluation path.

:func:`evaluate` is what ``python evaluate.py`` runs (its command line is
:mod:`tether_gym_agents.cli.evaluate`): every policy name resolves through the policy
registry (:mod:`.registry`: baselines, policies registered with
:func:`~.registry.register_policy`, shipped agents, run folders and hybrids) to a
:class:`~.registry.PolicySpec`, and every policy, baseline or trained, is a ``predict``
object run by :func:`tether_gym_agents.evaluation.rollout.rollout` on the native vector
env (one sub-env per seed, one observation per ``predict`` call, so an episode never
depends on the number of seeds, the thread count or the order of the policies). Each
episode becomes the metrics of :mod:`.metrics`; :mod:`.results` turns them into the
statistics over training runs (:mod:`.stats`), the tables and ``results.json``.

The steps: check the arguments; resolve the policies; build every scenario's env and
check every policy run against it (:func:`_prepare`, before anything runs); roll out
every policy, scenario and run (:func:`_run_all`); build and write the results.
"""

from __future__ import annotations

import dataclasses
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np

import tether_gym

from ..common.ranges import MAX_TORCH_THREADS
from .metrics import episode_metrics
from .registry import (
    BASELINES,
    HANDOVER,
    PolicyKind,
    PolicySpec,
    check_given_env_kwargs,
    default_policies,
    make_policy,
    resolve_policy,
    trained_on,
)
from .rollout import Trajectory, rollout
from .scenarios import Scenario, get_suite

__all__ = ["evaluate", "EvalOptions", "check_int", "check_out_dir", "resolve_policy",
           "make_policy", "default_policies", "PolicyKind", "PolicySpec", "BASELINES",
           "HANDOVER", "MAX_SEEDS", "MAX_SEED", "compute_cost",
           "new_out_dir", "DEFAULT_OUT_PARENT"]

MAX_SEEDS = 1000
"""Upper bound of ``--seeds`` (episodes per scenario and run)."""
MAX_SEED = 2**31 - 1
"""Largest env seed of an episode."""
DEFAULT_OUT_PARENT = Path("runs/eval")
"""Where ``evaluate.py`` without ``--out`` makes a new results folder per call."""


def _no_log(*args, **kwargs) -> None:
    """A ``log`` that prints nothing."""


@dataclass(frozen=True)
class EvalOptions:
    """How :func:`evaluate` runs and what it writes; none of it changes a number.

    Parameters
    ----------
    out : Path or None
        Folder for ``results.json`` and the plots (None: write nothing).
    plots : bool
        Write ``trajectories.png`` and ``metrics.png`` (needs matplotlib).
    log : callable or None
        Progress lines (``print`` by default; None: silent).
    torch_threads : int or None
        ``torch.set_num_threads`` before trained agents run (None: leave torch alone).
    command : str or None
        The command line recorded in ``results.json``'s ``meta``.
    allow_pickle : bool
        Let run folders without the safe agent files load stable-baselines3's pickled
        files (a pickle runs code when loaded: only for files you made or trust).
    """

    out: Path | None = None
    plots: bool = True
    log: Callable | None = print
    torch_threads: int | None = 1
    command: str | None = None
    allow_pickle: bool = False

    def __post_init__(self) -> None:
        if self.out is not None:
            _check_not_empty(self.out, "out")
            object.__setattr__(self, "out", Path(self.out))
        if self.torch_threads is not None:
            check_int("torch_threads", self.torch_threads, 1, MAX_TORCH_THREADS)

    @property
    def logger(self) -> Callable:
        """``log``, or a silent one."""
        return self.log or _no_log


def check_int(name: str, value, low: int, high: int) -> int:
    """Return ``value`` after checking it is an integer in ``[low, high]``.

    Raises ValueError naming ``name``, the value and the range (a bool is no integer).
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not (
            low <= value <= high):
        raise ValueError(f"{name}={value!r} must be an integer in [{low}, {high}]")
    return int(value)


def check_out_dir(out: str | Path, flag: str = "--out") -> None:
    """Create ``out`` and check that a file can be written there, before any work.

    Raises ValueError when ``out`` is empty (``--out ""`` would be the current folder),
    is a file, cannot be created or is not writable.
    """
    _check_not_empty(out, flag)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{flag} {str(out)!r} is a file; give a folder for results.json "
                         "and the plots")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=out, prefix=".write_test_"):
            pass
    except OSError as exc:
        raise ValueError(f"{flag} {str(out)!r} is not a writable folder: "
                         f"{exc.strerror or exc}") from None


def _check_not_empty(out, flag: str) -> None:
    """Raise ValueError when the output folder ``out`` is given as an empty string."""
    if isinstance(out, str) and not out.strip():
        raise ValueError(f"{flag} {out!r} is empty; give a folder for the results (an empty "
                         "path would write into the current folder)")


def new_out_dir(parent: str | Path = DEFAULT_OUT_PARENT) -> Path:
    """A new, empty folder ``parent/<YYYYmmdd-HHMMSS>[_K]`` for one evaluation's results.

    ``evaluate.py`` without ``--out`` writes there, so that no evaluation overwrites the
    results of an earlier one. Raises ValueError when ``parent`` cannot hold it.
    """
    parent = Path(parent)
    stamp = time.strftime("%Y%m%d-%H%M%S")
    try:
        parent.mkdir(parents=True, exist_ok=True)
        for k in range(1, 1000):
            out = parent / (stamp if k == 1 else f"{stamp}_{k}")
            try:
                out.mkdir()
                return out
            except FileExistsError:
                continue
    except OSError as exc:
        raise ValueError(f"cannot make a results folder in {str(parent)!r}: "
                         f"{exc.strerror or exc}; give one with --out") from None
    raise ValueError(f"{str(parent)!r} holds 999 results folders of {stamp}; give --out")


def evaluate(policies: list[str | PolicySpec], suite: str = "default", n_seeds: int = 10,
             seed: int = 0, env_kwargs: dict | None = None,
             options: EvalOptions | None = None,
             **option_fields) -> dict:
    """Evaluate ``policies`` on every scenario of ``suite``; return the results dict.

    Parameters
    ----------
    policies : list of str or PolicySpec
        Policy names: registered policies (the baselines and those added with
        :func:`~.registry.register_policy`), shipped agents, ``handover:AGENT`` or paths
        (:mod:`.registry`); or specs already resolved (and loaded) by
        :func:`~.registry.resolve_policy`, used as they are.
    suite : str
        A built-in suite name or a YAML suite file (:mod:`.scenarios`).
    n_seeds : int
        Episodes per scenario and training run (1 ... MAX_SEEDS), seeds ``seed`` ...
        ``seed + n_seeds - 1``.
    seed : int
        First env seed (>= 0).
    env_kwargs : dict or None
        Env arguments applied on top of every scenario.
    options : EvalOptions or None
        Output, logging and loading options (None: the defaults).
    **option_fields
        Fields of :class:`EvalOptions` that replace those of ``options``, e.g.
        ``out=None, log=None, plots=False``; any other name is a TypeError.

    Returns
    -------
    dict
        The content of ``results.json`` (:func:`.results.build_results`).
    """
    from .results import build_results

    opts = dataclasses.replace(options or EvalOptions(), **option_fields)
    log = opts.logger
    seeds = _seeds(n_seeds, seed)
    env_kwargs = dict(env_kwargs or {})
    scenarios = get_suite(suite)
    specs = _resolve_all(policies, opts.allow_pickle)  # before --out: a refused agent
    if opts.out is not None:                           # leaves no folder behind
        check_out_dir(opts.out, "out")
    _set_torch_threads(specs, opts.torch_threads)
    t_start = time.perf_counter()
    log(f"building {len(scenarios)} scenario env(s) and loading {len(specs)} policies (the "
        "first run after an install compiles the env's numba kernels: about a minute) ...")
    settings: list[_Setting] = []
    try:
        _prepare(settings, specs, scenarios, env_kwargs, seeds)
        log(f"  checked {sum(s.n_runs for s in specs)} policy run(s) against "
            f"{len(settings)} scenario(s) in {time.perf_counter() - t_start:.1f} s")
        episodes, trajectories = _run_all(specs, settings, seeds, log)
        compute = {spec.name: compute_cost(spec, settings[0], seeds[0]) for spec in specs}
        log("  compute per control step [ms], median / p99: " + ", ".join(
            f"{name} {med:.3g} / {p99:.3g}" for name, (med, p99) in compute.items()))
    finally:
        for st in settings:
            st.close()
    results = build_results(specs, settings, seeds, episodes, env_kwargs=env_kwargs,
                            suite=suite, command=opts.command,
                            torch_threads=opts.torch_threads, compute=compute)
    _write(results, trajectories, settings[0].scenario, opts)
    return results


def _seeds(n_seeds: int, seed: int) -> list[int]:
    """The env seeds ``seed ... seed + n_seeds - 1``, checked."""
    check_int("n_seeds", n_seeds, 1, MAX_SEEDS)
    check_int("seed", seed, 0, MAX_SEED - n_seeds + 1)
    return [seed + i for i in range(n_seeds)]


def _resolve_all(policies: list[str | PolicySpec], allow_pickle: bool) -> list[PolicySpec]:
    """Every policy's spec (a spec given is kept); a policy named twice is a ValueError."""
    specs = [p if isinstance(p, PolicySpec) else resolve_policy(p, allow_pickle)
             for p in policies]
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise ValueError(f"policies {names} name one policy twice")
    return specs


def _set_torch_threads(specs: list[PolicySpec], torch_threads: int | None) -> None:
    """``torch.set_num_threads`` when a policy other than a baseline is evaluated."""
    if any(s.kind is not PolicyKind.BASELINE for s in specs) and torch_threads is not None:
        import torch

        torch.set_num_threads(int(torch_threads))


@dataclass
class _Setting:
    """A scenario with its resolved env arguments and a probe env per action setting."""

    scenario: Scenario
    env_kwargs: dict
    envs: dict = field(default_factory=dict)

    def kwargs_for(self, spec: PolicySpec) -> dict:
        """The scenario's env arguments with the policy's action setting."""
        return {**self.env_kwargs, **spec.env_kwargs}

    def env_for(self, spec: PolicySpec):
        """The scenario's probe env in the policy's action setting (built once)."""
        key = tuple(sorted(spec.env_kwargs.items()))
        if key not in self.envs:
            self.envs[key] = gym.make(tether_gym.ENV_ID, **self.kwargs_for(spec))
        return self.envs[key]

    def close(self) -> None:
        """Close the probe envs."""
        for env in self.envs.values():
            env.close()


def _prepare(settings: list[_Setting], specs: list[PolicySpec], scenarios, env_kwargs: dict,
             seeds: list[int]) -> None:
    """Build every scenario's env into ``settings``, then check every policy run on it.

    All of it happens before any episode runs. Every scenario is built for the chain and
    task the trained agents were trained on (:func:`~.registry.trained_on`, under the
    scenario's own arguments), for the number of bodies it gets
    (:meth:`~.scenarios.Scenario.resolved`), with ``env_kwargs`` on top.

    Raises ValueError naming the scenario, the policy and what does not fit.
    """
    for spec in specs:
        spec.load()
        check_given_env_kwargs(spec, env_kwargs)
    base = trained_on(specs, env_kwargs)
    for sc in scenarios:
        try:
            resolved, kwargs = sc.resolved(env_kwargs, base)
        except ValueError as exc:
            raise ValueError(f"{exc} (trained-on env arguments {base})" if base
                             else str(exc)) from None
        st = _Setting(resolved, kwargs)
        settings.append(st)
        for spec in specs:
            try:
                st.env_for(spec)
            except (ValueError, TypeError) as exc:
                given = f" with --env-kwargs {env_kwargs}" if env_kwargs else ""
                raise ValueError(f"scenario {sc.name!r}{given} for policy {spec.name!r}: "
                                 f"{exc}") from None
    for st in settings:
        for spec in specs:
            for run in range(spec.n_runs):
                _check_run(spec, run, st, seeds[0])


def _check_run(spec: PolicySpec, run: int, st: _Setting, seed: int) -> None:
    """Build ``run`` of ``spec`` on the scenario's env and check one action's shape."""
    env = st.env_for(spec)
    obs, _ = env.reset(seed=seed)
    n_act = env.action_space.shape[0]
    where = (f"policy {spec.name!r}"
             + (f" (run {spec.runs[run]})" if spec.runs[run] is not None else "")
             + f" on scenario {st.scenario.name!r}")
    try:
        policy = spec.policies(run, env, st.scenario, [seed])[0]
        action, _ = policy.predict(obs[None], deterministic=True)
    except (ValueError, TypeError) as exc:
        raise ValueError(f"{where}: {exc}") from None
    shape = np.shape(action)
    if shape not in ((1, n_act), (n_act,)):
        raise ValueError(f"{where}: action of shape {shape} for an env with "
                         f"{n_act} reels (observation {obs.shape})")


class _Timed:
    """A policy whose ``predict`` calls are timed (wall clock, ``time.perf_counter``)."""

    def __init__(self, policy):
        self._policy = policy
        self.seconds: list[float] = []

    def __getattr__(self, name: str):
        return getattr(self._policy, name)

    def predict(self, *args, **kwargs):
        t0 = time.perf_counter()
        out = self._policy.predict(*args, **kwargs)
        self.seconds.append(time.perf_counter() - t0)
        return out


def compute_cost(spec: PolicySpec, st: _Setting, seed: int) -> tuple[float, float]:
    """(median, p99) wall time [ms] of ``spec``'s ``predict`` per control step.

    One episode of the scenario ``st`` (the policy's first run, env seed ``seed``), one
    observation per call, as a controller in the loop would run: the learned agents'
    batched calls of the benchmark itself would hide their per-call overhead.
    """
    timed = _Timed(spec.policies(0, st.env_for(spec), st.scenario, [seed])[0])
    rollout([timed], [seed], st.kwargs_for(spec))
    ms = 1e3 * np.asarray(timed.seconds)
    return float(np.median(ms)), float(np.percentile(ms, 99))


def _run_all(specs: list[PolicySpec], settings: list[_Setting], seeds: list[int],
             log: Callable) -> tuple[list[dict], dict[str, Trajectory]]:
    """Every episode's record, and each policy's first trajectory (for the plots)."""
    episodes: list[dict] = []
    trajectories: dict[str, Trajectory] = {}
    for k, spec in enumerate(specs, 1):
        t_policy = time.perf_counter()
        for j, st in enumerate(settings, 1):
            t0 = time.perf_counter()
            for run in range(spec.n_runs):
                trajs = rollout(spec.policies(run, st.env_for(spec), st.scenario, seeds),
                                seeds, st.kwargs_for(spec))
                for s, traj in zip(seeds, trajs, strict=True):
                    episodes.append({"policy": spec.name, "run": run,
                                     "scenario": st.scenario.name, "seed": s,
                                     **episode_metrics(traj)})
                if j == 1 and run == 0:
                    trajectories[spec.name] = trajs[0]
            log(f"  [{k}/{len(specs)}] {spec.name}: scenario {j}/{len(settings)} "
                f"{st.scenario.name}, {len(seeds)} episodes x {spec.n_runs} run(s) in "
                f"{time.perf_counter() - t0:.1f} s")
        log(f"  evaluated {spec.name} ({spec.kind.value}, {spec.n_runs} run(s)) on "
            f"{len(settings)} scenarios x {len(seeds)} seeds in "
            f"{time.perf_counter() - t_policy:.1f} s")
    return episodes, trajectories


def _write(results: dict, trajectories: dict, scenario: Scenario, opts: EvalOptions) -> None:
    """``results.json`` and, if asked, the plots into ``opts.out`` (nothing if None)."""
    from .results import write_results

    if opts.out is None:
        return
    write_results(results, opts.out / "results.json")
    if opts.plots:
        from .plots import plot_results

        plot_results(results, trajectories, scenario, opts.out, opts.logger)
