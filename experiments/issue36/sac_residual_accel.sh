#!/bin/bash
# Probe: sac_residual's recipe (configs/sac_residual.yml) trained with the reward's
# reel-acceleration penalty switched on (reward_weights: {accel: W}; the env's default is
# 0), to bring its chattering down to PPO's (docs/distillation.md). One training seed,
# one core; the evaluation uses the standard env (the reward does not enter the metrics).
# usage: experiments/issue36/sac_residual_accel.sh W SEED STEPS
#   -> runs/sac_residual_accel/a<W>/seed_<SEED>, then its default-suite score
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
weight=$1 seed=$2 steps=$3
out=runs/sac_residual_accel/a$weight
mkdir -p "$out"
sed "s#    obs_noise: 0.001#    obs_noise: 0.001\n    reward_weights: {accel: $weight}#" \
  configs/sac_residual.yml > "$out/config.yml"
grep -q "reward_weights: {accel: $weight}" "$out/config.yml"
python train.py --algo sac --config "$out/config.yml" --seed "$seed" --timesteps "$steps" \
  --out "$out/seed_$seed" --no-progress
python evaluate.py "$out/seed_$seed" --no-plots --out "$out/eval_seed_$seed"
