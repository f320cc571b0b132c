#!/usr/bin/env bash
# Five seeds of each learner (experiments/issue34/learners.py), two processes at a time
# (one per core, one thread each: every run under the same load); resumable: a run whose
# results file exists is skipped. Then the table (learners_table.py). Run it with the
# project's environment active and rsl-rl-lib installed (pip install rsl-rl-lib==5.5.1).
set -u
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
R=experiments/issue34/runs/learners
mkdir -p $R
for learner in home rsl_rl rsl_rl_rewnorm; do
  for seed in 0 1 2 3 4; do
    f=$R/results_${learner}_$seed.json
    [ -f "$f" ] && continue
    while [ "$(jobs -rp | wc -l)" -ge 2 ]; do wait -n; done
    python experiments/issue34/learners.py --learner $learner --seed $seed --out "$f" \
        > $R/${learner}_$seed.log 2>&1 &
  done
done
wait
python experiments/issue34/learners_table.py $R > experiments/issue34/learners.md
