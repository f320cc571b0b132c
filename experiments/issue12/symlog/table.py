"""Markdown table of the symlog-feature probe: ``python table.py`` (results kept here)."""

import sys
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))
from variant_table import print_table  # noqa: E402

print_table(HERE, {"../observe_e/blind": "configs/ppo.yml (the plain observation)",
                   "symlog": "symlog error features, S = 1e-3 rad",
                   "symlog_1e-2": "symlog error features, S = 1e-2 rad"})
