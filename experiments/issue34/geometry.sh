#!/usr/bin/env bash
# The second CPU session's study of issue 34 (experiments/issue34/README.md, "What D
# lacks"): cfgs E and F (torch backend) and G-M (numba backend), seeds 0-1 in one
# process each; G's, J's and L's seeds 2-5 and 6-9, four per process; then the
# default-suite scores and their learning curves against wall time. Two processes at a
# time (one per core, one thread each); resumable: a run folder with its agent is
# skipped. About three hours on the 2-core development machine. Run it with the
# project's environment active.
R=experiments/issue34/runs/geometry
. "$(dirname "$0")/jobs.sh"
train E torch 2 0 E
train F torch 2 0 F
train G numba 2 0 G
train H numba 2 0 H
train I numba 2 0 I
train J numba 2 0 J
train K numba 2 0 K
train L numba 2 0 L
train M numba 2 0 M
for X in G J L; do
  train $X numba 4 2 ${X}_from2
  train $X numba 4 6 ${X}_from6
done
wait
python evaluate.py $R/E $R/F $R/G $R/H $R/I $R/J $R/K $R/L $R/M ppo_fast --no-plots --out $R/eval_two_seeds
for X in G J L; do
  mkdir -p $R/${X}_ten
  cp -r $R/$X/seed_* $R/${X}_from2/seed_* $R/${X}_from6/seed_* $R/${X}_ten/
  python evaluate.py $R/${X}_ten ppo_fast --no-plots --out $R/eval_${X}_ten
  python evaluate.py curves $R/${X}_ten --rms 7e-3 --out $R/curves_${X}_ten
done
