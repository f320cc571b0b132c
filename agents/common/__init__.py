"""What every other subpackage of ``tether_gym_agents`` reads: the lowest layer.

* :mod:`.obs`: :class:`~.obs.ObservationLayout` (reads an observation by the env's
  declaration :data:`tether_gym.envs.layout.OBSERVATION`), :class:`~.obs.ReelRatePolicy`
  (the base of the model-based laws) and the one rate-mode declaration
  (:data:`~.obs.RATE_ENV_KWARGS`, :func:`~.obs.with_rate_mode`);
* :mod:`.features`: a learned policy's input features computed from the observation;
* :mod:`.env_kwargs`: ``--env-kwargs KEY=VALUE`` parsing (literals only, never code);
* :mod:`.jsonio`: strict JSON conversion, checked mappings, file hashes.
"""
