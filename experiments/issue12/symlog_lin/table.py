"""Markdown table of the learning-rate probe: ``python table.py`` (results kept here).

``constant``: the shipped ppo_symlog seeds 0-2 (learning rate 3e-4 throughout), evaluated
again from a folder of links to them; ``lin``: the same configuration and seeds with the
learning rate falling linearly from 3e-4 to 0 (ppo_symlog_lin.yml). From the repository
root (each results.json copied here under the name after ``->``; the beyond runs as
``beyond_constant.json`` and ``beyond_lin.json``):

    mkdir -p runs/symlog_ref
    for k in 0 1 2; do
        ln -sfn "$PWD/agents/pretrained/ppo_symlog/seed_$k" runs/symlog_ref/seed_$k
    done
    python evaluate.py runs/symlog_ref --out runs/eval_ref        # -> results_constant.json
    python evaluate.py runs/symlog_ref --suite beyond --out runs/eval_ref_beyond
    python train.py --config experiments/issue12/symlog_lin/ppo_symlog_lin.yml --seeds 3 --seed 0 \
        --out runs/symlog_lin
    python evaluate.py runs/symlog_lin --out runs/eval_lin        # -> results_lin.json
    python evaluate.py runs/symlog_lin --suite beyond --out runs/eval_lin_beyond
"""

import sys
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent))
from variant_table import print_table  # noqa: E402

print_table(HERE, {"constant": "configs/ppo_symlog.yml (learning rate 3e-4), seeds 0-2",
                   "lin": "learning rate lin_3e-4 (3e-4 falling to 0)"})
