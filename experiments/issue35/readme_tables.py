"""The README's main table of a suite: one evaluation's results.json with mpc's row merged in.

mpc (the CasADi extra, about 13 ms per step) is evaluated in its own call; this prints
``markdown_tables`` (less the probability of improvement) for the union of the
results' policies (mpc first, then the first folder's, then those of any further
folders: rows evaluated in a later call on the same suite and seeds, such as issue 36's
on ``robust`` and ``beyond``), so each README table is regenerated from the shipped
results.json files:

    python experiments/issue35/readme_tables.py docs/eval docs/eval_mpc
    python experiments/issue35/readme_tables.py docs/eval_robust docs/eval_robust/mpc
        docs/eval_robust/distill docs/eval_robust/sac_residual
        docs/eval_robust/filtered_distill_ppo
    python experiments/issue35/readme_tables.py docs/eval_beyond docs/eval_beyond/mpc
        docs/eval_beyond/distill docs/eval_beyond/sac_residual
        docs/eval_beyond/filtered_distill_ppo

(each of the last two is one command line).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from tether_gym_agents.evaluation.results import markdown_tables


def main(argv: list[str]) -> int:
    main_dir, mpc_dir, *extra_dirs = (Path(a) for a in argv)
    results = json.loads((main_dir / "results.json").read_text())
    mpc = json.loads((mpc_dir / "results.json").read_text())
    results["policies"] = {"mpc": mpc["policies"]["mpc"], **results["policies"]}
    for scenario, per in results["per_scenario"].items():
        per["mpc"] = mpc["per_scenario"][scenario]["mpc"]
    for folder in extra_dirs:
        extra = json.loads((folder / "results.json").read_text())
        if extra["seeds"] != results["seeds"] or set(extra["per_scenario"]) != set(
                results["per_scenario"]):
            raise SystemExit(f"{folder}: another suite or other seeds than {main_dir}")
        results["policies"].update(extra["policies"])
        for scenario, per in results["per_scenario"].items():
            per.update(extra["per_scenario"][scenario])
    text = markdown_tables(results)
    head, _, rest = text.partition("\n\nProbability of improvement")
    print(head + "\n\n" + rest[rest.index("Per scenario"):] if rest else text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
