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

__all__ = ["nominal_smc", "nominal_filter", "filtered_smc", "nominal_predictive", "nominal_mpc",
           "residual", "handover"]


def nominal_smc(env, scenario: Scenario):
    """The sliding-mode law designed on ``scenario.nominal`` (None: the env's own model).

    It never reads e or the masses from the observation (a hybrid's env observes them
    when its agent does): the law runs on its design model, as ``smc`` does.
    """
    from ..baselines.smc import SlidingModeController

    nominal = None
    given = scenario.nominal or {}
    if "masses" in given or "eccentricity" in given:  # the law has no reel model
        from tether_gym.physics import TetherChain

        cfg = env.unwrapped.config
        nominal = TetherChain(given.get("masses", cfg.masses),
                              given.get("eccentricity", cfg.eccentricity),
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


def nominal_predictive(env, scenario: Scenario):
    """``predictive``: the one-step predictive law on the nominal model, behind the filter.

    :class:`~tether_gym_agents.baselines.predictive.OneStepPredictive` predicts with the
    nominal step (``scenario.nominal``, else the env's own model) and the safety filter
    predicts with the same model.
    """
    from ..baselines.predictive import OneStepPredictive
    from ..hybrids.policies import FilteredPolicy

    law = OneStepPredictive.for_env(env, scenario.nominal)
    return FilteredPolicy(law, nominal_filter(env, scenario))


def nominal_mpc(env, scenario: Scenario, seed: int | None = None):
    """``mpc``: the model-predictive controller on the nominal model, behind the filter.

    One object per episode (``seed`` is not used: the controller is deterministic, but
    it keeps its last plan as the next warm start). Needs CasADi (``pip install -e
    ".[mpc]"`` in a clone); ModuleNotFoundError with that command otherwise.
    """
    from ..baselines.mpc import ModelPredictiveController
    from ..hybrids.policies import FilteredPolicy

    law = ModelPredictiveController.for_env(env, scenario.nominal)
    return FilteredPolicy(law, nominal_filter(env, scenario))


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


def filtered(agent, env, scenario: Scenario):
    """``agent`` behind the safety filter of ``smc_filtered`` (on the scenario's nominal model).

    The agent must command reel rates (``action_mode="rate"``), the filter's action.
    """
    from ..common.obs import ObservationLayout
    from ..hybrids.policies import FilteredPolicy

    return FilteredPolicy(agent, nominal_filter(env, scenario), ObservationLayout.from_env(env))


def handover(agent, env, scenario: Scenario):
    """``agent`` handing over to SMC, filtered, both on the scenario's nominal model."""
    from ..hybrids.policies import HandoverPolicy

    return HandoverPolicy(agent, nominal_smc(env, scenario), nominal_filter(env, scenario))
