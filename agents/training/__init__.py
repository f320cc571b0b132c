"""Training: runs of the learning algorithms, the fan-out of seeds on Ray, sweeps.

One run is ``train(settings)`` (``run.py``) on a ``TrainSettings`` resolved once from the
command line (``settings.py``); the fan-out (``fanout.py``) and the sweep (``sweep.py``)
derive one ``TrainSettings`` per seed or trial and call the same ``train``. Which
algorithms there are, and what each needs, is the table of
:mod:`tether_gym_agents.common.algorithms`.

Every module of this package, with what it holds: the diagram of docs/architecture.md
(the one list of modules). The command line of ``train.py`` is
:mod:`tether_gym_agents.cli.train`; the run folder's files are named, read and written by
:mod:`tether_gym_agents.files.run_folder`.
"""
