"""The model-based baselines: the paper's laws, designed on a model, no learning.

* :mod:`.smc`: :class:`~.smc.SlidingModeController`, the paper's sliding-mode law
  (Eqs. 12-17) on a :class:`tether_gym.physics.TetherChain` model;
* :mod:`.open_loop`: the open-loop reel laws, :class:`~.open_loop.ZeroStateReel`
  (Eq. 7) and :class:`~.open_loop.PeriodicReel` (Eq. 10), and
  :class:`~.open_loop.RandomPolicy`;
* :mod:`.predictive`: :class:`~.predictive.OneStepPredictive`, the held command whose
  nominal step makes the sliding variable decay by a set factor (``predictive``);
* :mod:`.mpc`: :class:`~.mpc.ModelPredictiveController`, nonlinear MPC with hard
  constraints over its horizon (``mpc``; CasADi, ``pip install -e ".[mpc]"``), on
  the symbolic model of :mod:`.mpc_model` (tested equal to the physics); both share
  :mod:`.prediction` (the nominal step, the reference ahead).

They are evaluated by name through :mod:`tether_gym_agents.evaluation.registry`.
"""
