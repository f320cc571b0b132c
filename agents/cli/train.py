"""Train an agent on a tether_gym environment: the command line of ``train.py``.

The learning algorithms (``--algo``) are the rows of
:data:`~tether_gym_agents.common.algorithms.ALGORITHMS` (PPO, PPO-Lagrangian, SAC, TQC, TD3 today).

``main`` parses the command line into a ``TrainOptions``, resolves it once into a
``TrainSettings`` (both in :mod:`tether_gym_agents.training.settings`) and trains
(:func:`tether_gym_agents.training.run.train`), or hands the options to the fan-out of
seeds (:mod:`tether_gym_agents.training.fanout`) or the sweep
(:mod:`tether_gym_agents.training.sweep`). Errors are ``ConfigError`` exceptions
(:mod:`tether_gym_agents.training.config`); ``main`` prints their message as
``train.py: error: <message>`` and returns 2.

A run folder (``--out``) keeps everything needed to reproduce, evaluate and resume
the run:

* ``config.yml`` (resolved hyperparameters, algorithm, env id and the resolved env
  kwargs), ``args.yml`` (parsed arguments), ``command.txt`` (every command line);
* ``agent.json`` + ``policy.safetensors``: the best agent (the evaluations' best) in the
  safe format of :mod:`tether_gym_agents.files.safe_format`, which is what ``evaluate.py
  RUN`` loads; ``final_agent/``: the agent at the last step, in the same format;
* ``eval/evaluations.npz`` and ``learning_curve.png`` (the learning curve; every run
  ends with an evaluation, whatever its budget), ``tb/`` (TensorBoard);
* ``train_info.json`` (steps, wall time including interrupted parts, seed; rewritten
  every ``PROGRESS_EVERY_S`` seconds while training and at each checkpoint);
* for ``--resume``: the models (``final_model.zip``, ``best_model.zip``,
  ``checkpoints/``), read back as tensors only, and the normalisation statistics and
  an off-policy algorithm's replay buffer as ``.npz`` arrays; stable-baselines3's pickled
  ``vecnormalize.pkl`` and ``*replay_buffer.pkl`` are written beside them for other
  tools and are unpickled only with ``--allow-pickle``.

The layout is owned by :mod:`tether_gym_agents.files.run_folder`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import tether_gym

from ..training.config import ConfigError
from ..training.fanout import run_fanout
from ..training.run import train
from ..training.settings import ALGOS, SEED_MAX, TrainOptions, resolve_settings
from ..training.sweep import run_sweep

__all__ = ["main", "build_parser"]


def main(argv=None) -> int:
    """Command line of ``train.py``; returns the exit code."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["gpu"]:  # PPO with env and learner on a torch device
        from ..accel.cli import main as gpu_main

        return gpu_main(argv[1:])
    if argv[:1] == ["distill"]:  # DAgger: a network trained on mpc's labels
        from ..training.distill_cli import main as distill_main

        return distill_main(argv[1:])
    args = build_parser().parse_args(argv)
    try:
        options = TrainOptions.from_namespace(args)
        if options.sweep is not None:
            return run_sweep(options)  # Ray is imported there only
        if options.seeds is not None:
            return run_fanout(options)
        train(resolve_settings(options, command=tuple(argv)))
        return 0
    except ConfigError as exc:
        print(f"train.py: error: {exc}", file=sys.stderr)
        return 2


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``train.py`` (its options are the fields of TrainOptions)."""
    p = argparse.ArgumentParser(prog="train.py", description="Train an agent on tether_gym.")
    p.add_argument("--algo", choices=ALGOS, default="ppo",
                   help=f"one of {', '.join(ALGOS)} (tqc needs sb3-contrib: pip install -e "
                        "\".[tqc]\" in a clone)")
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
    p.add_argument("--allow-pickle", action="store_true",
                   help="let --resume unpickle the statistics and replay buffer of a run "
                        "saved before they were also written as arrays (a pickle can run any "
                        "code: only for run folders you made or trust)")
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
    fan = p.add_argument_group("many runs on Ray (pip install -e \".[ray]\")")
    fan.add_argument("--seeds", type=int, default=None, metavar="N",
                     help="train N runs, training seeds --seed ... --seed+N-1, into "
                          "<out>/seed_K/ (not evaluate.py's --seeds, which counts episodes "
                          "per scenario), one Ray task each; re-running skips finished seeds "
                          "and resumes interrupted ones")
    fan.add_argument("--ray-address", default=None, metavar="ADDRESS",
                     help="existing Ray cluster: auto, HOST:PORT or ray://HOST:PORT; local "
                          "for a new local instance (default: $RAY_ADDRESS, else a local "
                          "instance with one CPU per run)")
    fan.add_argument("--sweep", type=Path, default=None, metavar="FILE.yml",
                     help="search config keys x several seeds per trial, rank by the median "
                          "final evaluation return (file format: tether_gym_agents.training.sweep)")
    return p
