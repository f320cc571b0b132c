"""A behaviour-cloning term beside PPO's updates (``bc_term``; fine-tuning a student).

PPO started from a distilled student (:mod:`.warm_start`) first learns to survive and
then drifts away from the student's precision: the reward barely tells a 1e-4 rad error
from a 1e-3 rad one, and nothing holds the actor near mpc's law. The config key

.. code-block:: yaml

    bc_term: {data: "runs/distill_data/part_*[02468]/dagger_data.npz",
              steps: 8, batch_size: 2048, learning_rate: 1.0e-5}

interleaves supervised steps with PPO's: before every rollout after the first, ``steps``
minibatches of ``batch_size`` (observation, mpc action) pairs drawn from the
``dagger_data.npz`` files of ``train.py distill`` (``data``: a glob pattern or a list
of paths) move the actor's deterministic action towards mpc's by Adam on the mean
squared error (its own optimiser, on the actor's parameters only, at
``learning_rate``). The inputs go through the run's feature and normalisation
pipeline exactly as the policy's do (the features of the config, then the training
env's current ``VecNormalize`` statistics). This is the auxiliary imitation loss of
demonstration-augmented policy gradients (Rajeswaran et al. 2018, DAPG; Nair et al.
2018), applied as alternating steps so that PPO's own update is stable-baselines3's,
unchanged. The loss of each phase is logged as ``train/bc_loss``. A resumed run
starts a new Adam for the term (its moments are not saved).
"""

from __future__ import annotations

import glob
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..common.features import add_features
from ..common.jsonio import checked_mapping
from ..common.ranges import interval
from .config import ConfigError

__all__ = ["BC_KEY", "BCTermSpec", "bc_term_spec", "BCTermCallback", "load_pairs"]

BC_KEY = "bc_term"
"""The config key (one of :data:`~.config.RUN_KEYS`)."""

_BOUNDS = {"steps": (1, 10_000), "batch_size": (1, 1_000_000),
           "learning_rate": (1e-9, 1.0)}


@dataclass(frozen=True)
class BCTermSpec:
    """The behaviour-cloning term's settings (plain data).

    Attributes
    ----------
    data : tuple of str
        The ``dagger_data.npz`` files (a glob pattern is expanded when checked).
    steps : int
        Minibatch steps per rollout [-].
    batch_size : int
        Pairs per minibatch [-].
    learning_rate : float
        Adam's step for the term [-].
    """

    data: tuple[str, ...]
    steps: int = 8
    batch_size: int = 2048
    learning_rate: float = 1e-5

    KEYS = ("data", "steps", "batch_size", "learning_rate")

    def to_dict(self) -> dict:
        """As the config records it (the expanded file list)."""
        return {"data": list(self.data), "steps": self.steps, "batch_size": self.batch_size,
                "learning_rate": self.learning_rate}


def bc_term_spec(value, source: str, algo: str) -> BCTermSpec | None:
    """The validated ``bc_term`` key (None when absent).

    Raises
    ------
    ConfigError
        For a non-mapping, an unknown key, a value out of its range (named with the
        range), a pattern that matches no file, or an algorithm other than PPO's.
    """
    if value is None:
        return None
    what = f"{source}: {BC_KEY}"
    try:
        checked_mapping(value, BCTermSpec.KEYS, what)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    if algo not in ("ppo", "ppo_lag"):
        raise ConfigError(f"{what}: the term steps an ActorCriticPolicy's actor; --algo {algo} "
                          "is not ppo or ppo_lag")
    data = value.get("data")
    if isinstance(data, str):
        files = sorted(glob.glob(data)) if glob.has_magic(data) else [data]
    elif isinstance(data, list) and data and all(isinstance(d, str) for d in data):
        files = list(data)
    else:
        raise ConfigError(f"{what}: data {data!r} must be a glob pattern or a list of "
                          "dagger_data.npz paths")
    if not files:
        raise ConfigError(f"{what}: data {data!r} matches no file")
    missing = [f for f in files if not Path(f).is_file()]
    if missing:
        raise ConfigError(f"{what}: data file {missing[0]!r} does not exist")
    numbers: dict[str, Any] = {}
    for key, (low, high) in _BOUNDS.items():
        v = value.get(key, getattr(BCTermSpec, key))
        integer = key != "learning_rate"
        ok = (not isinstance(v, bool) and isinstance(v, int if integer else (int, float))
              and math.isfinite(v) and low <= v <= high)
        if not ok:
            kind = "an integer" if integer else "a number"
            raise ConfigError(f"{what}: {key} {v!r} must be {kind} in {interval(low, high)}")
        numbers[key] = int(v) if integer else float(v)
    return BCTermSpec(tuple(files), **numbers)


