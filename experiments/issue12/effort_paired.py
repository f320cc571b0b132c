"""Reel effort of each policy against SMC's on the episodes that both survive.

The benchmark's reel effort (``agents/evaluation/metrics.py``) integrates |l_i'| over an episode,
so an episode that fails early spends less. SMC fails 14-18 of the default suite's 70
episodes in its first-orbit transient, and those short episodes pull its IQM down.
This script pairs every episode of a policy with SMC's episode of the same scenario and
env seed, keeps the pairs in which both ran to the time limit, and prints the ratio of
the two efforts (median and mean over pairs, and the median per training run), next to
each policy's effort IQM over all of its episodes as ``evaluate.py`` reports it. Then,
per training run of each policy with several runs: the IQM over the scenarios of the
run's per-scenario means (``evaluate.py``'s per-run figure) of the tracking RMS and the
effort, and its failed episodes.

    python experiments/issue12/effort_paired.py [docs/eval/results.json]
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from tether_gym_agents.evaluation.stats import iqm, run_scores

REFERENCE = "smc"


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    path = Path(args[0] if args else "docs/eval/results.json")
    results = json.loads(path.read_text())
    episodes = results["episodes"]
    reference = {(e["scenario"], e["seed"]): e for e in episodes if e["policy"] == REFERENCE}
    if not reference:
        print(f"{path} holds no episodes of {REFERENCE!r}: evaluate it beside the policies "
              f"(python evaluate.py ... {REFERENCE})", file=sys.stderr)
        return 2
    ref_ok = [e["reel_effort"] for e in reference.values() if e["success"]]
    print(f"{path}: {REFERENCE} effort, mean over all {len(reference)} episodes "
          f"{np.mean([e['reel_effort'] for e in reference.values()]):.3f}, over its "
          f"{len(ref_ok)} survivors {np.mean(ref_ok):.3f}\n")
    print("| policy | effort IQM (all episodes) | pairs (both survive) | effort / SMC's: "
          "median | mean | median per run (min-max) |")
    print("|---|---|---|---|---|---|")
    for name in results["policies"]:
        if name == REFERENCE:
            continue
        ratios: dict[int, list[float]] = {}
        for e in episodes:
            if e["policy"] != name or not e["success"]:
                continue
            ref = reference[(e["scenario"], e["seed"])]
            if ref["success"]:
                ratios.setdefault(e["run"], []).append(e["reel_effort"] / ref["reel_effort"])
        if not ratios:
            continue
        flat = np.concatenate([np.asarray(r) for r in ratios.values()])
        per_run = [float(np.median(r)) for r in ratios.values()]
        print(f"| {name} | {results['policies'][name]['reel_effort']:.3f} | {flat.size} | "
              f"{np.median(flat):.3f} | {flat.mean():.3f} | "
              f"{min(per_run):.3f}-{max(per_run):.3f} |")
    print_per_run(results)
    return 0


def print_per_run(results: dict) -> None:
    """Per run: IQM over scenarios of the scenario means (``evaluate.py``'s own helpers)."""
    for name, policy in results["policies"].items():
        if policy["n_runs"] < 2:
            continue
        print(f"\n{name}, per training run: tracking RMS [rad] / effort / failed episodes")
        episodes = [e for e in results["episodes"] if e["policy"] == name]
        runs = list(range(policy["n_runs"]))
        rms, effort = (run_scores(episodes, metric, runs, results["scenarios"])
                       for metric in ("tracking_rms", "reel_effort"))
        cells = [f"{run}: {iqm(rms[run]):.2e} / {iqm(effort[run]):.2f} / "
                 f"{sum(1 for e in episodes if e['run'] == run and not e['success'])}"
                 for run in runs]
        print("; ".join(cells))


if __name__ == "__main__":
    raise SystemExit(main())
