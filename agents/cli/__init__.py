"""Command lines: ``evaluate.py`` and ``train.py`` call ``evaluate.main`` and ``train.main``."""
