#!/usr/bin/env bash
# The learning rate's size (experiments/issue34/README.md, "The learning rate's size",
# 2026-12-07): I (J's geometry, 672 iterations) with its rate 1e-3, N with 2e-3 and O with
# 3e-3, seeds 0-1 in one process each; N's and I's seeds 2-5 and 6-9, four per process;
# P (N's schedule ending at 336 iterations), ten seeds in two processes of five; then
# the default-suite scores and the learning curves. Two processes at a time (one
# per core, one thread each); resumable: a run folder with its agent is skipped. About
# 70 minutes on the 2-core development machine. Run it with the project's environment
# active.
R=experiments/issue34/runs/learning_rate
. "$(dirname "$0")/jobs.sh"
train N numba 2 0 N
train O numba 2 0 O
train I numba 2 0 I
train N numba 4 2 N_from2
train N numba 4 6 N_from6
train I numba 4 2 I_from2
train I numba 4 6 I_from6
train P numba 5 0 P_from0
train P numba 5 5 P_from5
wait
python evaluate.py $R/N $R/O $R/I ppo_accel --no-plots --out $R/eval_two_seeds
for X in N I; do
  mkdir -p $R/${X}_ten
  cp -r $R/$X/seed_* $R/${X}_from2/seed_* $R/${X}_from6/seed_* $R/${X}_ten/
  python evaluate.py curves $R/${X}_ten --rms 7e-3 --out $R/curves_${X}_ten
done
mkdir -p $R/P_ten
cp -r $R/P_from0/seed_* $R/P_from5/seed_* $R/P_ten/
python evaluate.py curves $R/P_ten --rms 7e-3 --out $R/curves_P_ten
python evaluate.py $R/I_ten $R/N_ten ppo_accel ppo_fast --no-plots --out $R/eval_ten
python evaluate.py $R/P_ten $R/N_ten $R/I_ten ppo_accel --no-plots --out $R/eval_P
