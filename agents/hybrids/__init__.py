"""Hybrids: learned policies combined with the model-based laws, behind the safety filter.

``policies`` holds the hybrid policies (:class:`~.policies.FilteredPolicy`,
:class:`~.policies.ResidualPolicy`, :class:`~.policies.HandoverPolicy`), all filtering
through :class:`tether_gym.wrappers.FilterInTheLoop` at the observed state;
``residual_spec`` the plain-data description of a residual hybrid
(:class:`~.residual_spec.ResidualSpec`). Training a residual lives in
:mod:`tether_gym_agents.training.residual_env`, evaluating one in
:mod:`tether_gym_agents.evaluation`.
"""
