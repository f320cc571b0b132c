"""A trained policy's deterministic action as a float64 NumPy forward pass, batch-invariant.

torch's batched matrix products sum in an order that depends on the batch size, so an
episode's actions changed by about 1e-7 with the number of episodes evaluated beside it,
which a closed loop can amplify into a different episode. :class:`NumpyMLP` evaluates the
same network (the weights of the stable-baselines3 policy, cast to float64) with every
dot product summed over its own inputs only: row i of a batch is bitwise the same as row
i alone, whatever the batch size, thread count or the other rows. The actions agree
with SB3's float32 forward pass to float32 rounding (tests/agents/files/test_mlp.py).

Each dot product is summed in the order of NumPy's pairwise summation along a
contiguous last axis, which defined the shipped results (``(h[:, None, :] *
W).sum(-1)``, their first implementation): blocks of at most 128 terms are summed in
eight interleaved partial sums combined as ((r0 + r1) + (r2 + r3)) + ((r4 + r5) +
(r6 + r7)) plus the remainder in order, longer runs are split at half (rounded down
to a multiple of 8) and the halves' sums added, and the reduction starts from 0.
:func:`_linear` does exactly this in compiled loops that vectorise over the outputs
(bitwise equal to the NumPy expression, tests/agents/files/test_mlp.py) and
needs no (batch, out, in) temporary: 3-12 times faster for 256-wide layers at batches of
1-70 (bench/README.md). The split is a plan computed in Python (:func:`_plan`), so that the
compiled functions do not recurse and numba can cache them (``cache=True``, beside this
file or in numba's user cache: about 2-3 s to compile once, 0.4 s to load).

Supported: PPO/A2C ``ActorCriticPolicy`` without gSDE, SAC/TQC actors (a body and a
``mu`` head) and TD3's deterministic actor (``mu`` ending in tanh), on flattened Box
observations, with Linear layers and Tanh/ReLU activations.
:meth:`NumpyMLP.from_policy` returns None for anything else (the caller keeps torch).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit

__all__ = ["NumpyMLP", "pairwise_linear"]

_BLOCK = 128
"""NumPy's ``PW_BLOCKSIZE``: the longest run summed without a split."""


@njit(cache=True)
def _leaf(h, wt, lo, n, res):  # pragma: no cover - compiled (tested against NumPy)
    """res[b, o] = sum_{k < n} h[b, lo + k] wt[lo + k, o], n <= 128, in NumPy's order."""
    batch, n_out = h.shape[0], wt.shape[1]
    if n < 8:
        for b in range(batch):
            for o in range(n_out):
                res[b, o] = -0.0
            for i in range(lo, lo + n):
                x = h[b, i]
                for o in range(n_out):
                    res[b, o] += x * wt[i, o]
        return
    acc = np.empty((8, n_out))
    m = n - n % 8
    for b in range(batch):
        for k in range(8):
            x = h[b, lo + k]
            for o in range(n_out):
                acc[k, o] = x * wt[lo + k, o]
        for i in range(lo + 8, lo + m, 8):
            for k in range(8):
                x = h[b, i + k]
                for o in range(n_out):
                    acc[k, o] += x * wt[i + k, o]
        for o in range(n_out):
            res[b, o] = (((acc[0, o] + acc[1, o]) + (acc[2, o] + acc[3, o]))
                         + ((acc[4, o] + acc[5, o]) + (acc[6, o] + acc[7, o])))
        for i in range(lo + m, lo + n):
            x = h[b, i]
            for o in range(n_out):
                res[b, o] += x * wt[i, o]


@njit(cache=True)
def _linear_plan(h, wt, leaf_lo, leaf_n, program):  # pragma: no cover - compiled
    """(B, out) dot products of h (B, in) with the columns of wt (in, out) (:func:`_plan`)."""
    batch, n_out = h.shape[0], wt.shape[1]
    stack = np.empty((len(leaf_lo), batch, n_out))
    top = 0
    for code in program:
        if code >= 0:  # a leaf's sum onto the stack
            _leaf(h, wt, leaf_lo[code], leaf_n[code], stack[top])
            top += 1
        else:  # the two partial sums on top: left + right
            top -= 1
            for b in range(batch):
                for o in range(n_out):
                    stack[top - 1, b, o] = stack[top - 1, b, o] + stack[top, b, o]
    out = np.empty((batch, n_out))
    for b in range(batch):
        for o in range(n_out):
            out[b, o] = 0.0 + stack[0, b, o]
    return out


@functools.cache
def _plan(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """NumPy's pairwise split of n terms: leaves (start, length) and the order of the adds.

    Runs longer than 128 split at half rounded down to a multiple of 8, recursively;
    ``program`` lists leaf k (k >= 0, left to right) and -1 for "add the last two
    partial sums" in the order NumPy's recursion adds them.
    """
    lo: list[int] = []
    size: list[int] = []
    program: list[int] = []

    def split(start: int, count: int) -> None:
        if count <= _BLOCK:
            program.append(len(lo))
            lo.append(start)
            size.append(count)
            return
        half = count // 2
        half -= half % 8
        split(start, half)
        split(start + half, count - half)
        program.append(-1)

    split(0, n)
    return (np.asarray(lo, dtype=np.int64), np.asarray(size, dtype=np.int64),
            np.asarray(program, dtype=np.int64))


def _linear(h: np.ndarray, wt: np.ndarray) -> np.ndarray:
    """(B, out) for contiguous float64 h (B, in) and wt (in, out), NumPy's pairwise order."""
    return _linear_plan(h, wt, *_plan(h.shape[1]))


def pairwise_linear(h: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """``(h[:, None, :] * weight[None]).sum(-1)``, bitwise, without the temporary.

    Parameters
    ----------
    h : ndarray, shape (B, in)
        Inputs (cast to contiguous float64).
    weight : ndarray, shape (out, in)
        A linear layer's weight (cast to float64).

    Returns
    -------
    ndarray, shape (B, out)
        float64 dot products, each summed in NumPy's pairwise order (module docstring).
    """
    h = np.ascontiguousarray(h, dtype=np.float64)
    wt = np.ascontiguousarray(np.asarray(weight, dtype=np.float64).T)
    if h.ndim != 2 or wt.ndim != 2 or h.shape[1] != wt.shape[0] or h.shape[1] == 0:
        raise ValueError(f"pairwise_linear: inputs {h.shape} and weight "
                         f"{np.shape(weight)} do not make (B, in) x (out, in) with in >= 1")
    return _linear(h, wt)

_ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "Tanh": np.tanh, "ReLU": lambda x: np.maximum(x, 0.0)}


@dataclass(frozen=True)
class _Layer:
    weight: np.ndarray   # (out, in) float64
    bias: np.ndarray     # (out,) float64
    activation: str | None
    weight_t: np.ndarray = field(init=False, repr=False, compare=False)  # (in, out) contiguous

    def __post_init__(self):
        object.__setattr__(self, "weight_t", np.ascontiguousarray(self.weight.T))


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
        h = np.ascontiguousarray(obs, dtype=np.float64)
        for layer in self.layers:
            h = _linear(h, layer.weight_t) + layer.bias
            if layer.activation is not None:
                h = _ACTIVATIONS[layer.activation](h)
        if self.squash:
            h = self.low + 0.5 * (np.tanh(h) + 1.0) * (self.high - self.low)
        else:
            h = np.clip(h, self.low, self.high)
        return h.astype(np.float32)
