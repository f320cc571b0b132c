#!/usr/bin/env bash
# Five seeds of each learner (experiments/issue34/learners.py), the two learners' seed k
# side by side (one process per core, one thread each, the same load on both); resumable:
# a seed whose results file exists is skipped. Then the table (learners_table.py).
set -u
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
R=experiments/issue34/runs/learners
mkdir -p $R
for seed in 0 1 2 3 4; do
  for learner in home rsl_rl; do
    f=$R/results_${learner}_$seed.json
    [ -f "$f" ] || python experiments/issue34/learners.py --learner $learner --seed $seed \
        --out "$f" > $R/${learner}_$seed.log 2>&1 &
  done
  wait
done
python experiments/issue34/learners_table.py $R > experiments/issue34/learners.md
