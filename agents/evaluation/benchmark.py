"""Benchmark any mix of policies on a scenario suite through one evaluation path.

``python evaluate.py`` evaluates the shipped agents beside the sliding-mode and
open-loop baselines on the default suite and prints the tables;
``python evaluate.py paper --out DIR`` (alias ``--paper``) reproduces the paper's
figures instead (:mod:`tether_gym_agents.paper`).

Every policy, baseline or trained, is a ``predict`` object run by
:func:`tether_gym_agents.evaluation.rollout.rollout` on the native vector env (one sub-env per
seed, one observation per ``predict`` call, so an episode never depends on the number
of seeds, the thread count or the order of the policies). Each episode becomes the
metrics of :mod:`.metrics`; :mod:`.results` turns
them into the statistics over training runs (:mod:`.stats`), the
tables and ``results.json``.

A policy is a baseline name (``smc``, the paper's sliding-mode law; ``smc_filtered``,
the same law behind the model-based safety filter of :mod:`tether_gym.safety`;
``zero``, ``periodic``, ``random``; all run with ``action_mode="rate"``), a shipped
agent (``ppo``, ``sac``, ...), a run folder or model file written by ``train.py``, or a
folder of seed run folders (``runs/ppo/seed_0/``, ``seed_1/``, ...), which is one
policy with one run per folder. An agent whose files record a ``hybrid`` (trained
with a ``residual`` config, :mod:`tether_gym_agents.training.residual_env`) is of kind
``hybrid``: it runs as the residual of
:class:`~tether_gym_agents.hybrids.policies.ResidualPolicy` around the sliding-mode law (and
the filter, when it was trained with one), both on the scenario's nominal model like
``smc`` and ``smc_filtered``. ``handover:AGENT`` (e.g. ``handover:ppo``) is the hybrid
:class:`~tether_gym_agents.hybrids.policies.HandoverPolicy` of a trained agent: the agent steers
the transient and hands over to the sliding-mode law inside its boundary layer, all of
it behind the safety filter, on the same nominal model.
"""

from __future__ import annotations

import argparse
import shlex
import sys
import tempfile
import time
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path

import gymnasium as gym
import numpy as np

import tether_gym

from ..common.env_kwargs import parse_env_kwargs
from ..files.agent_files import seed_runs
from .metrics import episode_metrics
from .rollout import Trajectory, rollout
from .scenarios import Scenario, describe_suites, get_suite

__all__ = ["main", "evaluate", "resolve_policy", "make_policy", "default_policies",
           "PolicyKind", "PolicySpec", "BASELINES", "HANDOVER", "MAX_SEEDS"]

BASELINES = ("smc", "smc_filtered", "zero", "periodic", "random")
ACTION_KEYS = ("action_mode", "increment_gain")
"""Env arguments that define what a policy's action means."""
OBSERVATION_KEYS = ("observe_params",)
"""Env arguments that define what a policy's observation holds."""
MAX_SEEDS = 1000
"""Upper bound of ``--seeds`` (episodes per scenario and run)."""
MAX_SEED = 2**31 - 1
HANDOVER = "handover:"
"""Prefix of a handover hybrid's policy name: ``handover:`` + a trained agent's name."""
HANDOVER_OF = ("ppo",)
"""Shipped agents whose handover hybrid ``python evaluate.py`` benchmarks by default."""


class PolicyKind(Enum):
    """What a policy is, as recorded in results.json."""

    BASELINE = "baseline"
    RL = "rl"
    HYBRID = "hybrid"  # learning combined with a model-based law (residual, handover)


