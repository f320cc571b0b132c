#!/bin/bash
# Probe: distill_ppo's first call (configs/distill_ppo.yml, 1M steps, from the shipped
# student distill_bc/seed_SEED) with a weak behaviour-cloning anchor on set A's mpc labels
# (docs/distillation.md, "A weak anchor"). One training seed, one core.
# usage: experiments/issue36/distill_ppo_bc.sh BC_STEPS BC_LR SEED
#   -> runs/distill_ppo_bc/b<BC_STEPS>_<BC_LR>/seed_<SEED>, then its default-suite score
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
steps=$1 lr=$2 seed=$3
out=runs/distill_ppo_bc/b${steps}_$lr
mkdir -p "$out"
sed "s#^  init_policy: .*#&\n  bc_term: {data: \"runs/distill_data/part_*[02468]/dagger_data.npz\", steps: $steps, batch_size: 2048, learning_rate: $lr}#" \
  configs/distill_ppo.yml > "$out/config.yml"
grep -q "bc_term" "$out/config.yml"
python train.py --config "$out/config.yml" --seed "$seed" --out "$out/seed_$seed" \
  --eval-episodes 20 --no-progress
python evaluate.py "$out/seed_$seed" --no-plots --out "$out/eval_seed_$seed"
