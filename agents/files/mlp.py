"""A trained policy's deterministic action as a float64 NumPy forward pass, batch-invariant.

torch's batched matrix products sum in an order that depends on the batch size, so an
episode's actions changed by about 1e-7 with the number of episodes evaluated beside it,
which a closed loop can amplify into a different episode. :class:`NumpyMLP` evaluates the
same network (the weights of the stable-baselines3 policy, cast to float64) with every
dot product summed over its own inputs only (``(h[:, None, :] * W).sum(-1)``, NumPy's
pairwise sum along the last axis): row i of a batch is bitwise the same as row i alone,
whatever the batch size, thread count or the other rows. The actions agree with SB3's
float32 forward pass to float32 rounding (tests/agents/test_mlp.py).

Supported: PPO/A2C ``ActorCriticPolicy`` without gSDE, SAC/TQC actors (a body and a
``mu`` head) and TD3's deterministic actor (``mu`` ending in tanh), on flattened Box
observations, with Linear layers and Tanh/ReLU activations.
:meth:`NumpyMLP.from_policy` returns None for anything else (the caller keeps torch).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

__all__ = ["NumpyMLP"]

_ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "Tanh": np.tanh, "ReLU": lambda x: np.maximum(x, 0.0)}


@dataclass(frozen=True)
class _Layer:
    weight: np.ndarray   # (out, in) float64
    bias: np.ndarray     # (out,) float64
    activation: str | None


def _layers(modules) -> list[_Layer] | None:
    """Linear layers with the activation that follows each; None if unsupported."""
    layers: list[_Layer] = []
    for module in modules:
        kind = type(module).__name__
        if kind == "Linear":
            bias = (module.bias.detach().cpu().numpy() if module.bias is not None
                    else np.zeros(module.out_features))
            layers.append(_Layer(module.weight.detach().cpu().numpy().astype(np.float64),
                                 bias.astype(np.float64), None))
        elif kind in _ACTIVATIONS and layers and layers[-1].activation is None:
            last = layers[-1]
            layers[-1] = _Layer(last.weight, last.bias, kind)
        elif kind in ("Identity", "Flatten"):
            continue
        else:
            return None
    return layers


@dataclass(frozen=True)
class NumpyMLP:
    """The deterministic action of an MLP policy (see the module docstring).

    ``squash``: the network's output passes through tanh and is rescaled from [-1, 1]
    to the action box (SAC, TQC, TD3); otherwise it is clipped to the box (PPO).
    """

    layers: tuple[_Layer, ...]
    squash: bool
    low: np.ndarray
    high: np.ndarray

    @classmethod
    def from_policy(cls, policy) -> NumpyMLP | None:
        """Build from a stable-baselines3 policy; None when it is not a supported MLP."""
        owner = policy.actor if hasattr(policy, "actor") else policy
        extractor = getattr(owner, "features_extractor", None)
        if extractor is None or type(extractor).__name__ != "FlattenExtractor":
            return None
        space = policy.action_space
        if getattr(policy, "use_sde", False):
            return None
        if hasattr(policy, "mlp_extractor") and hasattr(policy, "action_net"):
            if type(getattr(policy, "pi_features_extractor", extractor)).__name__ \
                    != "FlattenExtractor":
                return None
            body = _layers(policy.mlp_extractor.policy_net)
            head = _layers([policy.action_net])
            squash = bool(policy.squash_output)
        elif hasattr(policy, "actor") and hasattr(policy.actor, "latent_pi"):
            actor = policy.actor  # SAC, TQC: a body and a mean head, squashed by tanh
            body = _layers(actor.latent_pi)
            head = _layers(actor.mu if hasattr(actor.mu, "__iter__") else [actor.mu])
            squash = True
        elif hasattr(policy, "actor") and hasattr(policy.actor, "mu"):
            # TD3: mu is the whole network and ends in the tanh that squashes the action
            layers = _layers(policy.actor.mu)
            if not layers or layers[-1].activation != "Tanh":
                return None
            body, head = layers[:-1], [replace(layers[-1], activation=None)]
            squash = True
        else:
            return None
        if body is None or head is None:
            return None
        return cls(tuple(body + head), squash, np.asarray(space.low, dtype=np.float64),
                   np.asarray(space.high, dtype=np.float64))

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Actions (B, act_dim) float32 for normalised observations (B, obs_dim)."""
        h = np.asarray(obs, dtype=np.float64)
        for layer in self.layers:
            h = (h[:, None, :] * layer.weight[None, :, :]).sum(axis=-1) + layer.bias
            if layer.activation is not None:
                h = _ACTIVATIONS[layer.activation](h)
        if self.squash:
            h = self.low + 0.5 * (np.tanh(h) + 1.0) * (self.high - self.low)
        else:
            h = np.clip(h, self.low, self.high)
        return h.astype(np.float32)