@dataclass
class PolicySpec:
    """A policy to evaluate: its name, kind and training runs.

    ``runs`` holds one path per training run of a trained policy, ``[None]`` for a
    baseline (one "run"). Trained agents are loaded once (:meth:`load`).
    """

    name: str
    kind: PolicyKind
    runs: list
    agents: list = field(default_factory=list)
    allow_pickle: bool = False
    handover: bool = False
    """A :class:`~tether_gym_agents.hybrids.policies.HandoverPolicy` of the runs' agents (else a
    hybrid is the residual its agents record)."""

    @property
    def env_kwargs(self) -> dict:
        """Env arguments the policy needs on every scenario (its action mode and observation).

        The baselines and the hybrids command reel rates (``action_mode="rate"``); a
        trained agent runs in the action mode it was trained in and sees what it saw
        (:data:`ACTION_KEYS` and :data:`OBSERVATION_KEYS` of its recorded env arguments,
        the env's defaults when absent); a handover hybrid's env gives its agent's
        observation. Nothing else of the training env is used: the scenario sets the rest.
        """
        if self.kind is PolicyKind.BASELINE:
            return dict(_rate_mode())
        self.load()
        if self.handover:
            return {**_rate_mode(), **self._recorded(OBSERVATION_KEYS)}
        if self.kind is PolicyKind.HYBRID:
            modes = {agent.env_kwargs.get("action_mode", "rate") for agent in self.agents}
            if modes != {"rate"}:
                raise ValueError(f"policy {self.name!r}: a hybrid's residual must be trained "
                                 f"with action_mode='rate', its runs have {sorted(modes)}")
            return dict(_rate_mode())
        return self._recorded(ACTION_KEYS + OBSERVATION_KEYS)

    def _recorded(self, keys: tuple[str, ...]) -> dict:
        """The runs' recorded env arguments among ``keys``; they must agree."""
        recorded = [{k: agent.env_kwargs[k] for k in keys if k in agent.env_kwargs}
                    for agent in self.agents]
        if any(r != recorded[0] for r in recorded):
            raise ValueError(f"policy {self.name!r}: its runs were trained with different "
                             f"action or observation settings {recorded}")
        return recorded[0]

    @property
    def n_runs(self) -> int:
        """Number of training runs (1 for a baseline)."""
        return len(self.runs)

    def load(self) -> None:
        """Load every run's agent with ``TrainedAgent.load`` (no-op for baselines)."""
        from ..files.trained import TrainedAgent

        if self.kind is PolicyKind.BASELINE or self.agents:
            return
        self.agents = [TrainedAgent.load(path, allow_pickle=self.allow_pickle)
                       for path in self.runs]
        residual = self.kind is PolicyKind.HYBRID and not self.handover
        for agent in self.agents:
            if (agent.hybrid is not None) != residual:
                raise ValueError(f"policy {self.name!r} of kind {self.kind.value!r}: run "
                                 f"{agent.path} records hybrid={agent.hybrid!r}")

    def policies(self, run: int, env, scenario: Scenario, seeds: list[int]) -> list:
        """One ``predict`` object per seed for ``run`` on the env of ``scenario``.

        Deterministic policies are shared (the rollout batches the batch-invariant ones;
        a filter's counters then sum over the episodes, and the rollout records each
        episode's interventions); ``random`` gets a generator per episode, seeded with
        the episode's seed, so that its actions do not depend on the other episodes.
        """
        from ..baselines.open_loop import PeriodicReel, RandomPolicy, ZeroStateReel

        if self.handover:
            return [_handover(self.agents[run], env, scenario)] * len(seeds)
        if self.kind is PolicyKind.HYBRID:
            return [_residual(self.agents[run], env, scenario)] * len(seeds)
        if self.kind is not PolicyKind.BASELINE:
            return [self.agents[run]] * len(seeds)
        if self.name == "random":
            return [RandomPolicy(env, seed=s) for s in seeds]
        if self.name == "smc":
            policy: object = _nominal_smc(env, scenario)
        elif self.name == "smc_filtered":
            from ..hybrids.policies import FilteredPolicy

            policy = FilteredPolicy(_nominal_smc(env, scenario), _nominal_filter(env, scenario))
        elif self.name == "zero":
            policy = ZeroStateReel.for_env(env)
        else:
            policy = PeriodicReel.for_env(env)
        return [policy] * len(seeds)


def _rate_mode() -> dict:
    """Env arguments of the policies that command reel rates (baselines, hybrids)."""
    from ..common.obs import ReelRatePolicy

    return ReelRatePolicy.ENV_KWARGS


