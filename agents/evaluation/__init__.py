"""The benchmark: which policy a name means, how episodes run, and what is reported.

Modules by job:

* :mod:`.registry`: the one policy registry (built-in baselines, policies added with
  :func:`~.registry.register_policy` or by plugin packages, shipped agents, run folders,
  hybrids); :mod:`.nominal` builds the model-based laws and hybrids on a scenario's
  nominal model.
* :mod:`.scenarios`: the scenario suites, as data (built-in or a YAML file).
* :mod:`.rollout`: the one rollout loop on the native vector env (also the paper's).
* :mod:`.metrics`: per-episode metrics; :mod:`.stats`: IQM, stratified bootstrap,
  probability of improvement over training runs.
* :mod:`.benchmark`: :func:`~.benchmark.evaluate`, policies x scenarios x runs x seeds.
* :mod:`.results`: ``results.json`` and the printed tables; :mod:`.plots`: the figures.
* :mod:`.curves`: learning curves on a suite, every checkpoint of seed runs scored as
  the benchmark scores a policy, against env steps and wall-clock time.

The command line (``evaluate.py``) is :mod:`tether_gym_agents.cli.evaluate`.
"""