def load_pairs(spec: BCTermSpec, features, n_tethers: int, input_dim: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """The term's (network input before normalisation, mpc action) pairs.

    Parameters
    ----------
    spec : BCTermSpec
        The term (its files).
    features : FeatureSpec or None
        The run's input features, appended to each stored observation.
    n_tethers : int
        The env's action size [-].
    input_dim : int
        The network's input size (observation and features) [-].

    Returns
    -------
    inputs, labels : numpy.ndarray
        float32 (N, input_dim) and float32 (N, n_tethers).

    Raises
    ------
    ConfigError
        If a file is not a DAgger dataset or its sizes do not fit the network.
    """
    from .dagger import Dataset

    inputs, labels = [], []
    for name in spec.data:
        try:
            part = Dataset.load(name)
        except ValueError as exc:  # its messages name the file and the key
            raise ConfigError(f"{BC_KEY}: {exc}") from None
        x = add_features(features, part.obs, n_tethers)
        if x.shape[1] != input_dim or part.labels.shape[1] != n_tethers:
            raise ConfigError(f"{BC_KEY}: {name} gives network inputs of {x.shape[1]} and "
                              f"actions of {part.labels.shape[1]}; the run's policy takes "
                              f"{input_dim} and acts on {n_tethers} tethers")
        inputs.append(x)
        labels.append(part.labels.astype(np.float32))
    return np.concatenate(inputs), np.concatenate(labels)


def _callback_base():
    from stable_baselines3.common.callbacks import BaseCallback
    return BaseCallback


class BCTermCallback(_callback_base()):  # type: ignore[misc]
    """Supervised steps on mpc's labels before every rollout after the first.

    Parameters
    ----------
    spec : BCTermSpec
        The term.
    features : FeatureSpec or None
        The run's input features.
    seed : int
        Seeds the minibatch draws.
    """

    def __init__(self, spec: BCTermSpec, features, seed: int):
        super().__init__()
        self.spec = spec
        self.features = features
        self.rng = np.random.default_rng(seed)
        self.inputs = np.zeros((0, 0), np.float32)
        self.labels = np.zeros((0, 0), np.float32)
        self.optimizer: Any = None
        self._params: list = []

    def _on_training_start(self) -> None:
        import torch

        env = self.model.get_env()
        self.inputs, self.labels = load_pairs(self.spec, self.features,
                                              int(env.action_space.shape[0]),
                                              int(env.observation_space.shape[0]))
        policy = self.model.policy
        self._params = [*policy.mlp_extractor.policy_net.parameters(),
                        *policy.action_net.parameters()]
        self.optimizer = torch.optim.Adam(self._params, lr=self.spec.learning_rate)

    def _on_rollout_start(self) -> None:
        if self.model.num_timesteps == 0 or self.optimizer is None:
            return  # nothing to follow yet: PPO has not updated
        import torch
        from torch.nn.functional import mse_loss

        from .dagger import deterministic_action

        venv = self.model.get_vec_normalize_env()
        policy = self.model.policy
        policy.set_training_mode(True)
        losses = []
        for _ in range(self.spec.steps):
            idx = self.rng.integers(0, len(self.inputs), self.spec.batch_size)
            x = self.inputs[idx]
            if venv is not None:
                x = venv.normalize_obs(x)
            x_t = torch.as_tensor(np.asarray(x, np.float32), device=policy.device)
            y_t = torch.as_tensor(self.labels[idx], device=policy.device)
            loss = mse_loss(deterministic_action(policy, x_t), y_t)
            self.optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(self._params, self.model.max_grad_norm)
            self.optimizer.step()
            losses.append(float(loss.detach()))
        policy.set_training_mode(False)
        self.logger.record("train/bc_loss", float(np.mean(losses)))

    def _on_step(self) -> bool:
        return True