def _nominal_smc(env, scenario: Scenario):
    """The sliding-mode law designed on ``scenario.nominal`` (None: the env's own model).

    It never reads e or the masses from the observation (a hybrid's env observes them
    when its agent does): the law runs on its design model, as ``smc`` does.
    """
    from ..baselines.smc import SlidingModeController

    nominal = None
    if scenario.nominal is not None:
        from tether_gym.physics import TetherChain

        cfg = env.unwrapped.config
        nominal = TetherChain(scenario.nominal["masses"], scenario.nominal["eccentricity"],
                              cfg.gravity, cfg.scales.length_ratio)
    return SlidingModeController.for_env(env, nominal=nominal, use_observed_params=False)


def _nominal_filter(env, scenario: Scenario):
    """The safety filter predicting with ``scenario.nominal`` (None: the env's own model)."""
    from tether_gym.safety import SafetyFilter

    return SafetyFilter.for_env(env, **(scenario.nominal or {}))


def _residual(agent, env, scenario: Scenario):
    """The hybrid of a residual ``agent``: SMC + scale * agent, filtered if trained so.

    The sliding-mode law and the filter use the scenario's nominal model, as ``smc`` and
    ``smc_filtered`` do.
    """
    from ..hybrids.policies import ResidualPolicy

    spec = agent.hybrid
    if spec is None:
        raise ValueError(f"{agent!r} records no hybrid: it is not the residual of one")
    flt = _nominal_filter(env, scenario) if spec["filter"] else None
    return ResidualPolicy(_nominal_smc(env, scenario), agent, spec["scale"], flt)


def _handover(agent, env, scenario: Scenario):
    """``agent`` handing over to SMC, filtered, both on the scenario's nominal model."""
    from ..hybrids.policies import HandoverPolicy

    return HandoverPolicy(agent, _nominal_smc(env, scenario), _nominal_filter(env, scenario))


def shipped_agents() -> dict[str, Path]:
    """Shipped agents: agent folders and folders of seed run folders in ``pretrained/``."""
    from ..files.trained import pretrained_agents

    return pretrained_agents()


def default_policies() -> list[str]:
    """What ``python evaluate.py`` benchmarks by default.

    The baselines, the shipped agents and the handover hybrid of each shipped agent in
    :data:`HANDOVER_OF`.
    """
    shipped = shipped_agents()
    return (list(BASELINES) + list(shipped)
            + [HANDOVER + name for name in HANDOVER_OF if name in shipped])


def resolve_policy(name: str, allow_pickle: bool = False) -> PolicySpec:
    """PolicySpec of a baseline name, a shipped agent's name or a path.

    ``allow_pickle`` lets a run folder without the safe agent files load
    stable-baselines3's pickled ones (which run code when loaded).
    Raises ValueError listing the valid names when ``name`` is none of these.
    """
    if name in BASELINES:
        return PolicySpec(name, PolicyKind.BASELINE, [None])
    if name.startswith(HANDOVER):
        inner = resolve_policy(name[len(HANDOVER):], allow_pickle=allow_pickle)
        if inner.kind is not PolicyKind.RL:
            raise ValueError(f"policy {name!r}: a handover hybrid needs a trained agent that "
                             f"acts alone, {inner.name!r} is of kind {inner.kind.value!r}")
        return PolicySpec(name, PolicyKind.HYBRID, inner.runs, allow_pickle=allow_pickle,
                          handover=True)
    shipped = shipped_agents()
    path = shipped.get(name)
    if path is None and Path(name).exists():
        path = Path(name)
    if path is None:
        valid = list(BASELINES) + list(shipped)
        raise ValueError(f"unknown policy {name!r}: give one of {valid} or a path to a trained "
                         "agent (run folder, model file or folder of seed_K run folders)")
    runs = seed_runs(path) or [path]
    from ..files.trained import hybrid_of

    hybrid = [hybrid_of(run) is not None for run in runs]
    if any(hybrid) and not all(hybrid):
        mixed = {str(r): "hybrid" if h else "rl" for r, h in zip(runs, hybrid, strict=True)}
        raise ValueError(f"policy {name!r} mixes residuals of a hybrid and plain agents "
                         f"{mixed}; evaluate them as separate policies")
    kind = PolicyKind.HYBRID if all(hybrid) else PolicyKind.RL
    return PolicySpec(name, kind, runs, allow_pickle=allow_pickle)


