"""SMC (the paper's law) and the shipped PPO on our generalisation suite, for context.

    python experiments/issue12/smc_gen.py
"""

import json
import os
import sys
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from run import GEN_SUITE, strict  # noqa: E402

from tether_gym_agents.evaluation.benchmark import _run_scenario  # noqa: E402
from tether_gym_agents.evaluation.metrics import aggregate  # noqa: E402

torch.set_num_threads(1)
out = {}
for policy in sys.argv[1:] or ["smc"]:
    eps = []
    for sc in GEN_SUITE:
        e, _ = _run_scenario(policy, sc, [1000 + i for i in range(5)], record=False)
        for x in e:
            x["scenario"] = sc.name
        eps += e
        print(policy, sc.name, sum(x["success"] for x in e) / len(e), flush=True)
    agg = aggregate(eps)
    surv = [x["tracking_rms"] for x in eps if x["success"]]
    out[policy] = {"success": agg["success"], "tracking_rms_success":
                   sum(surv) / len(surv) if surv else None,
                   "reel_excursion": agg["reel_excursion"], "episodes": eps}
    print(policy, {k: v for k, v in out[policy].items() if k != "episodes"})
Path(__file__).with_name("baselines_gen.json").write_text(json.dumps(strict(out), indent=1))
