"""Reward of the libration-tracking task (pure function).

Per control step, with e_i = theta_i - theta_d and e_i' = theta_i' - theta_d':

    r = r_track * (1 - p),
    r_track = 1 / (1 + c / sigma^2),   c = mean(e_i^2) + rate_weight * mean(e_i'^2),
    p = w_effort mean(a_i^2) + w_accel mean(min(1, (acc_i / acc_ref)^2))
        + w_slack mean(clip(1 - T^_i,min / T_safe, 0, 1)^2)
        + w_length mean(min(1, ((l_i - l_i,nom) / length_scale)^2)),

where a in [-1, 1]^(N-1) is the action (normalised reel-rate command), acc_i the
reel's physical acceleration at the end of the step over the acceleration limit (or
0.01 m/s^2 without one), T^_i,min the smallest tension of tether i during the step
and l_i,nom the tether's configured initial length. r_track lies in (0, 1] and decays
slowly (like 1/c) so that a policy far from the reference still gains by staying
alive; the weights sum to at most 1, so p lies in [0, 1] and r in [0, 1]: ending an
episode early never pays. The length term keeps the reels near their nominal
deployment: without it, reeling out (tension grows with length) is a cheap way to
avoid the slack penalty, and trained agents drifted to the length bound. (A smooth
x^2 / (1 + x^2), x = deviation / 0.25, weight 0.3, was tried as well: the PPO agent
trained on it survived 73 % of the default suite instead of 100 %, with the same
length excursion, so the saturating form stays.)
The components reported in ``info`` add up to r: ``reward_tracking`` = r_track and
the penalties ``reward_effort`` = -r_track w_effort mean(a^2) etc. (each <= 0).

Adding a penalty term: a field of :class:`RewardWeights` with ``penalty=True`` in its
metadata (its weight; the component ``reward_<name>`` and the info entry follow from
it), and the line of :func:`penalty_terms` that accumulates its per-tether value.
"""

from __future__ import annotations

from collections import namedtuple
from dataclasses import asdict, dataclass, field, fields
from typing import NamedTuple

from numba import njit

from ..params import check_range
from ..physics.jit import INLINE
from ..physics.layout import at
from ..physics.state import S

__all__ = ["RewardWeights", "RewardParams", "reward_terms", "penalty_terms", "COMPONENTS",
           "PENALTIES"]


def _penalty(default: float):
    return field(default=default, metadata={"penalty": True})


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the reward terms (the declaration of the reward's components).

    Parameters
    ----------
    sigma : float
        Tracking scale [rad], > 0: an RMS error of sigma halves r_track.
    rate_weight : float
        Weight of the rate error e' in the tracking cost [rad^2/(rad/rad)^2], >= 0.
    effort : float
        Weight of mean(a^2), >= 0 (penalty).
    accel : float
        Weight of the reel-acceleration penalty, >= 0 (penalty).
    slack : float
        Weight of the closeness-to-slack penalty, >= 0 (penalty).
    length : float
        Weight of the length-deviation penalty, >= 0 (penalty).
    safe_tension : float
        T_safe [-], > 0: tensions above it are not penalised.
    length_scale : float
        Deviation |l_i - l_i,nom| [-], > 0, at which the length penalty saturates.
    """

    sigma: float = 0.05
    rate_weight: float = 0.1
    effort: float = _penalty(0.05)
    accel: float = _penalty(0.05)
    slack: float = _penalty(0.2)
    length: float = _penalty(0.2)
    safe_tension: float = 0.5
    length_scale: float = 0.5

    def __post_init__(self) -> None:
        check_range("sigma", self.sigma, 0.0, low_open=True)
        check_range("safe_tension", self.safe_tension, 0.0, low_open=True)
        check_range("length_scale", self.length_scale, 0.0, low_open=True)
        check_range("rate_weight", self.rate_weight, 0.0, 1.0)
        for name in PENALTIES:
            check_range(name, getattr(self, name), 0.0, 1.0)
        total = sum(getattr(self, name) for name in PENALTIES)
        if total > 1.0:
            raise ValueError(f"{' + '.join(PENALTIES)} = {total!r} must be <= 1 so that the "
                             "reward stays in [0, 1]")

    @classmethod
    def from_dict(cls, values: dict | RewardWeights | None) -> RewardWeights:
        """Build from a dict, rejecting unknown keys with the list of valid ones."""
        if values is None:
            return cls()
        if isinstance(values, RewardWeights):
            return values
        if not isinstance(values, dict):
            raise TypeError(f"reward_weights must be a dict, got {type(values).__name__}")
        valid = set(asdict(cls()))
        unknown = sorted(set(values) - valid)
        if unknown:
            raise ValueError(f"unknown reward_weights keys {unknown}; valid keys: {sorted(valid)}")
        return cls(**values)

    def record(self) -> RewardParams:
        """The weights as the kernels take them."""
        return RewardParams(self.sigma, self.rate_weight, self.safe_tension, self.length_scale,
                            tuple(float(getattr(self, name)) for name in PENALTIES))


PENALTIES = tuple(f.name for f in fields(RewardWeights) if f.metadata.get("penalty"))
"""Penalty terms in the order of their components (after ``reward_tracking``)."""
COMPONENTS = ("reward_tracking",) + tuple(f"reward_{name}" for name in PENALTIES)
"""Names of the reward components reported in ``info`` (penalties are <= 0)."""
PEN = namedtuple("PenaltyIndex", PENALTIES)(*range(len(PENALTIES)))
"""Index of each penalty in the kernels' per-term arrays."""


class RewardParams(NamedTuple):
    """:class:`RewardWeights` as a compiled-code record (penalty weights in PENALTIES order)."""

    sigma: float
    rate_weight: float
    safe_tension: float
    length_scale: float
    penalty: tuple


@njit(**INLINE)
def penalty_terms(y, n, action, accel_ratio, tension_min, length_nominal, params, raw):
    """Accumulate each penalty's per-tether sum into ``raw[PEN.<name>]`` (zeroed here).

    ``accel_ratio`` holds the reels' L_ddot / a_ref at the end of the step.
    """
    for i in range(raw.shape[0]):
        raw[i] = 0.0
    ln = at(S.length, n)
    for j in range(n):
        raw[PEN.effort] += action[j] * action[j]
        raw[PEN.accel] += min(1.0, accel_ratio[j] * accel_ratio[j])
        margin = min(max(1.0 - tension_min[j] / params.safe_tension, 0.0), 1.0)
        raw[PEN.slack] += margin * margin
        dev = (y[ln + j] - length_nominal[j]) / params.length_scale
        raw[PEN.length] += min(1.0, dev * dev)


@njit(**INLINE)
def reward_terms(y, n, theta_ref, dtheta_ref, params, raw, out):
    """Fill ``out`` with the components of :data:`COMPONENTS`; return their sum.

    ``y`` is the state row after the step, ``raw`` the per-term sums of
    :func:`penalty_terms`.
    """
    th = at(S.theta, n)
    dth = at(S.dtheta, n)
    err = 0.0
    rate = 0.0
    for j in range(n):
        e = y[th + j] - theta_ref
        de = y[dth + j] - dtheta_ref
        err += e * e
        rate += de * de
    cost = (err + params.rate_weight * rate) / n
    track = 1.0 / (1.0 + cost / (params.sigma * params.sigma))
    out[0] = track
    total = out[0]
    for i in range(raw.shape[0]):
        out[1 + i] = -track * params.penalty[i] * raw[i] / n
        total += out[1 + i]
    return total
