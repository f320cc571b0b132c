"""The benchmark: which policy a name means, how episodes run, and what is reported.

The policy registry (built-in baselines, policies added with
:func:`tether_gym_agents.register_policy` or by plugin packages, shipped agents, run
folders, hybrids), the scenario suites, the one rollout loop on the native vector env
(also the paper's), per-episode metrics and the statistics over training runs,
:func:`tether_gym_agents.evaluate`, ``results.json``, tables and figures, and learning
curves of seed runs' checkpoints.

Every module of this package, with what it holds: the diagram of docs/architecture.md
(the one list of modules). The command line (``evaluate.py``) is
:mod:`tether_gym_agents.cli.evaluate`.
"""
