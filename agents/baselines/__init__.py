"""The model-based baselines: the paper's laws, designed on a model, no learning.

* :mod:`.smc`: :class:`~.smc.SlidingModeController`, the paper's sliding-mode law
  (Eqs. 12-17) on a :class:`tether_gym.physics.TetherChain` model;
* :mod:`.open_loop`: the open-loop reel laws, :class:`~.open_loop.ZeroStateReel`
  (Eq. 7) and :class:`~.open_loop.PeriodicReel` (Eq. 10), and
  :class:`~.open_loop.RandomPolicy`.

They are evaluated by name through :mod:`tether_gym_agents.evaluation.registry`.
"""
