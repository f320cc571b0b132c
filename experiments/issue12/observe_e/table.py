"""Markdown table of the observation probe: ``python table.py`` (results kept here)."""

import sys
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))
from variant_table import print_table  # noqa: E402

print_table(HERE, {"blind": "observe_params False (configs/ppo.yml)",
                   "eccentricity": "observe_params \"eccentricity\"",
                   "params": "observe_params True"}, first="observation")
