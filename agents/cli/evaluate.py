"""``python evaluate.py``: benchmark policies, learning curves, or reproduce the paper.

``evaluate.py [bench] [policies] [options]`` (the default command) checks every argument,
then runs :func:`tether_gym_agents.evaluation.benchmark.evaluate` and prints its tables;
``evaluate.py paper --out DIR`` (alias ``--paper``) runs
:func:`tether_gym_agents.paper.cli.run`; ``evaluate.py curves RUNS... --out DIR``
evaluates every checkpoint of folders of seed runs on a suite
(:mod:`tether_gym_agents.evaluation.curves`); ``evaluate.py dataset POLICY...`` writes
Minari demonstration datasets (:mod:`tether_gym_agents.cli.dataset`). A policy name is
anything the policy registry resolves (:mod:`tether_gym_agents.evaluation.registry`),
including the policies that user code registered with
:func:`tether_gym_agents.register_policy` before calling :func:`main`. A bad argument,
such as an unknown policy, is one ``evaluate.py: error:`` line on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys
import textwrap
import time
from pathlib import Path

import tether_gym

from ..common.env_kwargs import parse_env_kwargs
from ..common.ranges import MAX_TORCH_THREADS
from ..evaluation.benchmark import (
    DEFAULT_OUT_PARENT,
    MAX_SEED,
    MAX_SEEDS,
    EvalOptions,
    check_int,
    check_out_dir,
    evaluate,
    new_out_dir,
)
from ..evaluation.registry import BASELINES, default_policies, resolve_policy
from ..evaluation.results import markdown_tables
from ..evaluation.scenarios import describe_suites, get_suite
from ..files.trained import refuse_special_file
from .dataset import add_arguments as add_dataset_arguments
from .dataset import run as dataset_run

__all__ = ["main", "build_parser"]

COMMANDS = ("bench", "paper", "curves", "dataset")
NOTES = (
    "A suite file (--suite FILE.yml) lists scenarios as YAML: 'scenarios: [{name: ..., "
    "description: ..., env_kwargs: {...}, nominal: {masses: [...], eccentricity: ...}}]'.",
    "The table reports, per policy, success as the surviving fraction of all episodes "
    "(and its worst scenario), every other metric as the interquartile mean over training "
    "runs x scenarios of each run's mean over its episodes, with 95 % stratified-bootstrap "
    "intervals (2 runs or more), the compute time per control step, and the probability "
    "of improvement over smc. Cost (v2's info['cost'], docs/safe_rl.md): the mean cost "
    "per step as such an IQM, and the fraction of all episodes whose mean cost per step "
    "exceeds tether_gym.tasks.cost.COST_LIMIT (raw, like success).",
    "Scenarios are defined for any number of bodies (per-tether values follow n_bodies, "
    "agents/evaluation/scenarios.py). Trained agents run on the n_bodies, amplitude, "
    "frequency and control_step their agent.json records, for every policy of the call, "
    "unless --env-kwargs gives them; an agent runs only on the n_bodies it was trained on.",
    "A policy of your own: register it with tether_gym_agents.register_policy(name, "
    "factory, kind=..., env_kwargs=...) and call tether_gym_agents.cli.evaluate.main([name, "
    "...]) or tether_gym_agents.evaluate([name, ...]) (README: Evaluate your own "
    "controller).",
    "Reproduce the paper instead: evaluate.py paper --out DIR (alias: evaluate.py "
    "--paper --out DIR).")

SEEDS_HELP = (f"episodes per scenario and policy (env seeds --seed ... --seed+K-1; per "
              f"training run of a folder of seed runs), 1 ... {MAX_SEEDS} (default 10); not "
              "train.py's --seeds (training runs)")


def _bench_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    parser.add_argument("policies", nargs="*",
                        help=f"registered policies ({', '.join(BASELINES)}, and those "
                             "added with register_policy), shipped agents "
                             "(ppo, ...), paths to trained agents (run folder, model file, or "
                             "a folder of seed_K run folders = one policy with several runs), "
                             "handover:AGENT (the agent hands over to smc, filtered) or "
                             "filtered:AGENT (a rate-mode agent behind the safety filter); "
                             "default: all baselines, shipped agents, handover:ppo and "
                             "filtered:distill_ppo")
    parser.add_argument("--suite", default="default",
                        help="scenario suite: a name below or a YAML suite file (default: "
                             "default)")
    parser.add_argument("--env-kwargs", nargs="+", default=[], metavar="KEY=VALUE",
                        help="env arguments applied on top of every scenario (and over "
                             "what trained agents were trained on), as Python literals, e.g. "
                             "n_bodies=4 eccentricity=0.3 masses=(1,2,3); not an action or "
                             "observation argument a policy sets itself (the baselines' "
                             "reel-rate mode, an agent's action mode, gain and observation)")
    parser.add_argument("--seeds", type=int, default=10, metavar="K", help=SEEDS_HELP)
    parser.add_argument("--seed", type=int, default=0, help="first env seed (default 0)")
    parser.add_argument("--out", default=None,
                        help="folder for results.json and plots (default: a new folder "
                             f"{DEFAULT_OUT_PARENT}/<YYYYmmdd-HHMMSS>/ per call, so that no "
                             "evaluation overwrites another; an existing --out is written "
                             "over)")
    parser.add_argument("--torch-threads", type=int, default=1,
                        help="torch threads for trained agents (default 1; results do not "
                             "depend on it)")
    parser.add_argument("--no-plots", action="store_true", help="skip the plots")
    parser.add_argument("--allow-pickle", action="store_true",
                        help="also load stable-baselines3's pickled files (*.zip, "
                             "vecnormalize.pkl) when a folder has no agent.json; a pickle "
                             "runs code when loaded: only for files you made or trust")
    return parser


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``evaluate.py`` with its ``bench`` and ``paper`` commands."""
    from ..paper.cli import add_arguments as add_paper_arguments

    epilog = "\n\n".join([describe_suites(), *(textwrap.fill(n, 79) for n in NOTES)])
    top = argparse.ArgumentParser(
        prog="evaluate.py", formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Benchmark policies on tether_gym scenario suites (evaluate.py [bench] "
                    "...), or reproduce the paper's figures (evaluate.py paper ...).",
        epilog=epilog)
    sub = top.add_subparsers(dest="command", metavar="{bench,paper,curves,dataset}")
    bench = sub.add_parser("bench", help="benchmark policies (the default command)",
                           prog="evaluate.py [bench]", epilog=epilog,
                           formatter_class=argparse.RawDescriptionHelpFormatter,
                           description="Benchmark policies on a tether_gym scenario suite.")
    _bench_arguments(bench)
    paper = sub.add_parser("paper", help="reproduce Shi, Zhu & Zhu (2019), Figs. 2-9",
                           prog="evaluate.py paper",
                           description="Reproduce Shi, Zhu & Zhu (2019), Figs. 2-9, from "
                                       "tether_gym and write paper_vs_tether_gym.md/.json "
                                       "beside the PNG figures.")
    add_paper_arguments(paper)
    curves = sub.add_parser("curves", help="learning curves: every checkpoint of seed runs, "
                                           "scored on a suite, against steps and wall time",
                            prog="evaluate.py curves",
                            description="Evaluate the checkpoint agents "
                                        "(checkpoints/agent_<N>_steps/) of folders of seed "
                                        "runs on a suite, as the benchmark scores a policy; "
                                        "write curves.json, curves.md and curves.png. A "
                                        "folder with a curves.json this command wrote is "
                                        "read, not evaluated again, so separately evaluated "
                                        "curves can be put side by side.")
    curves.add_argument("runs", nargs="+", type=Path,
                        help="folders of seed_K run folders written by train.py, or output "
                             "folders of this command (their curves.json)")
    curves.add_argument("--suite", default="default", help="scenario suite (default: default)")
    curves.add_argument("--seeds", type=int, default=10, metavar="K", help=SEEDS_HELP)
    curves.add_argument("--rms", type=float, default=5.5e-3,
                        help="threshold tracking RMS [rad] (default 5.5e-3)")
    curves.add_argument("--success", type=float, default=0.99,
                        help="threshold success fraction (default 0.99)")
    curves.add_argument("--filtered", action="store_true",
                        help="score each checkpoint behind the safety filter, as "
                             "filtered:RUN (rate-mode agents)")
    curves.add_argument("--out", required=True, help="output folder")
    dataset = sub.add_parser("dataset", help="Minari demonstration datasets of policies "
                                             "(the datasets extra; docs/datasets.md)",
                             prog="evaluate.py dataset",
                             description="Roll each policy out on the learners' training "
                                         "distribution and write a Minari dataset "
                                         "(MINARI_DATASETS_PATH, else ~/.minari/datasets).")
    add_dataset_arguments(dataset)
    return top


def _with_command(argv: list[str]) -> list[str]:
    """``argv`` with its command first: ``--paper`` anywhere means ``paper``, none ``bench``."""
    if "--paper" in argv:
        return ["paper"] + [a for a in argv if a != "--paper"]
    if not argv or argv[0] not in COMMANDS:
        return ["bench", *argv]
    return argv


def _checked(args: argparse.Namespace) -> tuple[dict, list[str], dict]:
    """The env arguments, the policy names and their specs (``{name: spec}``, agents
    loaded) of a bench command, every argument checked.

    Raises ValueError naming the flag or the value, before anything is built or run.
    """
    env_kwargs = parse_env_kwargs(args.env_kwargs)
    check_int("--seeds", args.seeds, 1, MAX_SEEDS)
    check_int("--seed", args.seed, 0, MAX_SEED - args.seeds + 1)
    check_int("--torch-threads", args.torch_threads, 1, MAX_TORCH_THREADS)
    get_suite(args.suite)
    names, specs = list(args.policies or default_policies()), {}
    for name in names:  # every agent loads before --out is made: a refused one leaves
        if name not in specs:  # no empty folder behind
            specs[name] = _resolved(name, args.allow_pickle)
            specs[name].load()
    if args.out is None:
        args.out = new_out_dir()
    else:
        check_out_dir(args.out)
        args.out = Path(args.out)
        if (args.out / "results.json").exists():
            print(f"--out {args.out}: replacing the results of an earlier evaluation there")
    return env_kwargs, names, specs


def _resolved(name: str, allow_pickle: bool):
    """``resolve_policy(name)``, after refusing a path that is neither a file nor a folder."""
    path = name.removeprefix("handover:")
    try:
        if path:
            refuse_special_file(path)
    except ValueError as exc:
        shown = repr(name) if len(name) <= 200 else f"{name[:60]!r}..."
        raise ValueError(f"policy {shown}: {exc}") from None
    return resolve_policy(name, allow_pickle)


def _remove_if_made_empty(out, made: bool) -> None:
    """Remove the output folder ``out`` after an error when this call made it, still empty."""
    if made and isinstance(out, Path) and out.is_dir() and not any(out.iterdir()):
        out.rmdir()


def _bench(args: argparse.Namespace, command: str) -> int:
    """Run the bench command; print the tables. Returns the exit code."""
    made = args.out is None or not Path(args.out).exists()  # removed again if left empty
    try:
        env_kwargs, policies, specs = _checked(args)
        t0 = time.perf_counter()
        print(f"tether_gym {tether_gym.__version__}: {len(policies)} policies on suite "
              f"{args.suite!r}, {args.seeds} seeds per scenario and run, torch threads "
              f"{args.torch_threads}" + (f", env kwargs {env_kwargs}" if env_kwargs else "")
              + f"; results go to {args.out}")
        options = EvalOptions(out=args.out, plots=not args.no_plots,
                              torch_threads=args.torch_threads, command=command,
                              allow_pickle=args.allow_pickle)
        results = evaluate([specs[name] for name in policies], args.suite, args.seeds,
                           args.seed, env_kwargs, options)  # the agents loaded above
    except ValueError as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        _remove_if_made_empty(args.out, made)
        return 2
    print()
    print(markdown_tables(results))
    print(f"\nresults: {args.out / 'results.json'} ({time.perf_counter() - t0:.0f} s)")
    return 0


def main(argv=None) -> int:
    """Command line of ``evaluate.py``; returns the exit code.

    ``evaluate.py [bench] [policies] [options]`` benchmarks (the default command),
    ``evaluate.py paper --out DIR`` reproduces the paper; ``--paper`` anywhere is an
    alias of the ``paper`` command.
    """
    argv = [str(a) for a in (sys.argv[1:] if argv is None else argv)]
    command = shlex.join(["evaluate.py", *argv])
    args = build_parser().parse_args(_with_command(argv))
    if args.command == "paper":
        from ..paper.cli import run as paper_run

        return paper_run(args)  # it checks --out before any study
    if args.command == "curves":
        return _curves(args)
    if args.command == "dataset":
        return dataset_run(args)
    return _bench(args, command)


def _curves(args: argparse.Namespace) -> int:
    """Run the curves command; print each policy's table. Returns the exit code."""
    from ..evaluation.curves import (
        CURVES_FILE,
        Threshold,
        learning_curves,
        load_curves,
        markdown,
        write_curves,
    )
    from ..files.run_folder import seed_runs

    made = not Path(args.out).exists()  # removed again if an error leaves it empty
    try:
        check_int("--seeds", args.seeds, 1, MAX_SEEDS)
        get_suite(args.suite)
        if not (math.isfinite(args.rms) and args.rms > 0):
            raise ValueError(f"--rms {args.rms!r} must be a finite threshold > 0 [rad]")
        if not 0.0 <= args.success <= 1.0:
            raise ValueError(f"--success {args.success!r} must be a fraction in [0, 1]")
        for run in args.runs:
            if not run.is_dir():
                raise ValueError(f"{run} is not a folder of seed runs")
        check_out_dir(args.out)
        args.out = Path(args.out)
        threshold = Threshold(args.rms, args.success)
        all_curves = []
        for run in args.runs:
            if (run / CURVES_FILE).is_file() and not seed_runs(run):
                print(f"{run}: reading its {CURVES_FILE}")
                all_curves += load_curves(run, args.suite, args.seeds, threshold)
                continue
            print(f"{run}: evaluating its checkpoints on suite {args.suite!r} ...")
            all_curves.append(learning_curves(run, args.suite, args.seeds, threshold,
                                              filtered=args.filtered))
            print(markdown(all_curves[-1]))
    except ValueError as exc:
        print(f"evaluate.py: error: {exc}", file=sys.stderr)
        _remove_if_made_empty(args.out, made)
        return 2
    for path in write_curves(all_curves, args.out):
        print(f"wrote {path}")
    return 0
