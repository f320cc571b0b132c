"""Markdown table of the precision screen: ``python table.py`` (results kept here)."""

import sys
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))
from variant_table import print_table  # noqa: E402

print_table(HERE, {"../observe_e/blind": "configs/ppo.yml (increment gain 0.5, lr 3e-4)",
                   "g1": "increment gain 1.0",
                   "lin": "learning rate lin_3e-4 (ppo_lin.yml)",
                   "net256": "[256, 256] networks (ppo_net256.yml)"})
