"""``python train.py distill``: a student network trained by DAgger on ``mpc``'s labels.

    python train.py distill --iterations 5 --episodes 6 --seed 0 --out runs/dagger/seed_0

writes a run folder that ``python evaluate.py runs/dagger/seed_0`` (or ``runs/dagger``,
all seeds as one policy) scores like any trained agent; the algorithm, its outputs and
its choices are in :mod:`tether_gym_agents.training.dagger`. Needs CasADi for the expert
(``pip install -e ".[mpc]"`` in a clone). A bad value is refused as one line naming it
and its valid range (exit code 2) before anything is built.
"""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from tether_gym.envs.config import EnvConfig

from ..common.ranges import interval
from ..files.folder_paths import FolderFileError
from .dagger import (
    LIMITS,
    MIXTURES,
    DaggerSettings,
    Dataset,
    InitPolicyError,
    check_out,
    fmt_rate,
    train_dagger,
    training_env_kwargs,
)

__all__ = ["main", "build_parser"]

PROG = "train.py distill"


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (argparse prints the usage too)
        print(f"{PROG}: error: {message}", file=sys.stderr)
        raise SystemExit(2)


def _range(name: str) -> str:
    lo, hi = LIMITS[name]
    return interval(lo, hi)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``train.py distill``."""
    d = DaggerSettings()
    p = _Parser(prog=PROG, description="Distil mpc into a network by DAgger (Ross et al. "
                "2011): mpc labels every observation the student's mixture visits.")
    p.add_argument("--iterations", type=int, default=d.iterations,
                   help=f"DAgger iterations, iteration 0 the expert alone, in "
                        f"{_range('iterations')} (default {d.iterations})")
    p.add_argument("--episodes", type=int, default=d.episodes,
                   help=f"labelled episodes per iteration, in {_range('episodes')} (default "
                        f"{d.episodes}; mpc costs ~15-25 ms per step, ~10-20 s per "
                        "3-orbit episode)")
    p.add_argument("--epochs", type=int, default=d.epochs,
                   help=f"passes over the aggregated data per refit, in "
                        f"{_range('epochs')} (default {d.epochs})")
    p.add_argument("--seed", type=int, default=d.seed,
                   help=f"seed in {_range('seed')} (default {d.seed})")
    p.add_argument("--orbits", type=float, default=None,
                   help=f"episode length [orbits] in {_range('orbits')} (default: the env's, 3)")
    p.add_argument("--beta-decay", type=float, default=d.beta_decay,
                   help=f"the mixture executes mpc's action with probability "
                        f"beta_decay**iteration, in {_range('beta_decay')} (default "
                        f"{d.beta_decay})")
    p.add_argument("--mixture", choices=MIXTURES, default=d.mixture,
                   help="step: each step executes mpc's action with probability beta; "
                        "episode: each episode is flown by mpc alone with probability beta, "
                        f"else by the student alone (default {d.mixture})")
    p.add_argument("--net-arch", type=int, nargs="+", default=list(d.net_arch),
                   metavar="WIDTH", help="hidden layer widths of the tanh MLP (default "
                                         f"{' '.join(map(str, d.net_arch))})")
    p.add_argument("--batch-size", type=int, default=d.batch_size,
                   help=f"minibatch, in {_range('batch_size')} (default {d.batch_size})")
    p.add_argument("--learning-rate", type=float, default=d.learning_rate,
                   help=f"Adam's initial step, in {_range('learning_rate')} (default "
                        f"{d.learning_rate:g})")
    p.add_argument("--check-episodes", type=int, default=d.check_episodes,
                   help=f"unlabelled episodes the student flies alone after each refit, in "
                        f"{_range('check_episodes')} (default {d.check_episodes})")
    p.add_argument("--expert-noise", type=float, default=d.expert_noise,
                   help="standard deviation of Gaussian noise on mpc's executed action "
                        f"(DART; the label stays clean), in {_range('expert_noise')} "
                        f"(default {d.expert_noise:g})")
    p.add_argument("--gate", type=float, default=None,
                   help="HG-DAgger intervention: mpc flies the rest of an episode once the "
                        "student's action departs from mpc's by more than this, in "
                        f"{_range('gate')} (default: never)")
    p.add_argument("--drop-failed", action="store_true",
                   help="leave the labels of terminated episodes out of the aggregate")
    p.add_argument("--symlog-scale", type=float, default=None, metavar="S",
                   help="the student also sees symlog(e/S) and symlog(e'/S) of its tracking "
                        f"errors (S [rad] in {_range('symlog_scale')}; default: no features)")
    p.add_argument("--data", type=str, nargs="+", default=None, metavar="NPZ",
                   help="shared labelled data (dagger_data.npz files of earlier runs) the "
                        "student is first fitted on; the labelled iterations follow")
    p.add_argument("--init-policy", type=str, default=None, metavar="AGENT",
                   help="start the student from a trained rate-mode ppo agent (a run folder "
                        "or a shipped name such as distill_ppo/seed_{seed}; {seed} is the "
                        "seed), its observation statistics kept: mpc relabels the states it "
                        "visits from iteration 1 on (default: a new network)")
    p.add_argument("--out", type=str, default=None,
                   help="run folder (default runs/dagger/seed_<seed>)")
    return p


def main(argv=None) -> int:
    """Command line of ``train.py distill``; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    try:
        settings = DaggerSettings(
            iterations=args.iterations, episodes=args.episodes, epochs=args.epochs,
            seed=args.seed, orbits=args.orbits, beta_decay=args.beta_decay,
            net_arch=tuple(args.net_arch), batch_size=args.batch_size,
            learning_rate=args.learning_rate, check_episodes=args.check_episodes,
            mixture=args.mixture, expert_noise=args.expert_noise, gate=args.gate,
            drop_failed=args.drop_failed, symlog_scale=args.symlog_scale,
            init_policy=args.init_policy)
    except ValueError as exc:
        print(f"{PROG}: error: {_flag(str(exc))}", file=sys.stderr)
        return 2
    if settings.iterations == 0 and not args.data:
        print(f"{PROG}: error: --iterations 0 fits on shared data alone: give --data NPZ",
              file=sys.stderr)
        return 2
    try:
        import casadi  # noqa: F401  (the expert's solver)
    except ImportError:
        print(f"{PROG}: error: the expert mpc needs CasADi: pip install -e \".[mpc]\"",
              file=sys.stderr)
        return 2
    out = Path(args.out if args.out is not None else f"runs/dagger/seed_{settings.seed}")
    # an earlier run there is refused before the data are read; a new folder is made
    # (and checked) by train_dagger, after its own refusals
    if out.exists() or out.is_symlink():
        try:
            check_out(out)
        except FolderFileError as exc:
            print(f"{PROG}: error: {exc}", file=sys.stderr)
            return 2
    initial = None
    env = EnvConfig.from_kwargs(**training_env_kwargs(settings.orbits)) if args.data else None
    for path in args.data or ():
        try:  # its messages name the file and the key
            part = _fitting(Dataset.load(path), path, env)
        except ValueError as exc:
            print(f"{PROG}: error: --data {exc}", file=sys.stderr)
            return 2
        if initial is None:
            initial = part
        else:
            initial.extend(part)
    command = shlex.join(["python", "train.py", "distill", *argv])
    try:
        summary = train_dagger(settings, out, command=command, initial=initial)
    except InitPolicyError as exc:  # refused before the run folder is written
        print(f"{PROG}: error: {_flag(str(exc))}", file=sys.stderr)
        return 2
    except FolderFileError as exc:  # a new --out that cannot be made or written
        print(f"{PROG}: error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {out}: {summary['labels']} labels in {summary['episodes']} episodes, "
          f"{summary['wall_time_s']:.1f} s ({fmt_rate(summary['labels_per_s'])}); "
          f"score it with: python evaluate.py {shlex.quote(str(out))}")
    return 0


def _fitting(data: Dataset, path, config) -> Dataset:
    """``data`` if its observations and labels fit the training env's ``config``."""
    got = (data.obs.shape[1], data.labels.shape[1])
    if got != (config.obs_dim, config.n_tethers):
        raise ValueError(f"{path}: observations of {got[0]} entries and labels of {got[1]}; "
                         f"the training env gives {config.obs_dim} and takes "
                         f"{config.n_tethers} (n_bodies {config.n_bodies})")
    return data


def _flag(message: str) -> str:
    """``name=value: ...`` as ``--name value: ...`` (the flag the user typed)."""
    name, sep, rest = message.partition("=")
    if sep and name.isidentifier():
        return f"--{name.replace('_', '-')}={rest}"
    return message
