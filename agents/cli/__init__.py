"""The command lines, the top layer: ``evaluate.py`` and ``train.py`` call their ``main``.

* :mod:`.evaluate`: ``evaluate.py [bench] ...`` (the benchmark) and ``evaluate.py paper``;
* :mod:`.train`: ``train.py`` (one run, ``--seeds N`` fan-out, ``--sweep``).

Each ``main(argv=None) -> int`` takes the arguments as a list of strings, so tests and
users call it in-process.
"""