def make_policy(name: str, env, scenario: Scenario | None = None, seed: int = 0):
    """Policy object with ``predict`` for a baseline name or a trained agent (its first run).

    ``env`` is a TetherLibration env; ``scenario`` gives the nominal model of ``smc``
    (model mismatch); ``seed`` seeds ``random``.
    """
    spec = resolve_policy(name)
    spec.load()
    return spec.policies(0, env, scenario or Scenario("env", ""), [seed])[0]


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

    @property
    def env(self):
        """A probe env of the scenario (the first one built)."""
        return next(iter(self.envs.values()))

    def close(self) -> None:
        """Close the probe envs."""
        for env in self.envs.values():
            env.close()


def _prepare(specs: list[PolicySpec], scenarios, env_kwargs: dict, seeds: list[int],
             log) -> list[_Setting]:
    """Build every scenario's env and check every policy run against it, before any run.

    Raises ValueError naming the scenario, the policy and what does not fit.
    """
    settings = []
    for spec in specs:
        spec.load()
    for sc in scenarios:
        st = _Setting(sc, sc.env_kwargs_with(env_kwargs))
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
            env = st.env_for(spec)
            obs, _ = env.reset(seed=seeds[0])
            n_act = env.action_space.shape[0]
            for run in range(spec.n_runs):
                where = (f"policy {spec.name!r}"
                         + (f" (run {spec.runs[run]})" if spec.runs[run] is not None else "")
                         + f" on scenario {st.scenario.name!r}")
                try:
                    policy = spec.policies(run, env, st.scenario, seeds[:1])[0]
                    action, _ = policy.predict(obs[None], deterministic=True)
                except (ValueError, TypeError) as exc:
                    raise ValueError(f"{where}: {exc}") from None
                shape = np.shape(action)
                if shape not in ((1, n_act), (n_act,)):
                    raise ValueError(f"{where}: action of shape {shape} for an env with "
                                     f"{n_act} reels (observation {obs.shape})")
    return settings


