"""The table of experiments/issue34/learners.sh's runs (markdown on stdout).

    python experiments/issue34/learners_table.py experiments/issue34/runs/learners

Per learner over its seeds: training wall time, the deterministic policy's survival on 64
training-distribution episodes (raw fraction over all episodes of all seeds, and the worst
seed), the tracking RMS's interquartile mean over seeds with its 95 % stratified-bootstrap
interval (seeds without a surviving episode have no RMS: counted in the survival, not
trimmed away), and the mean episode return.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from tether_gym_agents.evaluation.stats import iqm, stratified_bootstrap_ci


def main(argv=None) -> int:
    folder = Path((sys.argv[1:] if argv is None else argv)[0])
    rows = {}
    for f in sorted(folder.glob("results_*.json")):
        r = json.loads(f.read_text())
        rows.setdefault(r["learner"], []).append(r)
    print("# Issue 34: the home-made PPO of `train.py gpu` against rsl_rl's PPO\n")
    print("`experiments/issue34/learners.sh` (five seeds of each learner, `learners.py`, "
          "hyperparameters `cfg/cpu_learners.yml`) on the CPU of the 2-core development "
          "machine, two runs at a time, one thread each. `rsl_rl_rewnorm` is rsl_rl trained "
          "on rewards scaled as the home-made learner's (VecNormalize's formula). Each policy is "
          "scored deterministically on 64 episodes of the training distribution (the "
          "same function for both). This table is written by `learners_table.py`.\n")
    print("| learner | seeds | env steps per seed | training wall time [s] | survived (raw) "
          "| worst seed | tracking RMS IQM [rad] [95 % CI] | seeds with no survivor "
          "| mean return |")
    print("|---|---|---|---|---|---|---|---|---|")
    for learner, runs in sorted(rows.items()):
        survived = [r["final"]["survived"][0] for r in runs]
        rms = np.array([[np.nan if r["final"]["tracking_rms"][0] is None
                         else r["final"]["tracking_rms"][0]] for r in runs])
        ci = stratified_bootstrap_ci(rms)
        ci_text = "n/a" if ci is None else f"[{ci[0]:.2e}, {ci[1]:.2e}]"
        walls = [r["train_wall_s"] for r in runs]
        seeds = ", ".join(str(r["seed"]) for r in runs)
        print(f"| {learner} | {seeds} | {runs[0]['steps']:,} | {np.mean(walls):.0f} "
              f"({min(walls):.0f}-{max(walls):.0f}) | {np.mean(survived):.3f} "
              f"| {min(survived):.3f} | {iqm(rms):.2e} {ci_text} "
              f"| {int(np.isnan(rms).sum())} "
              f"| {np.mean([r['final']['mean_return'][0] for r in runs]):.1f} |")
    print()
    print("Per seed (survived, tracking RMS [rad], mean return, training wall time [s]):")
    print()
    for learner, runs in sorted(rows.items()):
        for r in runs:
            f = r["final"]
            rms = f["tracking_rms"][0]
            print(f"- {learner} seed {r['seed']}: {f['survived'][0]:.3f}, "
                  f"{'none' if rms is None else f'{rms:.2e}'}, {f['mean_return'][0]:.1f}, "
                  f"{r['train_wall_s']:.0f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
