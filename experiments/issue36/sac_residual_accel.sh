#!/bin/bash
# Probe: sac_residual's recipe (configs/sac_residual.yml) trained with the reward's
# reel-acceleration penalty switched on (reward_weights: {accel: W}; the env's default is
# 0), to bring its chattering down to PPO's (docs/distillation.md). One training seed,
# one core; the evaluation uses the standard env (the reward does not enter the metrics).
# usage: experiments/issue36/sac_residual_accel.sh W SEED STEPS
#   -> runs/sac_residual_accel/a<W>/seed_<SEED>, then its default-suite score
set -euo pipefail
weight=$1
exec "$(dirname "$0")/sac_residual_variant.sh" "runs/sac_residual_accel/a$weight" \
  "s#    obs_noise: 0.001#    obs_noise: 0.001\n    reward_weights: {accel: $weight}#" \
  "reward_weights: {accel: $weight}" "$2" "$3"
