#!/bin/bash
# One training seed of configs/sac_residual.yml with one of its lines changed by a sed
# expression, then its default-suite score (the probes sac_residual_scale.sh and
# sac_residual_accel.sh; docs/distillation.md). One core.
# usage: experiments/issue36/sac_residual_variant.sh OUT SED_EXPR CHECK SEED STEPS
#   OUT/config.yml is the changed recipe (CHECK: a string it must then contain),
#   OUT/seed_SEED the run, OUT/eval_seed_SEED its score
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
out=$1 expr=$2 check=$3 seed=$4 steps=$5
mkdir -p "$out"
sed "$expr" configs/sac_residual.yml > "$out/config.yml"
grep -q "$check" "$out/config.yml"
python train.py --algo sac --config "$out/config.yml" --seed "$seed" --timesteps "$steps" \
  --out "$out/seed_$seed" --no-progress
python evaluate.py "$out/seed_$seed" --no-plots --out "$out/eval_seed_$seed"
