#!/bin/bash
# Probe: sac_residual's recipe (configs/sac_residual.yml) with another residual weight
# (docs/distillation.md, "A smaller residual"). One training seed, one core.
# usage: experiments/issue36/sac_residual_scale.sh SCALE SEED STEPS
#   -> runs/sac_residual_scale/s<SCALE>/seed_<SEED>, then its default-suite score
set -euo pipefail
scale=$1
exec "$(dirname "$0")/sac_residual_variant.sh" "runs/sac_residual_scale/s$scale" \
  "s#residual: {base: smc, scale: 0.2, filter: true}#residual: {base: smc, scale: $scale, filter: true}#" \
  "scale: $scale," "$2" "$3"
