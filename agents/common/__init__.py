"""What every other subpackage of ``tether_gym_agents`` reads: the lowest layer.

The observation reader (``ObservationLayout``, by the env's declaration
:data:`tether_gym.envs.layout.OBSERVATION`), the base of the model-based laws and the one
rate-mode declaration, a learned policy's input features, ``--env-kwargs`` parsing
(literals only, never code), strict JSON and safe YAML reading, and the table of learning
algorithms (plain data).

Every module of this package, with what it holds: the diagram of docs/architecture.md
(the one list of modules).
"""
