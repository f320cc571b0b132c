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
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from numba import njit

from ..params import check_range

__all__ = ["RewardWeights", "reward_terms", "COMPONENTS"]

COMPONENTS = ("reward_tracking", "reward_effort", "reward_accel", "reward_slack",
              "reward_length")
"""Names of the reward components reported in ``info`` (penalties are <= 0)."""


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the reward terms.

    Parameters
    ----------
    sigma : float
        Tracking scale [rad], > 0: an RMS error of sigma halves r_track.
    rate_weight : float
        Weight of the rate error e' in the tracking cost [rad^2/(rad/rad)^2], >= 0.
    effort : float
        Weight of mean(a^2), >= 0.
    accel : float
        Weight of the reel-acceleration penalty, >= 0.
    slack : float
        Weight of the closeness-to-slack penalty, >= 0.
    safe_tension : float
        T_safe [-], > 0: tensions above it are not penalised.
    length : float
        Weight of the length-deviation penalty, >= 0.
    length_scale : float
        Deviation |l_i - l_i,nom| [-], > 0, at which the length penalty saturates.
    """

    sigma: float = 0.05
    rate_weight: float = 0.1
    effort: float = 0.05
    accel: float = 0.05
    slack: float = 0.2
    safe_tension: float = 0.5
    length: float = 0.2
    length_scale: float = 0.5

    def __post_init__(self) -> None:
        check_range("sigma", self.sigma, 0.0, low_open=True)
        check_range("safe_tension", self.safe_tension, 0.0, low_open=True)
        check_range("length_scale", self.length_scale, 0.0, low_open=True)
        for name in ("rate_weight", "effort", "accel", "slack", "length"):
            check_range(name, getattr(self, name), 0.0, 1.0)
        total = self.effort + self.accel + self.slack + self.length
        if total > 1.0:
            raise ValueError(f"effort + accel + slack + length = {total!r} must be <= 1 so "
                             "that the reward stays in [0, 1]")

    @classmethod
    def from_dict(cls, values: dict | None) -> RewardWeights:
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

    def as_tuple(self) -> tuple[float, ...]:
        return (self.sigma, self.rate_weight, self.effort, self.accel, self.slack,
                self.safe_tension, self.length, self.length_scale)


@njit(cache=True, inline="always", error_model="numpy")
def reward_terms(theta, dtheta, length, theta_ref, dtheta_ref, action, accel_ratio,
                 tension_min, length_nominal, weights, out):
    """Fill ``out[0:5]`` with the components of :data:`COMPONENTS`; return their sum.

    ``weights`` is :meth:`RewardWeights.as_tuple`; ``accel_ratio`` the reels'
    L_ddot / a_ref.
    """
    sigma, rate_weight, w_effort, w_accel, w_slack, safe, w_length, length_scale = weights
    n = theta.shape[0]
    err = 0.0
    rate = 0.0
    effort = 0.0
    acc = 0.0
    slack = 0.0
    drift = 0.0
    for j in range(n):
        e = theta[j] - theta_ref
        de = dtheta[j] - dtheta_ref
        err += e * e
        rate += de * de
        effort += action[j] * action[j]
        acc += min(1.0, accel_ratio[j] * accel_ratio[j])
        margin = min(max(1.0 - tension_min[j] / safe, 0.0), 1.0)
        slack += margin * margin
        dev = (length[j] - length_nominal[j]) / length_scale
        drift += min(1.0, dev * dev)
    cost = (err + rate_weight * rate) / n
    track = 1.0 / (1.0 + cost / (sigma * sigma))
    out[0] = track
    out[1] = -track * w_effort * effort / n
    out[2] = -track * w_accel * acc / n
    out[3] = -track * w_slack * slack / n
    out[4] = -track * w_length * drift / n
    return out[0] + out[1] + out[2] + out[3] + out[4]
