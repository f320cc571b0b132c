"""Training: PPO and SAC runs, the fan-out of seeds on Ray and hyperparameter sweeps.

Modules, from the bottom up (a module imports only those above it in this list):

* :mod:`.config`: hyperparameter files and env kwargs, read and checked (``ConfigError``);
* :mod:`.settings`: ``TrainOptions`` (the command line, typed) and ``TrainSettings``
  (one run, resolved once by ``resolve_settings``);
* :mod:`.vec_env`, :mod:`.residual_env`: the vector envs a run trains on;
* :mod:`.resume`, :mod:`.callbacks`, :mod:`.curves`: pieces of a run;
* :mod:`.run`: ``train(settings) -> RunSummary``, one run;
* :mod:`.fanout`: seeds of one configuration as Ray tasks (records, not command lines);
* :mod:`.sweep`: trials x seeds, ranked by the median final evaluation return.

The command line of ``train.py`` (parse -> settings -> train) is
:mod:`tether_gym_agents.cli.train`.

The run folder's files are named, read and written by
:mod:`tether_gym_agents.files.run_folder`.
"""