def evaluate(policies: list[str], suite: str = "default", n_seeds: int = 10, seed: int = 0,
             out: Path | None = None, plots: bool = True, log=print,
             env_kwargs: dict | None = None, torch_threads: int | None = 1,
             command: str | None = None, allow_pickle: bool = False) -> dict:
    """Evaluate ``policies`` on every scenario of ``suite``; return the results dict.

    Parameters
    ----------
    policies : list of str
        Baseline names, shipped agents' names or paths (see the module docstring).
    suite : str
        A built-in suite name or a YAML suite file (:mod:`tether_gym_agents.evaluation.scenarios`).
    n_seeds : int
        Episodes per scenario and training run (1 ... MAX_SEEDS), seeds ``seed`` ...
        ``seed + n_seeds - 1``.
    seed : int
        First env seed (>= 0).
    out : Path or None
        Folder for ``results.json`` and the plots (None: write nothing).
    plots : bool
        Write ``trajectories.png`` and ``metrics.png`` (needs matplotlib).
    log : callable or None
        Progress lines (``print`` by default).
    env_kwargs : dict or None
        Env arguments applied on top of every scenario.
    torch_threads : int or None
        ``torch.set_num_threads`` before trained agents run (None: leave torch alone).
    command : str or None
        The command line recorded in ``results.json``'s ``meta``.
    allow_pickle : bool
        Let run folders without the safe agent files load stable-baselines3's pickled
        files (a pickle runs code when loaded: only for files you made or trust).

    Returns
    -------
    dict
        The content of ``results.json`` (:func:`.results.build_results`).
    """
    from .results import build_results, write_results

    log = log or (lambda *a, **k: None)
    _check_count("n_seeds", n_seeds, 1, MAX_SEEDS)
    _check_count("seed", seed, 0, MAX_SEED - n_seeds + 1)
    env_kwargs = dict(env_kwargs or {})
    scenarios = get_suite(suite)
    if out is not None:
        check_out_dir(Path(out), "out")
    specs = [resolve_policy(p, allow_pickle) for p in policies]
    names = [s.name for s in specs]
    if len(set(names)) != len(names):
        raise ValueError(f"policies {names} name one policy twice")
    if any(s.kind is not PolicyKind.BASELINE for s in specs) and torch_threads is not None:
        import torch

        torch.set_num_threads(int(torch_threads))
    seeds = [seed + i for i in range(n_seeds)]
    t_start = time.perf_counter()
    log(f"building {len(scenarios)} scenario env(s) and loading {len(specs)} policies (the "
        "first run after an install compiles the env's numba kernels: about a minute) ...")
    settings = _prepare(specs, scenarios, env_kwargs, seeds, log)
    log(f"  checked {sum(s.n_runs for s in specs)} policy run(s) against "
        f"{len(settings)} scenario(s) in {time.perf_counter() - t_start:.1f} s")
    episodes: list[dict] = []
    trajectories: dict[str, Trajectory] = {}
    try:
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
                    f"{st.scenario.name}, {n_seeds} episodes x {spec.n_runs} run(s) in "
                    f"{time.perf_counter() - t0:.1f} s")
            log(f"  evaluated {spec.name} ({spec.kind.value}, {spec.n_runs} run(s)) on "
                f"{len(settings)} scenarios x {n_seeds} seeds in "
                f"{time.perf_counter() - t_policy:.1f} s")
    finally:
        for st in settings:
            st.close()
    results = build_results(specs, settings, seeds, episodes, env_kwargs=env_kwargs,
                            suite=suite, command=command, torch_threads=torch_threads)
    if out is not None:
        write_results(results, Path(out) / "results.json")
        if plots:
            from .plots import plot_results

            plot_results(results, trajectories, settings[0].scenario, Path(out), log)
    return results


def _check_count(flag: str, value, low: int, high: int) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not (
            low <= value <= high):
        raise ValueError(f"{flag}={value!r} must be an integer in [{low}, {high}]")


def check_out_dir(out: Path, flag: str = "--out") -> None:
    """Create ``out`` and check that a file can be written there, before any work.

    Raises ValueError when ``out`` is a file, cannot be created or is not writable.
    """
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


