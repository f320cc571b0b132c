"""Markdown table of the learning-rate probe: ``python table.py`` (results kept here).

``constant``: the shipped ppo_symlog seeds 0-2 (learning rate 3e-4 throughout), evaluated
again from a folder of links to them; ``lin``: the same configuration and seeds with the
learning rate falling linearly from 3e-4 to 0 (ppo_symlog_lin.yml).
"""

import sys
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))
from variant_table import print_table  # noqa: E402

print_table(HERE, {"constant": "configs/ppo_symlog.yml (learning rate 3e-4), seeds 0-2",
                   "lin": "learning rate lin_3e-4 (3e-4 falling to 0)"})
