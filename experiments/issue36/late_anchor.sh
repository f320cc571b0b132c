#!/bin/bash
# Probe: a behaviour-cloning anchor switched on late. PPO continues from the shipped
# fine-tuned student distill_ppo/seed_SEED (after its 2M steps; configs/distill_ppo.yml's
# recipe, statistics fixed) for STEPS more env steps with bc_term on set A's mpc labels
# (docs/distillation.md, "A late anchor"). One training seed, one core.
# usage: experiments/issue36/late_anchor.sh BC_STEPS BC_LR SEED STEPS   (BC_STEPS 0: no anchor)
#   -> runs/late_anchor/b<BC_STEPS>_<BC_LR>/seed_<SEED>, then its default-suite score
set -euo pipefail
cd "$(dirname "$0")/../.."
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
steps=$1 lr=$2 seed=$3 timesteps=$4
out=runs/late_anchor/b${steps}_$lr
mkdir -p "$out"
anchor="\n  bc_term: {data: \"runs/distill_data/part_*[02468]/dagger_data.npz\", steps: $steps, batch_size: 2048, learning_rate: $lr}"
[ "$steps" = 0 ] && anchor=""   # BC_STEPS 0: the control, PPO alone from the same start
sed -e "s#^  init_policy: .*#  init_policy: distill_ppo/seed_{seed}$anchor#" \
  configs/distill_ppo.yml > "$out/config.yml"
grep -q "init_policy: distill_ppo/seed_{seed}" "$out/config.yml"
python train.py --config "$out/config.yml" --seed "$seed" --timesteps "$timesteps" \
  --out "$out/seed_$seed" --eval-episodes 20 --no-progress
python evaluate.py "$out/seed_$seed" "$out/seed_$seed/final_agent" --no-plots \
  --out "$out/eval_seed_$seed"