def _bench_parser(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    parser.add_argument("policies", nargs="*",
                        help="smc, smc_filtered, zero, periodic, random, shipped agents "
                             "(ppo, ...), paths to trained agents (run folder, model file, or "
                             "a folder of seed_K run folders = one policy with several runs), "
                             "or handover:AGENT (the agent hands over to smc, filtered); "
                             "default: all baselines, shipped agents and handover:ppo")
    parser.add_argument("--suite", default="default",
                        help="scenario suite: a name below or a YAML suite file (default: "
                             "default)")
    parser.add_argument("--env-kwargs", nargs="+", default=[], metavar="KEY=VALUE",
                        help="env arguments applied on top of every scenario, as Python "
                             "literals, e.g. n_bodies=4 eccentricity=0.3 masses=(1,2,3)")
    parser.add_argument("--seeds", type=int, default=10,
                        help=f"episodes per scenario and run, 1 ... {MAX_SEEDS} (default 10)")
    parser.add_argument("--seed", type=int, default=0, help="first env seed (default 0)")
    parser.add_argument("--out", type=Path, default=Path("runs/eval"),
                        help="folder for results.json and plots (default runs/eval)")
    parser.add_argument("--torch-threads", type=int, default=1,
                        help="torch threads for trained agents (default 1; results do not "
                             "depend on it)")
    parser.add_argument("--no-plots", action="store_true", help="skip the plots")
    parser.add_argument("--allow-pickle", action="store_true",
                        help="also load stable-baselines3's pickled files (*.zip, "
                             "vecnormalize.pkl) when a folder has no agent.json; a pickle "
                             "runs code when loaded: only for files you made or trust")
    return parser


def _build_parser() -> tuple[argparse.ArgumentParser, argparse.ArgumentParser]:
    import textwrap

    from ..paper.cli import add_arguments as add_paper_arguments

    notes = (
        "A suite file (--suite FILE.yml) lists scenarios as YAML: 'scenarios: [{name: ..., "
        "description: ..., env_kwargs: {...}, nominal: {masses: [...], eccentricity: ...}}]'.",
        "The table reports, per policy, the interquartile mean over training runs x "
        "scenarios of each run's mean over its episodes, with a 95 % stratified-bootstrap "
        "interval (2 runs or more) and the probability of improvement over smc.",
        "Reproduce the paper instead: evaluate.py paper --out DIR (alias: evaluate.py "
        "--paper --out DIR).")
    epilog = "\n\n".join([describe_suites(), *(textwrap.fill(n, 79) for n in notes)])
    top = argparse.ArgumentParser(
        prog="evaluate.py", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Benchmark policies on tether_gym scenario suites (evaluate.py [bench] "
                    "...), or reproduce the paper's figures (evaluate.py paper ...).",
        epilog=epilog)
    sub = top.add_subparsers(dest="command", metavar="{bench,paper}")
    bench = sub.add_parser("bench", help="benchmark policies (the default command)",
                           prog="evaluate.py [bench]", epilog=epilog,
                           formatter_class=argparse.RawDescriptionHelpFormatter,
                           description="Benchmark policies on a tether_gym scenario suite.")
    _bench_parser(bench)
    paper = sub.add_parser("paper", help="reproduce Shi, Zhu & Zhu (2019), Figs. 2-9",
                           prog="evaluate.py paper",
                           description="Reproduce Shi, Zhu & Zhu (2019), Figs. 2-9, from "
                                       "tether_gym and write paper_vs_tether_gym.md/.json "
                                       "beside the PNG figures.")
    add_paper_arguments(paper)
    return top, bench


def main(argv=None) -> int:
    """Command line of ``evaluate.py``; returns the exit code.

    ``evaluate.py [bench] [policies] [options]`` benchmarks (the default command),
    ``evaluate.py paper --out DIR`` reproduces the paper; ``--paper`` anywhere is an
    alias of the ``paper`` command.
    """
    argv = [str(a) for a in (sys.argv[1:] if argv is None else argv)]
    command = shlex.join(["evaluate.py", *argv])
    if "--paper" in argv:
        argv = ["paper"] + [a for a in argv if a != "--paper"]
    elif not argv or argv[0] not in ("bench", "paper"):
        argv = ["bench", *argv]
    top, _ = _build_parser()
    args = top.parse_args(argv)
    if args.command == "paper":
        from ..paper.cli import run as paper_run

        return paper_run(args)
    try:
        env_kwargs = parse_env_kwargs(args.env_kwargs)
        _check_count("--seeds", args.seeds, 1, MAX_SEEDS)
        _check_count("--seed", args.seed, 0, MAX_SEED - args.seeds + 1)
        _check_count("--torch-threads", args.torch_threads, 1, 256)
        get_suite(args.suite)
        policies = args.policies or default_policies()
        for name in policies:
            resolve_policy(name)
        check_out_dir(args.out)
        t0 = time.perf_counter()
        print(f"tether_gym {tether_gym.__version__}: {len(policies)} policies on suite "
              f"{args.suite!r}, {args.seeds} seeds per scenario and run, torch threads "
              f"{args.torch_threads}" + (f", env kwargs {env_kwargs}" if env_kwargs else ""))
        results = evaluate(policies, args.suite, args.seeds, args.seed, args.out,
                           plots=not args.no_plots, env_kwargs=env_kwargs,
                           torch_threads=args.torch_threads, command=command,
                           allow_pickle=args.allow_pickle)
    except ValueError as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        return 2
    from .results import markdown_tables

    print()
    print(markdown_tables(results))
    print(f"\nresults: {args.out / 'results.json'} ({time.perf_counter() - t0:.0f} s)")
    return 0
