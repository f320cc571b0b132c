"""Demonstration datasets of any policy, in the Minari format (offline RL, imitation).

:func:`build_dataset` rolls a policy of the registry (``mpc``, ``smc_filtered``, a
trained agent ...) out on a TetherLibration env, episode by episode, and writes the
episodes as a Minari dataset (``minari``, the maintained successor of D4RL; the
``datasets`` extra): ``minari.load_dataset(dataset_id)`` loads it, and
``dataset.recover_environment()`` makes its env again from the env spec recorded in it
(id and every keyword argument).

What one episode holds (Minari's layout: T steps, T + 1 observations):

* ``observations`` (T + 1, obs_dim) float32: the env's observation, the reset's first,
  exactly what a learned agent sees (noise included, nothing privileged);
* ``actions`` (T, n) float32: the policy's action in the env's action box [-1, 1] (the
  baselines command reel rates, ``action_mode="rate"``: the dataset env is made so);
* ``rewards``, ``terminations``, ``truncations`` (T,);
* ``infos``: :data:`INFO_KEYS` of every step's info, the reset's first (T + 1 rows):
  the constraint cost and its parts (docs/safe_rl.md), the smallest tension, theta and
  theta_d, for safe offline RL and for plots.

Episode k is the env reset with seed ``seed + k``; the policy is deterministic, so a
dataset is a function of (policy, env kwargs, episodes, seed) and of the code.
:func:`content_checksum` hashes the arrays (not the HDF5 file, whose bytes hold
creation times): a rebuilt dataset has the recorded checksum.
"""

from __future__ import annotations

import hashlib
import re
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import tether_gym

from .registry import check_given_env_kwargs, make_policy, resolve_policy

__all__ = ["INFO_KEYS", "DATASET_PREFIX", "MAX_EPISODES", "dataset_id_for", "build_dataset",
           "content_checksum", "require_minari", "dataset_path", "check_request"]

INFO_KEYS = ("cost", "cost_slack", "cost_length", "cost_tumble", "tension_min", "theta",
             "theta_ref")
"""Entries of the env's info recorded for every step (and the reset)."""
DATASET_PREFIX = "tether_gym/libration"
"""Namespace of the datasets' ids: ``tether_gym/libration/<policy>-v0``."""
MAX_EPISODES = 100_000
_ID = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_./-]*-v\d+$")
MINARI_PIP = 'pip install "minari[hdf5]==0.5.4"'


def require_minari():
    """The ``minari`` module; ImportError with the pip command when it is missing."""
    try:
        import minari
    except ImportError as exc:
        raise ImportError(f"Minari datasets need minari with its HDF5 storage: {MINARI_PIP} "
                          f'(or pip install -e ".[datasets]")') from exc
    try:
        import h5py  # noqa: F401  (Minari's default storage)
    except ImportError as exc:
        raise ImportError(f"Minari's HDF5 storage needs h5py: {MINARI_PIP}") from exc
    return minari


def dataset_id_for(policy: str) -> str:
    """``tether_gym/libration/<policy>-v0`` for a registry name (letters, digits, ``_``)."""
    if not re.fullmatch(r"[A-Za-z0-9_]+", policy):
        raise ValueError(f"policy {policy!r} is not a plain name: give the dataset id "
                         f"(e.g. {DATASET_PREFIX}/my_agent-v0)")
    return f"{DATASET_PREFIX}/{policy}-v0"


