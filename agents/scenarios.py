"""Scenario suites for benchmarking policies, described as data.

A scenario is env keyword arguments plus, optionally, the nominal model that
model-based controllers design on (model mismatch). Every scenario is run with the
same fixed seeds for every policy.
"""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Scenario", "SUITES", "get_suite", "RANDOM_INIT"]

RANDOM_INIT = {"initial_theta": (0.0, 0.0), "init_theta_range": 0.15, "init_dtheta_range": 0.1}
"""theta_i(0) uniform in +-0.15 rad, theta_i'(0) within +-0.1 of the reference rate."""


@dataclass(frozen=True)
class Scenario:
    """One benchmark scenario.

    Parameters
    ----------
    name : str
        Short identifier used in tables and results.json.
    description : str
        One line for the README and the printed table.
    env_kwargs : dict
        Arguments of ``gym.make("tether_gym/TetherLibration-v0", ...)``.
    nominal : dict
        ``{"masses": ..., "eccentricity": ...}`` of the model that model-based
        controllers design on, when it differs from the env's (model mismatch).
    """

    name: str
    description: str
    env_kwargs: dict = field(default_factory=dict)
    nominal: dict | None = None


DEFAULT_SUITE = (
    Scenario("paper", "Sec. 4.3 case: theta(0) = (0.1, 0), theta'(0) = 0.2, e = 0.2"),
    Scenario("random_init", "theta_i(0) in +-0.15 rad, theta_i'(0) in 0.2 +- 0.1",
             dict(RANDOM_INIT)),
    Scenario("ecc_0.0", "random initial libration, circular orbit",
             {**RANDOM_INIT, "eccentricity": 0.0}),
    Scenario("ecc_0.1", "random initial libration, e = 0.1", {**RANDOM_INIT, "eccentricity": 0.1}),
    Scenario("ecc_0.3", "random initial libration, e = 0.3", {**RANDOM_INIT, "eccentricity": 0.3}),
    Scenario("mismatch", "true m1 +20 %, m2 -20 %, e = 0.22; SMC designs on (1, 2), e = 0.2",
             {**RANDOM_INIT, "masses": (1.2, 1.6), "eccentricity": 0.22},
             nominal={"masses": (1.0, 2.0), "eccentricity": 0.2}),
    Scenario("disturbed", "random init, |d_i| <= 0.1 on theta'' (Eq. 20), obs noise 1e-3",
             {**RANDOM_INIT, "disturbance": 0.1, "obs_noise": 1e-3}),
)

SUITES = {"default": DEFAULT_SUITE, "paper": DEFAULT_SUITE[:1]}


def get_suite(name: str) -> tuple[Scenario, ...]:
    """The named suite; ValueError listing the valid names otherwise."""
    try:
        return SUITES[name]
    except KeyError:
        raise ValueError(f"unknown suite {name!r}; valid suites: {sorted(SUITES)}") from None
