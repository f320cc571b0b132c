"""Markdown table of the 3M- against 6M-step PPO runs: ``python table.py`` (results kept here)."""

import sys
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))
from variant_table import print_table  # noqa: E402

print_table(HERE, {"three": "3M steps (the ten runs of the fan-out)",
                   "six": "6M steps (the same runs continued)"}, first="budget")
