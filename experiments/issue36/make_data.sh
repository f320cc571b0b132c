#!/bin/bash
# The shared mpc dataset of the behaviour-cloning probes (docs/distillation.md, issue 36).
#
# usage: experiments/issue36/make_data.sh FIRST STEP LAST
#   builds parts FIRST, FIRST+STEP, ... <= LAST of runs/distill_data/part_<k>/: 20 mpc
#   episodes each on the learners' training distribution (train.py distill's iteration 0,
#   mpc alone behind its filter), labels of terminated episodes left out. Even k: mpc's
#   own action (set A); odd k: Gaussian noise of sigma 0.03 on the flown action, the
#   label clean (DART, set B). Seed 1000 + k. A part already written is skipped, so an
#   interrupted run resumes; the shipped study: "0 2 166" (set A, 84 parts) and "1 2 171"
#   (set B, 86 parts) side by side.
# Measured (2-core development machine, one job per core): median 117-120 s per part,
# 20,174 s in all.
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
first=$1 step=$2 last=$3
for ((k = first; k <= last; k += step)); do
  d=runs/distill_data/part_$k
  [ -f "$d/dagger_data.npz" ] && continue
  rm -rf "$d"
  noise=0
  if ((k % 2)); then noise=0.03; fi
  python train.py distill --iterations 1 --episodes 20 --epochs 1 --check-episodes 0 \
    --expert-noise "$noise" --drop-failed --seed $((1000 + k)) --out "$d"
done
