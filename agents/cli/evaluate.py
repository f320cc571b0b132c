"""``python evaluate.py``: benchmark policies, or reproduce the paper (``evaluate.py paper``)."""

from ..evaluation.benchmark import main

__all__ = ["main"]
