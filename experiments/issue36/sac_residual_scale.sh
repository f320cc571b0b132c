#!/bin/bash
# Probe: sac_residual's recipe (configs/sac_residual.yml) with another residual weight
# (docs/distillation.md, "A smaller residual"). One training seed, one core.
# usage: experiments/issue36/sac_residual_scale.sh SCALE SEED STEPS
#   -> runs/sac_residual_scale/s<SCALE>/seed_<SEED>, then its default-suite score
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
scale=$1 seed=$2 steps=$3
out=runs/sac_residual_scale/s$scale
mkdir -p "$out"
sed "s#residual: {base: smc, scale: 0.2, filter: true}#residual: {base: smc, scale: $scale, filter: true}#" \
  configs/sac_residual.yml > "$out/config.yml"
grep -q "scale: $scale," "$out/config.yml"
python train.py --algo sac --config "$out/config.yml" --seed "$seed" --timesteps "$steps" \
  --out "$out/seed_$seed" --no-progress
python evaluate.py "$out/seed_$seed" --no-plots --out "$out/eval_seed_$seed"
