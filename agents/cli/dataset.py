"""``python evaluate.py dataset POLICY ...``: Minari demonstration datasets of policies.

One dataset per policy (:func:`tether_gym_agents.evaluation.datasets.build_dataset`), on
the training distribution of the shipped PPO agents (``agents/configs/ppo.yml``'s
``env_kwargs``: random masses, eccentricity and initial libration, disturbance and
observation noise) unless ``--env-kwargs`` replaces it. docs/datasets.md has the recipe
and checksums of the datasets the benchmark describes.
"""

from __future__ import annotations

import argparse
import sys
import time

import gymnasium as gym

import tether_gym

from ..common.env_kwargs import parse_env_kwargs
from ..evaluation.datasets import (
    MAX_EPISODES,
    build_dataset,
    check_request,
    dataset_id_for,
    dataset_path,
    require_minari,
)
from ..evaluation.registry import resolve_policy
from ..training.config import training_distribution

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``dataset`` command's arguments."""
    parser.add_argument("policies", nargs="+",
                        help="registered policies (mpc, smc_filtered, ...), shipped agents "
                             "or run folders; one dataset each")
    parser.add_argument("--episodes", type=int, default=50,
                        help=f"episodes per dataset, 1 ... {MAX_EPISODES} (default 50)")
    parser.add_argument("--seed", type=int, default=0,
                        help="env seed of the first episode; episode k uses seed + k "
                             "(default 0)")
    parser.add_argument("--env-kwargs", nargs="+", default=None, metavar="KEY=VALUE",
                        help="env arguments instead of the training distribution "
                             "(agents/configs/ppo.yml's env_kwargs), as Python literals")
    parser.add_argument("--dataset-id", default=None,
                        help="Minari id (one policy only; default "
                             "tether_gym/libration/<policy>-v0)")


def run(args: argparse.Namespace) -> int:
    """Build each dataset; one line per episode; returns the exit code."""
    try:
        if args.dataset_id is not None and len(args.policies) != 1:
            raise ValueError(f"--dataset-id {args.dataset_id!r} names one dataset; "
                             f"{len(args.policies)} policies given")
        env_kwargs = (training_distribution() if args.env_kwargs is None
                      else parse_env_kwargs(args.env_kwargs))
        ids = [args.dataset_id or dataset_id_for(p) for p in args.policies]
        for policy, dataset_id in zip(args.policies, ids, strict=True):
            check_request(policy, args.episodes, args.seed, dataset_id)
            spec = resolve_policy(policy)  # an unknown policy or a bad agent file: now
            spec.load()
            gym.make(tether_gym.ENV_ID, **{**env_kwargs, **spec.env_kwargs}).close()
        minari = require_minari()
        existing = set(minari.list_local_datasets())
        for dataset_id in ids:
            if dataset_id in existing:
                raise ValueError(f"dataset {dataset_id!r} exists at "
                                 f"{dataset_path(dataset_id)}: remove it "
                                 f"(minari.delete_dataset) or give --dataset-id")
    except (ValueError, TypeError, ImportError) as exc:
        print(f"evaluate.py dataset: error: {exc}", file=sys.stderr)
        return 2
    for policy, dataset_id in zip(args.policies, ids, strict=True):
        t0 = time.perf_counter()
        print(f"{policy}: {args.episodes} episodes from env seed {args.seed} -> "
              f"{dataset_id}", flush=True)
        try:
            dataset, checksum = build_dataset(policy, env_kwargs, args.episodes, args.seed,
                                              dataset_id, log=lambda s: print(s, flush=True))
        except (ValueError, TypeError) as exc:
            print(f"evaluate.py dataset: error: {exc}", file=sys.stderr)
            return 2
        print(f"{dataset_id}: {dataset.total_episodes} episodes, {dataset.total_steps} "
              f"steps, content sha256 {checksum}, at {dataset_path(dataset_id)} "
              f"({time.perf_counter() - t0:.0f} s); load it with "
              f"minari.load_dataset({dataset_id!r})", flush=True)
    return 0
