#!/bin/bash
# DAgger from each seed's fine-tuned student (issue 36 probe, docs/distillation.md):
# one iteration of 8 episodes flown by distill_ppo/seed_K alone, labelled by mpc, and a
# refit of 20 epochs at a step of 3e-6 from its weights, its statistics kept.
#   experiments/issue36/dagger_from_finetuned.sh K [LR] [ITERATIONS] [OUT]
# then: python evaluate.py runs/dagger_ft_row distill_ppo --no-plots --out runs/dagger_ft_eval
set -euo pipefail
cd "$(dirname "$0")/../.."
K=${1:?seed}
LR=${2:-3e-6}
IT=${3:-1}
OUT=${4:-runs/dagger_ft_row/seed_$K}
export OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1
if [ -f "$OUT/agent.json" ]; then   # a finished run is kept (remove it to run again)
  echo "kept $OUT (finished)"; exit 0
fi
rm -rf "$OUT"   # an unfinished run starts over (train.py distill has no resume)
python train.py distill --init-policy "distill_ppo/seed_{seed}" --symlog-scale 1e-4 \
  --iterations "$IT" --episodes 8 --beta-decay 0 --epochs 20 --learning-rate "$LR" \
  --check-episodes 8 --seed "$K" --out "$OUT"
