"""Reward of the libration-tracking task, v1 (pure function).

Per control step, with e_i = theta_i - theta_d, e_i' = theta_i' - theta_d' and the
tracking cost c = mean(e_i^2) + rate_weight * mean(e_i'^2) [rad^2]:

    r = (1 - W) r_track (1 - p) + sum_k w_k (1 - q_k),     W = sum_k w_k,

    r_track = (1 - log_share) / (1 + c / sigma^2)
              + log_share * clip(ln(max(sqrt(c), floor)) / ln(floor), 0, 1),
    p   = w_effort mean(u_i^2) + w_accel mean(min(1, (acc_i / acc_ref)^2)),
    q_slack  = mean(clip(1 - T^_i,min / T_safe, 0, 1)^2),
    q_length = mean(min(1, h(ln(l_i / l_i,nom)) / h(ln 10))),  h(x) = sqrt(1 + (x/delta)^2) - 1,

where u in [-1, 1]^(N-1) is the normalised reel-rate command (the action in
``action_mode="rate"``, the integrated increments otherwise), acc_i the reel's
physical acceleration at the end of the step over the acceleration limit (or 0.01
m/s^2 without one), T^_i,min the smallest tension of tether i during the step and
l_i,nom the tether's configured initial length. Every part lies in [0, 1] and the
weights sum to at most 1, so r lies in [0, 1]: ending an episode early never pays.

Why this form (ablation over training seeds in docs/task_design.md):

* r_track has two parts. The Lorentzian (scale sigma) is steep between 1e-1 and
  1e-2 rad and pays a policy far from the reference for staying alive; the
  logarithmic part pays the same for every decade of precision from 1 rad down to
  ``log_floor`` (1e-4 rad), where the Lorentzian alone stops paying (from 1e-2 to
  1e-3 rad it is worth 2 % of a step's reward).
* The slack and length terms (``margin`` terms) are *added*, not multiplied by
  r_track, so their gradient does not collapse while the tracking is poor, nor
  vanish when it is good. The length term is a pseudo-Huber function of ln(l/l_nom):
  it has a gradient everywhere inside the length bounds (v0's saturating square had
  none beyond a deviation of 0.5) and reaches 1 at a factor of 10 from nominal.
* The effort and acceleration terms (``penalty`` terms) stay multiplied by r_track,
  as in v0. The acceleration term's default weight is 0: every design of the
  ablation ran with it about 80 times weaker than v0's (a unit slip in the
  exploratory wrapper divided the reel acceleration in m/s^2 by the dimensionless
  limit), so none of the evidence is for a policy trained with it; with increments
  the command cannot jump from step to step, which is what v0's term was for. It
  stays declared, so ``reward_weights={"accel": 0.05}`` restores it.

The components reported in ``info`` add up to r: ``reward_tracking`` = (1 - W)
r_track, the penalties ``reward_effort`` = -(1 - W) r_track w_effort mean(u^2) and
``reward_accel`` (each <= 0), and the margin terms ``reward_slack`` = w_slack (1 -
q_slack) and ``reward_length`` (each in [0, w_k]).

Adding a term: a field of :class:`RewardWeights` declared with :func:`_penalty` or
:func:`_margin` (its weight; the component ``reward_<name>`` and the info entry
follow from it), and the line of :func:`term_sums` that accumulates its per-tether
value q_k (in [0, 1] per tether).
"""

from __future__ import annotations

import math
from collections import namedtuple
from dataclasses import dataclass, field, fields
from typing import NamedTuple

from numba import njit

from ..params import check_range, weights_from_dict
from ..physics.jit import INLINE
from ..physics.layout import at
from ..physics.state import S

__all__ = ["RewardWeights", "RewardParams", "reward_terms", "term_sums", "COMPONENTS",
           "TERMS", "PENALTIES", "MARGINS"]

LENGTH_SATURATION = math.log(10.0)
"""|ln(l / l_nom)| [-] at which the length term reaches 1 (a factor of 10)."""


def _penalty(default: float):
    """A term multiplied by r_track: its weight w_k scales -r_track q_k."""
    return field(default=default, metadata={"term": "penalty"})


