#!/usr/bin/env bash
# The second CPU session's study of issue 34 (experiments/issue34/README.md, "What D
# lacks"): cfgs E and F (torch backend) and G-M (numba backend), seeds 0-1 in one
# process each; G's, J's and L's seeds 2-5 and 6-9, four per process; then the
# default-suite scores and their learning curves against wall time. Two processes at a
# time (one per core, one thread each); resumable: a run folder with its agent is
# skipped. About three hours on the 2-core development machine. Run it with the
# project's environment active.
set -u
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
C=experiments/issue34/cfg
R=experiments/issue34/runs/geometry
mkdir -p $R
train() {  # cfg backend seeds first-seed folder
  [ -f "$R/$5/seed_$4/agent.json" ] && return
  while [ "$(jobs -rp | wc -l)" -ge 2 ]; do wait -n; done
  python train.py gpu --config $C/$1.yml --device cpu --backend $2 --seeds $3 --seed $4 \
      --out $R/$5 > $R/$5.log 2>&1 &
}
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
