"""Model-based policies built on a scenario's nominal model.

The sliding-mode law, the safety filter, and the hybrids that combine them with a
trained agent. Under model mismatch a scenario names the model that model-based
controllers design on (``Scenario.nominal``); every builder here uses it, so that
``smc``, ``smc_filtered``, a residual hybrid and ``handover:AGENT`` all see the same
model on a given scenario. Each builder takes ``(env, scenario)`` (plus the trained
agent of a hybrid) and returns an object with stable-baselines3's ``predict``.
"""

from __future__ import annotations

from .scenarios import Scenario

__all__ = ["nominal_smc", "nominal_filter", "filtered_smc", "residual", "handover"]


def nominal_smc(env, scenario: Scenario):
    """The sliding-mode law designed on ``scenario.nominal`` (None: the env's own model).

    It never reads e or the masses from the observation (a hybrid's env observes them
    when its agent does): the law runs on its design model, as ``smc`` does.
    """
    from ..baselines.smc import SlidingModeController

    nominal = None
    if scenario.nominal is not None:
        from tether_gym.physics import TetherChain

        cfg = env.unwrapped.config
        nominal = TetherChain(scenario.nominal["masses"], scenario.nominal["eccentricity"],
                              cfg.gravity, cfg.scales.length_ratio)
    return SlidingModeController.for_env(env, nominal=nominal, use_observed_params=False)


def nominal_filter(env, scenario: Scenario):
    """The safety filter predicting with ``scenario.nominal`` (None: the env's own model)."""
    from tether_gym.safety import SafetyFilter

    return SafetyFilter.for_env(env, **(scenario.nominal or {}))


def filtered_smc(env, scenario: Scenario):
    """``smc_filtered``: the nominal sliding-mode law behind the nominal safety filter."""
    from ..hybrids.policies import FilteredPolicy

    return FilteredPolicy(nominal_smc(env, scenario), nominal_filter(env, scenario))


def residual(agent, env, scenario: Scenario):
    """The hybrid of a residual ``agent``: SMC + scale * agent, filtered if trained so.

    The sliding-mode law and the filter use the scenario's nominal model, as ``smc`` and
    ``smc_filtered`` do.
    """
    from ..hybrids.policies import ResidualPolicy

    spec = agent.hybrid
    if spec is None:
        raise ValueError(f"{agent!r} records no hybrid: it is not the residual of one")
    flt = nominal_filter(env, scenario) if spec["filter"] else None
    return ResidualPolicy(nominal_smc(env, scenario), agent, spec["scale"], flt)


def handover(agent, env, scenario: Scenario):
    """``agent`` handing over to SMC, filtered, both on the scenario's nominal model."""
    from ..hybrids.policies import HandoverPolicy

    return HandoverPolicy(agent, nominal_smc(env, scenario), nominal_filter(env, scenario))