def _margin(default: float):
    """A term added to the reward: it pays w_k (1 - q_k)."""
    return field(default=default, metadata={"term": "margin"})


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the reward terms (the declaration of the reward's components).

    Parameters
    ----------
    sigma : float
        Scale of the Lorentzian tracking part [rad], > 0: an RMS error of sigma
        halves it.
    log_share : float
        Share of the logarithmic tracking part in r_track [-], in [0, 1].
    log_floor : float
        RMS error [rad] at which the logarithmic part reaches 1, in (0, 1).
    rate_weight : float
        Weight of the rate error e' in the tracking cost [rad^2/(rad/rad)^2], in [0, 1].
    effort : float
        Weight of mean(u^2), >= 0 (penalty).
    accel : float
        Weight of the reel-acceleration penalty, >= 0 (penalty).
    slack : float
        Weight of the tension-margin term, >= 0 (margin).
    length : float
        Weight of the length term, >= 0 (margin).
    safe_tension : float
        T_safe [-], > 0: tensions above it cost nothing.
    length_delta : float
        Width delta [-] of the length term's pseudo-Huber function of ln(l / l_nom), > 0.
    """

    sigma: float = 0.05
    log_share: float = 0.5
    log_floor: float = 1.0e-4
    rate_weight: float = 0.1
    effort: float = _penalty(0.05)
    accel: float = _penalty(0.0)
    slack: float = _margin(0.2)
    length: float = _margin(0.2)
    safe_tension: float = 0.5
    length_delta: float = 0.2

    def __post_init__(self) -> None:
        check_range("sigma", self.sigma, 0.0, low_open=True)
        check_range("log_share", self.log_share, 0.0, 1.0)
        check_range("log_floor", self.log_floor, 0.0, 1.0, low_open=True, high_open=True)
        check_range("safe_tension", self.safe_tension, 0.0, low_open=True)
        check_range("length_delta", self.length_delta, 0.0, low_open=True)
        check_range("rate_weight", self.rate_weight, 0.0, 1.0)
        for name in TERMS:
            check_range(name, getattr(self, name), 0.0, 1.0)
        for kind, names in (("penalty", PENALTIES), ("margin", MARGINS)):
            total = sum(getattr(self, name) for name in names)
            if total > 1.0:
                raise ValueError(f"{' + '.join(names)} = {total!r} (the {kind} weights) must be "
                                 "<= 1 so that the reward stays in [0, 1]")

    @classmethod
    def from_dict(cls, values: dict | RewardWeights | None) -> RewardWeights:
        """Build from a dict, rejecting unknown keys with the list of valid ones."""
        return weights_from_dict(cls, values, "reward_weights", "weights")

    def record(self) -> RewardParams:
        """The weights as the kernels take them."""
        margin_total = sum(getattr(self, name) for name in MARGINS)
        return RewardParams(
            sigma=self.sigma, log_share=self.log_share, log_floor_ln=math.log(self.log_floor),
            rate_weight=self.rate_weight, safe_tension=self.safe_tension,
            length_delta=self.length_delta,
            length_norm=math.sqrt(1.0 + (LENGTH_SATURATION / self.length_delta) ** 2) - 1.0,
            track_weight=1.0 - margin_total,
            weight=tuple(float(getattr(self, name)) for name in TERMS),
            margin=tuple(name in MARGINS for name in TERMS))


TERMS = tuple(f.name for f in fields(RewardWeights) if "term" in f.metadata)
"""Weighted terms in the order of their components (after ``reward_tracking``)."""
PENALTIES = tuple(f.name for f in fields(RewardWeights) if f.metadata.get("term") == "penalty")
"""Terms multiplied by r_track."""
MARGINS = tuple(f.name for f in fields(RewardWeights) if f.metadata.get("term") == "margin")
"""Terms added to the reward."""
COMPONENTS = ("reward_tracking",) + tuple(f"reward_{name}" for name in TERMS)
"""Names of the reward components reported in ``info`` (they add up to the reward)."""
TERM = namedtuple("TermIndex", TERMS)(*range(len(TERMS)))
"""Index of each term in the kernels' per-term arrays."""


class RewardParams(NamedTuple):
    """:class:`RewardWeights` as a compiled-code record (term weights in TERMS order)."""

    sigma: float
    log_share: float
    log_floor_ln: float    # ln(log_floor)
    rate_weight: float
    safe_tension: float
    length_delta: float
    length_norm: float     # h(ln 10) of the length term
    track_weight: float    # 1 - W, W the sum of the margin weights
    weight: tuple
    margin: tuple          # per term: True for a margin term, False for a penalty


@njit(**INLINE)
def term_sums(y, n, command, accel_ratio, tension_min, length_nominal, params, raw):
    """Accumulate each term's per-tether q into ``raw[TERM.<name>]`` (zeroed here).

    ``command`` holds the normalised reel-rate commands u of the step and
    ``accel_ratio`` the reels' L_ddot / a_ref at its end.
    """
    for i in range(raw.shape[0]):
        raw[i] = 0.0
    ln = at(S.length, n)
    for j in range(n):
        raw[TERM.effort] += command[j] * command[j]
        raw[TERM.accel] += min(1.0, accel_ratio[j] * accel_ratio[j])
        margin = min(max(1.0 - tension_min[j] / params.safe_tension, 0.0), 1.0)
        raw[TERM.slack] += margin * margin
        x = math.log(max(y[ln + j], 1e-300) / length_nominal[j]) / params.length_delta
        raw[TERM.length] += min(1.0, (math.sqrt(1.0 + x * x) - 1.0) / params.length_norm)


@njit(**INLINE)
def tracking(cost, params):
    """r_track [-] in [0, 1] of the tracking cost c [rad^2] (module docstring)."""
    lorentz = 1.0 / (1.0 + cost / (params.sigma * params.sigma))
    rms = math.sqrt(cost)
    if rms <= 1.0:
        log_part = min(1.0, math.log(max(rms, 1e-300)) / params.log_floor_ln)
    else:
        log_part = 0.0
    return (1.0 - params.log_share) * lorentz + params.log_share * log_part


@njit(**INLINE)
def reward_terms(y, n, theta_ref, dtheta_ref, params, raw, out):
    """Fill ``out`` with the components of :data:`COMPONENTS`; return their sum.

    ``y`` is the state row after the step, ``raw`` the per-term sums of
    :func:`term_sums`.
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
    track = params.track_weight * tracking((err + params.rate_weight * rate) / n, params)
    out[0] = track
    total = track
    for i in range(raw.shape[0]):
        if params.margin[i]:
            out[1 + i] = params.weight[i] * (1.0 - raw[i] / n)
        else:
            out[1 + i] = -track * params.weight[i] * raw[i] / n
        total += out[1 + i]
    return total