def check_request(policy: str, episodes: int, seed: int, dataset_id: str) -> None:
    """Refuse a bad request (TypeError/ValueError naming the value and its range)."""
    if not isinstance(policy, str) or not policy:
        raise TypeError(f"policy must be a non-empty string, got {policy!r}")
    for name, value, high in (("episodes", episodes, MAX_EPISODES),
                              ("seed", seed, 2**31 - 1 - MAX_EPISODES)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise TypeError(f"{name} must be an integer, got {value!r}")
        low = 1 if name == "episodes" else 0
        if not low <= value <= high:
            why = ("" if name == "episodes" else f" (episode k resets with seed + k, and "
                   f"every env seed stays below 2**31 for up to {MAX_EPISODES} episodes)")
            raise ValueError(f"{name} {value!r} must be in [{low}, {high}]{why}")
    if not isinstance(dataset_id, str) or not _ID.fullmatch(dataset_id):
        raise ValueError(f"dataset id {dataset_id!r} must look like "
                         f"{DATASET_PREFIX}/<name>-v<K> (letters, digits, _ . / -)")


def _episode(env, policy, seed: int) -> dict[str, Any]:
    """One deterministic episode's arrays (Minari's layout) and its summary."""
    obs, info = env.reset(seed=seed)
    observations, actions, rewards, terms, truncs = [obs], [], [], [], []
    infos: dict[str, list] = {key: [np.asarray(info[key], dtype=float)] for key in INFO_KEYS}
    first, done = True, False
    while not done:
        action, _ = policy.predict(obs, episode_start=np.array([first]), deterministic=True)
        first = False
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        actions.append(np.asarray(action, dtype=np.float32))
        rewards.append(float(reward))
        terms.append(bool(terminated))
        truncs.append(bool(truncated))
        for key in INFO_KEYS:
            infos[key].append(np.asarray(info[key], dtype=float))
        done = terminated or truncated
    return {"observations": np.asarray(observations, dtype=np.float32),
            "actions": np.asarray(actions, dtype=np.float32),
            "rewards": np.asarray(rewards), "terminations": np.asarray(terms),
            "truncations": np.asarray(truncs),
            "infos": {key: np.asarray(v) for key, v in infos.items()},
            "failure": str(info.get("failure", ""))}


def content_checksum(episodes) -> str:
    """sha256 of every episode's arrays, in episode order.

    ``episodes``: Minari ``EpisodeData`` (``dataset.iterate_episodes()``) or the dicts
    :func:`build_dataset` makes. Observations and actions as float32, rewards as float64,
    the flags as bytes 0/1, each little-endian and C-ordered.
    """
    digest = hashlib.sha256()
    for ep in episodes:
        get = ep.get if isinstance(ep, dict) else lambda name, ep=ep: getattr(ep, name)
        for name, dtype in (("observations", "<f4"), ("actions", "<f4"), ("rewards", "<f8"),
                            ("terminations", "u1"), ("truncations", "u1")):
            digest.update(np.ascontiguousarray(np.asarray(get(name)).astype(dtype)).tobytes())
    return digest.hexdigest()


def build_dataset(policy: str, env_kwargs: dict, episodes: int, seed: int = 0,
                  dataset_id: str | None = None,
                  log: Callable[[str], None] | None = print) -> tuple[Any, str]:
    """Roll ``policy`` out for ``episodes`` episodes and write a Minari dataset.

    Parameters
    ----------
    policy : str
        A name of the policy registry (``mpc``, ``smc_filtered``, a shipped agent, a run
        folder), built by :func:`~.registry.make_policy` on the dataset env.
    env_kwargs : dict
        The env's keyword arguments (e.g. a training distribution). The policy's own
        (``resolve_policy(policy).env_kwargs``, as evaluate.py applies them: the
        baselines' ``action_mode="rate"``, a trained agent's action mode and bodies)
        go over them.
    episodes : int
        Episodes, 1 ... :data:`MAX_EPISODES`; episode k resets with seed ``seed + k``.
    seed : int
        First env seed, >= 0.
    dataset_id : str or None
        Minari id; default :func:`dataset_id_for` ``(policy)``. Written under Minari's
        root (``MINARI_DATASETS_PATH``, else ``~/.minari/datasets``); an existing id is
        refused.
    log : callable or None
        Receives one progress line per episode.

    Returns
    -------
    (minari.MinariDataset, str)
        The dataset and its :func:`content_checksum`.
    """
    dataset_id = dataset_id_for(policy) if dataset_id is None else dataset_id
    check_request(policy, episodes, seed, dataset_id)
    minari = require_minari()
    from minari.data_collector.episode_buffer import EpisodeBuffer

    if dataset_id in minari.list_local_datasets():
        raise ValueError(f"dataset {dataset_id!r} exists at {dataset_path(dataset_id)}: "
                         f"remove it (minari.delete_dataset({dataset_id!r})) or give "
                         "another id")
    spec = resolve_policy(policy)
    spec.load()
    # the policy's own env arguments over the given ones, as evaluate.py does: reel rates
    # for the baselines, a trained agent's action mode, bodies and reference; a given
    # value they would replace is refused
    check_given_env_kwargs(spec, env_kwargs)
    kwargs = {**env_kwargs, **spec.env_kwargs}
    env = gym.make(tether_gym.ENV_ID, **kwargs)
    agent_policy = make_policy(policy, env)
    records, buffers = [], []
    t0 = time.perf_counter()
    for k in range(episodes):
        t = time.perf_counter()
        ep = _episode(env, agent_policy, seed + k)
        records.append(ep)
        buffers.append(EpisodeBuffer(
            id=k, seed=seed + k, observations=ep["observations"], actions=ep["actions"],
            rewards=list(ep["rewards"]), terminations=list(ep["terminations"]),
            truncations=list(ep["truncations"]), infos=ep["infos"]))
        if log is not None:
            steps = len(ep["rewards"])
            log(f"  [{policy}] episode {k + 1}/{episodes} (env seed {seed + k}): {steps} "
                f"steps, return {ep['rewards'].sum():.2f}, "
                f"{'failed: ' + ep['failure'] if ep['terminations'][-1] else 'survived'}, "
                f"{time.perf_counter() - t:.1f} s ({time.perf_counter() - t0:.0f} s in all)")
    checksum = content_checksum(records)
    steps = sum(len(ep["rewards"]) for ep in records)
    survived = sum(not ep["terminations"][-1] for ep in records)
    description = (
        f"{policy} on {tether_gym.ENV_ID} (tether_gym {tether_gym.__version__}), "
        f"{episodes} episodes, env seeds {seed}..{seed + episodes - 1}, env kwargs "
        f"{kwargs}; {survived}/{episodes} survived, {steps} steps; content sha256 "
        f"{checksum}. infos: {', '.join(INFO_KEYS)}.")
    with warnings.catch_warnings():  # Minari asks for a contact e-mail and a code URL
        warnings.filterwarnings("ignore", message=r"`(author_email|code_permalink)` is set",
                                category=UserWarning)
        dataset = minari.create_dataset_from_buffers(
            dataset_id, buffers, env=env, eval_env=env.spec, algorithm_name=policy,
            author="tether_gym", description=description, requirements=["tether_gym"])
    env.close()
    return dataset, checksum


def dataset_path(dataset_id: str) -> Path:
    """Where Minari keeps ``dataset_id`` locally."""
    from minari.storage.datasets_root_dir import get_dataset_path

    return Path(get_dataset_path(dataset_id))
